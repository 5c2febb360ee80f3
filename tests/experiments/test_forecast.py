import numpy as np
import pytest

from scpformer.experiments.forecast import IMPULSE_THRESHOLD, forecast_metrics, mean_metrics


def _trajectory(seed: int, n: int = 10):
    rng = np.random.default_rng(seed)
    dv = rng.normal(scale=1e-2, size=(n, 3))
    dv[::3] = 0.0  # coasting nodes
    return rng.normal(size=(n + 1, 6)), rng.normal(size=(n + 1, 6)), dv


def test_a_perfect_prediction_has_zero_error_and_full_impulse_accuracy():
    rtn, roe, dv = _trajectory(0)
    m = forecast_metrics(rtn, roe, dv, rtn, roe, dv)
    assert m.rtn_pos_rmse_m == m.roe_rmse_m == m.control_rmse_mm_s == 0.0
    assert m.impulse_accuracy_pct == 100.0
    assert m.cost_mm_s == pytest.approx(m.true_cost_mm_s)


def test_errors_match_a_hand_computation():
    rtn, roe, dv = _trajectory(1, n=4)
    shifted = rtn.copy()
    shifted[:, 0] += 3.0  # 3 m radial offset at every node
    shifted[-1, 4] += 0.004  # 4 mm/s along-track at the end
    m = forecast_metrics(shifted, roe, dv, rtn, roe, dv)
    assert m.rtn_pos_rmse_m == pytest.approx(3.0)
    assert m.target_rtn_pos_m == pytest.approx(3.0)
    assert m.target_rtn_vel_mm_s == pytest.approx(4.0)
    assert m.rtn_vel_rmse_mm_s == pytest.approx(4.0 / np.sqrt(5))


def test_impulse_accuracy_counts_true_impulses_the_prediction_misses():
    rtn, roe, _ = _trajectory(2, n=4)
    true_dv = np.array([[1e-2, 0, 0], [0, 0, 0], [0, 1e-2, 0], [0, 0, 1e-2]])
    pred_dv = np.array([[1e-2, 0, 0], [5e-3, 0, 0], [0, 0.1 * IMPULSE_THRESHOLD, 0], [0, 0, 0]])
    m = forecast_metrics(rtn, roe, pred_dv, rtn, roe, true_dv)
    assert m.impulse_accuracy_pct == pytest.approx(100.0 / 3.0)


def test_mean_metrics_averages_each_field():
    a = forecast_metrics(*_trajectory(3), *_trajectory(4))
    b = forecast_metrics(*_trajectory(5), *_trajectory(6))
    mean = mean_metrics([a, b])
    assert mean["roe_rmse_m"] == pytest.approx((a.roe_rmse_m + b.roe_rmse_m) / 2)


@pytest.mark.parametrize("bad", ["shape", "nan"])
def test_bad_predictions_are_refused_by_name(bad):
    rtn, roe, dv = _trajectory(7)
    pred = rtn[:-1] if bad == "shape" else np.where(rtn > 0, np.nan, rtn)
    with pytest.raises(ValueError, match="pred_rtn"):
        forecast_metrics(pred, roe, dv, rtn, roe, dv)
