"""Forecasting metrics of the ART paper's Tables 2-3 (Sec. 5.1), in plain numpy.

Each metric compares a predicted trajectory with the "true" optimizer solution of the same
instance. The paper names the metrics but not every formula; the choices, per instance:

* trajectory RMSE: ``sqrt(mean_k |xhat_k - x_k|_2^2)`` over the N+1 nodes, separately for
  RTN position [m], RTN velocity [mm/s] and the ROE vector [m];
* target RMSE: ``|xhat_N - x_N|_2`` at the final node (the docking state the true solution
  reaches), per block as above;
* cost: ``sum_k |dv_k|_2`` [mm/s] of the predicted impulses;
* impulse accuracy: of the nodes where the true solution fires (``|dv_k| > IMPULSE_THRESHOLD``),
  the share where the prediction fires too [%] (the paper: "whenever true applies
  dv(t_i) > 0, the predicted trajectory also applies dv(t_i) > 0"); a threshold is needed
  because an interior-point solution is never exactly zero;
* control RMSE: ``sqrt(mean_k |dvhat_k - dv_k|_2^2)`` [mm/s].

The aggregate over a test set is the mean of the per-instance values, as the paper's tables
report averages over the test set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

IMPULSE_THRESHOLD = 1e-4  # m/s: an impulse counts as fired above 0.1 mm/s
MM = 1e3  # m/s -> mm/s


@dataclass(frozen=True)
class ForecastMetrics:
    """Tables 2-3 metrics of one predicted trajectory against the true solution."""

    rtn_pos_rmse_m: float  # trajectory RMSE, RTN position [m]
    rtn_vel_rmse_mm_s: float  # trajectory RMSE, RTN velocity [mm/s]
    roe_rmse_m: float  # trajectory RMSE, ROE [m]
    target_rtn_pos_m: float  # final-node error, RTN position [m]
    target_rtn_vel_mm_s: float  # final-node error, RTN velocity [mm/s]
    target_roe_m: float  # final-node error, ROE [m]
    cost_mm_s: float  # sum |dv|_2 of the prediction [mm/s]
    true_cost_mm_s: float  # sum |dv|_2 of the true solution [mm/s]
    impulse_accuracy_pct: float  # share of true impulses also fired by the prediction [%]
    control_rmse_mm_s: float  # RMSE of the impulses [mm/s]


def _rms_norm(error: np.ndarray) -> float:
    """``sqrt(mean_k |e_k|_2^2)`` over the leading axis of ``error`` (K, d)."""
    return float(np.sqrt(np.mean(np.sum(error**2, axis=-1))))


def _check(name: str, value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    value = np.asarray(value, dtype=float)
    if value.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {value.shape}")
    if not np.all(np.isfinite(value)):
        raise ValueError(f"{name} must be finite")
    return value


def forecast_metrics(
    pred_rtn: np.ndarray,
    pred_roe: np.ndarray,
    pred_dv: np.ndarray,
    true_rtn: np.ndarray,
    true_roe: np.ndarray,
    true_dv: np.ndarray,
) -> ForecastMetrics:
    """Tables 2-3 metrics of one prediction.

    Parameters
    ----------
    pred_rtn, true_rtn
        RTN states (N+1, 6) [m, m/s].
    pred_roe, true_roe
        Scaled ROE ``a dalpha`` (N+1, 6) [m].
    pred_dv, true_dv
        Impulses (N, 3) [m/s].
    """
    n = np.asarray(true_dv).shape[0]
    pred_rtn, true_rtn = (
        _check("pred_rtn", pred_rtn, (n + 1, 6)),
        _check("true_rtn", true_rtn, (n + 1, 6)),
    )
    pred_roe, true_roe = (
        _check("pred_roe", pred_roe, (n + 1, 6)),
        _check("true_roe", true_roe, (n + 1, 6)),
    )
    pred_dv, true_dv = _check("pred_dv", pred_dv, (n, 3)), _check("true_dv", true_dv, (n, 3))
    d_rtn, d_roe = pred_rtn - true_rtn, pred_roe - true_roe
    fired_true = np.linalg.norm(true_dv, axis=1) > IMPULSE_THRESHOLD
    fired_pred = np.linalg.norm(pred_dv, axis=1) > IMPULSE_THRESHOLD
    accuracy = 100.0 * np.mean(fired_pred[fired_true]) if fired_true.any() else float("nan")
    return ForecastMetrics(
        rtn_pos_rmse_m=_rms_norm(d_rtn[:, :3]),
        rtn_vel_rmse_mm_s=MM * _rms_norm(d_rtn[:, 3:]),
        roe_rmse_m=_rms_norm(d_roe),
        target_rtn_pos_m=float(np.linalg.norm(d_rtn[-1, :3])),
        target_rtn_vel_mm_s=MM * float(np.linalg.norm(d_rtn[-1, 3:])),
        target_roe_m=float(np.linalg.norm(d_roe[-1])),
        cost_mm_s=MM * float(np.linalg.norm(pred_dv, axis=1).sum()),
        true_cost_mm_s=MM * float(np.linalg.norm(true_dv, axis=1).sum()),
        impulse_accuracy_pct=float(accuracy),
        control_rmse_mm_s=MM * _rms_norm(pred_dv - true_dv),
    )


def mean_metrics(metrics: list[ForecastMetrics]) -> dict[str, float]:
    """Test-set averages of every field (NaN-aware: an instance without true impulses)."""
    if not metrics:
        raise ValueError("mean_metrics needs at least one ForecastMetrics")
    names = ForecastMetrics.__dataclass_fields__
    return {k: float(np.nanmean([getattr(m, k) for m in metrics])) for k in names}
