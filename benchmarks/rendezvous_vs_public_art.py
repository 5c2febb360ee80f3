"""Our verified rendezvous SCP against the public ART code's ``solve_scp``.

The public code is the rendezvous part (``rpod/``) of the repository of Celestini, Gammelli,
Guffanti, D'Amico, Capello and Pavone, "Transformer-based model predictive control: trajectory
optimization via sequence modeling" (``transformermpc-ral24`` on GitHub). It is not part of
scpformer and is never copied into it: ``--art-repo DIR`` names a checkout (``DIR`` holding
``optimization/ocp.py``, or the repository root holding ``rpod/optimization/ocp.py``), loaded
here as a measurement instrument, unmodified. MOSEK, which ``ocp.py`` imports but does not call
(its normalized branch is disabled), is replaced by ``DIR/mosek.py`` when the package is not
installed, or else by an empty module.

On each of ``--n`` instances drawn by our sampler (``--seed``), in one process, with the three
variants alternated (their order rotates with the repeat) and ``--repeats`` rounds over all
instances, this times

* theirs: ``ocp_cvx`` (their Problem 2 warm start, as their ``warmstarting_analysis.py`` does)
  and then ``solve_scp`` from its states: the SCP alone and CVX + SCP;
* ours, verified: ``scpformer.rendezvous.solve(instance, config)`` (method ``"scp"``), what
  ``scpformer solve rendezvous --problem scp`` runs (our Problem 2 warm start, the SCP, and
  the nonlinear replay check :func:`~scpformer.problems.rendezvous.problem.verify_solution`),
  with the replay's cache cleared first so every timed solve pays the whole check; the SCP
  alone is the total minus the warm start's time;
* ours without the check (``verify=False``), timed the same way.

It reports per instance the medians over the repeats, both costs (sum of ``|dv|_2``), the
iterations and statuses, and whether their final plan passes OUR replay check (run once,
untimed), then the medians over the instances and the speed-ups, both as the ratio of those
medians and as the median of the per-instance ratios (each instance's variants run back to
back, so this one is robust to the load of other jobs on the machine).

The same instance on both sides
-------------------------------
``solve_scp(stm, cim, psi, state_roe_0, dock_param, states_roe_ref, n_time)`` takes the
dynamics as arrays, so it is fed ours: ``stm`` = our ``Phi_k`` (6, 6, N), ``psi`` = our
``Psi_k`` (6, 6, N+1), ``cim`` = our ``B_k`` (6, 3, N) plus a ZERO block at ``t_N``, and
``n_time = N + 1``: the same 101 nodes and time grid, the same initial mean ROE. Their program
has one impulse more than ours, at the last node (terminal condition
``s_N + B_N a_N = s_f``); our Problem 3 docks by coasting from ``t_{N-1}`` (``x_N = x_dock``).
The zero block makes their terminal condition ours (``a_N`` then only costs, and comes out
zero). ``dock_param`` comes from their ``dock_param_maker`` for our docking state, with its
``state_roe_target`` (which they map with ``Psi(t_0)`` of their near-circular model) replaced by
ours, ``Psi(t_N)^-1 (dr_dp, 0)``; the script checks that their waypoint node, cone vertex,
cone angle, waypoint, keep-out ellipsoid and SCP constants (K = 20, 200 m -> 1 m, J_tol) equal
ours and stops otherwise.

What still differs (measured costs need not be equal)
-----------------------------------------------------
* Approach cone vertex: this version of their code puts it 5 m behind the docking port
  (``cone_vertex_displ = 5``), as ours does; the older AeroConf'24 ART code (discussed in
  ``docs/results/art-warmstart/report.md``) put it at the port. No difference here.
* Rows: their keep-out cut and trust region hold at nodes ``0 .. N_wp - 1``, ours at
  ``0 .. N_wp`` (node ``N_wp`` is the waypoint, fixed outside the keep-out zone); their cone
  holds at ``N_wp .. N``, ours at ``N_wp .. N-1`` (node ``N`` is the docked state, inside the
  cone). Both differences are redundant rows.
* Returned iterate: theirs returns the LAST iterate, ours the cheapest one. Their first
  iteration can never stop (``DELTA_J = 10``); ours compares with the warm start's cost.
  Their loop returns the last iterate also when K = 20 is reached; ours reports that as
  ``max_iterations`` (the paper counts it infeasible).
* Solver and problem building: theirs builds a new cvxpy problem every iteration with Python
  loops over the nodes and solves it with ECOS; ours is compiled once with Parameters (loaded
  from the disk cache) and solved with Clarabel (``--our-solver`` picks ECOS or QOCO).
* Not timed on either side: building the dynamics matrices for theirs (done by their
  pipeline outside its timers too); process start-up and loading our compiled problem
  (``benchmarks/cli_speed.py`` measures those). Ours includes building its linear model
  (~2 ms) inside ``solve``.

Usage: python benchmarks/rendezvous_vs_public_art.py --art-repo DIR [--n 20] [--seed 0]
[--repeats 3] [--our-solver clarabel] [--out DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import importlib
import importlib.machinery
import importlib.util
import io
import math
import os
import statistics
import sys
import time
import types
import warnings
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.problems.rendezvous import problem, verification
from scpformer.problems.rendezvous.instance import RendezvousInstance, sample_instances
from scpformer.problems.rendezvous.scenario import RendezvousSolverConfig, SCPParameters
from scpformer.rendezvous import solve
from scpformer.scp.solution import Status

DEFAULT_OUT = Path("vs-public-art")  # relative to the working folder
OCP = Path("optimization") / "ocp.py"
VARIANTS = ("theirs", "ours_check", "ours_nocheck")


# ======================================================================================
# loading the public code
# ======================================================================================
def art_root(repo: Path) -> Path:
    """The folder holding ``optimization/ocp.py``: ``repo`` itself or ``repo/rpod``."""
    for root in (repo, repo / "rpod"):
        if (root / OCP).is_file():
            return root
    raise FileNotFoundError(
        f"--art-repo: {repo / OCP} not found (nor {repo / 'rpod' / OCP}); pass a checkout of "
        "the public ART code (transformermpc-ral24, its rpod/ folder or the repository root)"
    )


def _namespace_package(name: str, folder: Path) -> types.ModuleType:
    spec = importlib.machinery.ModuleSpec(name, None, is_package=True)
    spec.submodule_search_locations = [str(folder)]
    module = importlib.util.module_from_spec(spec)
    module.__path__ = [str(folder)]
    return module


def _mosek_stand_in(root: Path) -> types.ModuleType:
    """``root/mosek.py`` if present, else an empty module (MOSEK is imported, never called)."""
    path = root / "mosek.py"
    if path.is_file():
        spec = importlib.util.spec_from_file_location("mosek", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    return types.ModuleType("mosek")


def load_public_art(repo: Path) -> tuple[types.ModuleType, types.ModuleType, str]:
    """Import their ``optimization.ocp`` and ``optimization.rpod_scenario`` unmodified.

    Their top-level packages ``optimization`` and ``dynamics`` are registered as namespace
    packages rooted in the checkout (no ``sys.path`` entry of ours); ``rpod_scenario`` appends
    its own root to ``sys.path`` when imported, which is undone afterwards.
    """
    root = art_root(repo)
    for name in ("optimization", "dynamics"):
        loaded = sys.modules.get(name)
        if loaded is not None and list(getattr(loaded, "__path__", [])) != [str(root / name)]:
            raise RuntimeError(f"a module named {name!r} is already imported from elsewhere")
        sys.modules[name] = _namespace_package(name, root / name)
    note = "mosek: installed"
    if importlib.util.find_spec("mosek") is None:
        sys.modules["mosek"] = _mosek_stand_in(root)
        note = f"mosek: not installed, stand-in {root / 'mosek.py'} (never called)"
    saved = list(sys.path)
    try:
        ocp = importlib.import_module("optimization.ocp")
        scenario = importlib.import_module("optimization.rpod_scenario")
    finally:
        sys.path[:] = saved
    return ocp, scenario, note


# ======================================================================================
# the same instance on both sides
# ======================================================================================
@dataclass(frozen=True)
class PublicInputs:
    """Arguments of their ``ocp_cvx`` / ``solve_scp`` for one of our instances."""

    stm: np.ndarray  # (6, 6, N)
    cim: np.ndarray  # (6, 3, N+1), zero at t_N
    psi: np.ndarray  # (6, 6, N+1)
    s0: np.ndarray  # (6,)
    dock_param: dict[str, Any]
    n_time: int  # N + 1


def check_same_constants(scenario: types.ModuleType, instance: RendezvousInstance) -> None:
    """Stop unless their scenario constants equal ours (see the module docstring)."""
    ours, scp = instance.scenario, SCPParameters()
    pairs = {
        "waypoint node": (scenario.dock_wyp_sample, ours.n_waypoint),
        "keep-out E": (np.sqrt(np.diag(scenario.EE_koz)), np.diag(ours.E_koz)),
        "K": (scenario.iter_max_SCP, scp.K),
        "zeta_1": (scenario.trust_region0, scp.zeta_1),
        "zeta_K": (scenario.trust_regionf, scp.zeta_K),
        "J_tol": (scenario.J_tol, scp.J_tol),
    }
    for name, (theirs, mine) in pairs.items():
        if not np.allclose(theirs, mine, rtol=1e-12, atol=0.0):
            raise RuntimeError(f"{name} differs: theirs {theirs}, ours {mine}")


def public_inputs(
    scenario: types.ModuleType, instance: RendezvousInstance, model: problem.LinearModel
) -> PublicInputs:
    """Our dynamics, boundary data and docking geometry in their argument layout."""
    sc = instance.scenario
    bounds = problem.boundary_data(instance, model)
    dock_state = np.r_[sc.dock_port_m, 0.0, 0.0, 0.0]
    dock_param, _ = scenario.dock_param_maker(dock_state)
    geometry = {
        "dock_port": (dock_param["dock_port"], sc.cone_vertex_m),
        "dock_axis": (dock_param["dock_axis"], np.asarray(sc.approach_axis)),
        "dock_cone_angle": (dock_param["dock_cone_angle"], math.radians(sc.cone_half_angle_deg)),
        "dock_wyp": (dock_param["dock_wyp"], np.r_[sc.waypoint_m, 0.0, 0.0, 0.0]),
    }
    for name, (theirs, mine) in geometry.items():
        if not np.allclose(theirs, mine, rtol=0.0, atol=1e-9):
            raise RuntimeError(f"dock_param[{name!r}] differs: theirs {theirs}, ours {mine}")
    dock_param = {**dock_param, "state_roe_target": bounds.x_dock}
    zero = np.zeros((6, 3, 1))
    return PublicInputs(
        stm=np.ascontiguousarray(np.moveaxis(model.Phi, 0, -1)),
        cim=np.concatenate([np.moveaxis(model.B, 0, -1), zero], axis=2),
        psi=np.ascontiguousarray(np.moveaxis(model.Psi, 0, -1)),
        s0=instance.roe0.copy(),
        dock_param=dock_param,
        n_time=instance.n_nodes + 1,
    )


# ======================================================================================
# timed runs
# ======================================================================================
@dataclass(frozen=True)
class Run:
    """One timed solve: wall times [s] and what it returned."""

    total: float  # warm start + SCP (+ our check)
    scp: float  # SCP (+ our check) alone
    check: float  # our replay check inside ``scp`` (0 for theirs and without it)
    cost: float  # sum |dv|_2 [m/s]
    iterations: int
    status: str
    x: np.ndarray | None = None  # (N+1, 6) final states, theirs only (for our check)
    dv: np.ndarray | None = None  # (N, 3)
    final_dv: float = math.nan  # |a_N| of theirs [m/s]
    inaccurate: int = 0  # their SCP subproblems solved "optimal_inaccurate" (cvxpy's warning)


def run_theirs(ocp: types.ModuleType, inp: PublicInputs) -> Run:
    """``ocp_cvx`` then ``solve_scp`` from its states, as their pipeline does."""
    start = time.perf_counter()
    try:
        s_cvx, _, feas_cvx = ocp.ocp_cvx(
            inp.stm, inp.cim, inp.psi, inp.s0, inp.dock_param, inp.n_time
        )
    except Exception as err:  # their pipeline catches every exception here too
        feas_cvx, s_cvx = f"failure ({type(err).__name__})", None
    mid = time.perf_counter()
    if feas_cvx != "optimal":
        return Run(mid - start, math.nan, 0.0, math.nan, 0, f"cvx {feas_cvx}")
    with (
        contextlib.redirect_stdout(io.StringIO()) as said,  # their "unfeasible scp" print
        warnings.catch_warnings(record=True) as caught,  # cvxpy: "may be inaccurate"
    ):
        warnings.simplefilter("always")
        s, a, feas, iters, _, _ = ocp.solve_scp(
            inp.stm, inp.cim, inp.psi, inp.s0, inp.dock_param, s_cvx, inp.n_time
        )
    inaccurate = sum("inaccurate" in str(w.message) for w in caught)
    end = time.perf_counter()
    if s is None:
        status = f"scp {feas}" + (f" ({said.getvalue().strip()})" if said.getvalue() else "")
        return Run(end - start, end - mid, 0.0, math.nan, iters, status, inaccurate=inaccurate)
    ended = "converged" if iters < ocp.iter_max_SCP else "K reached"
    return Run(
        total=end - start,
        scp=end - mid,
        check=0.0,
        cost=float(np.linalg.norm(a, axis=0).sum()),
        iterations=iters,
        status=f"{ended} ({feas})",
        x=s.T.copy(),
        dv=a[:, :-1].T.copy(),
        final_dv=float(np.linalg.norm(a[:, -1])),
        inaccurate=inaccurate,
    )


def run_ours(instance: RendezvousInstance, config: RendezvousSolverConfig, verify: bool) -> Run:
    """``scpformer.rendezvous.solve(instance, config)`` (what ``scpformer solve rendezvous``
    runs)."""
    verification._osculating_initial_state.cache_clear()  # each timed check pays the replay
    start = time.perf_counter()
    sol = solve(instance, config, method="scp", verify=verify)
    total = time.perf_counter() - start
    warm = sol.extras["warmstart"]["time_s"]
    return Run(
        total=total,
        scp=total - warm,
        check=sol.timing.verification if sol.timing is not None else 0.0,
        cost=sol.cost,
        iterations=sol.iterations,
        status=sol.status.value,
    )


def their_plan_passes(instance: RendezvousInstance, model: problem.LinearModel, run: Run) -> str:
    """Our replay check (Problem 3 constraints) of their final plan: ``yes``/``no``/``-``."""
    if run.x is None:
        return "-"
    ver = problem.verify_solution(instance, model, run.x, run.dv, "scp")
    return "yes" if ver.passed else f"no: {ver.message.split(';')[0]}"


# ======================================================================================
# the measurement and its report
# ======================================================================================
def measure(
    ocp: types.ModuleType,
    instances: list[RendezvousInstance],
    inputs: list[PublicInputs],
    config: RendezvousSolverConfig,
    repeats: int,
) -> list[dict[str, list[Run]]]:
    """``repeats`` rounds over the instances, the three variants back to back per instance."""
    runners = {
        "theirs": lambda k: run_theirs(ocp, inputs[k]),
        "ours_check": lambda k: run_ours(instances[k], config, verify=True),
        "ours_nocheck": lambda k: run_ours(instances[k], config, verify=False),
    }
    for name in VARIANTS:  # warm-up, untimed: imports, compiled problem, solver start-up
        runners[name](0)
    runs: list[dict[str, list[Run]]] = [{name: [] for name in VARIANTS} for _ in instances]
    for r in range(repeats):
        order = VARIANTS[r % 3 :] + VARIANTS[: r % 3]
        for k in range(len(instances)):
            for name in order:
                runs[k][name].append(runners[name](k))
        print(f"round {r + 1}/{repeats} done, load average {os.getloadavg()[0]:.2f}", flush=True)
    return runs


def _median(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return statistics.median(finite) if finite else math.nan


def instance_rows(
    instances: list[RendezvousInstance],
    runs: list[dict[str, list[Run]]],
    passes: list[str],
) -> list[dict[str, Any]]:
    """One row per instance: medians over the repeats, the last repeat's outcome."""
    rows = []
    for k, (instance, by_variant) in enumerate(zip(instances, runs, strict=True)):
        row: dict[str, Any] = {"instance": k, "horizon_orbits": round(instance.horizon_orbits, 4)}
        for name in VARIANTS:
            rs = by_variant[name]
            row[f"{name}_total_ms"] = 1e3 * _median([r.total for r in rs])
            row[f"{name}_scp_ms"] = 1e3 * _median([r.scp for r in rs])
            if name == "ours_check":
                row["ours_check_replay_ms"] = 1e3 * _median([r.check for r in rs])
            row[f"{name}_cost_mm_s"] = 1e3 * rs[-1].cost
            row[f"{name}_iterations"] = rs[-1].iterations
            row[f"{name}_status"] = rs[-1].status
        row["theirs_final_dv_mm_s"] = 1e3 * by_variant["theirs"][-1].final_dv
        row["theirs_inaccurate_subproblems"] = by_variant["theirs"][-1].inaccurate
        row["theirs_passes_our_check"] = passes[k]
        row["theirs_cost_over_ours"] = row["theirs_cost_mm_s"] / row["ours_check_cost_mm_s"]
        for what in ("total", "scp"):
            for ours in ("ours_check", "ours_nocheck"):
                row[f"speedup_{what}_{ours}"] = row[f"theirs_{what}_ms"] / row[f"{ours}_{what}_ms"]
        rows.append(row)
    return rows


def summary(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Medians over the instances (their failed solves left out of the SCP times)."""
    keys = [k for k in rows[0] if k.endswith("_ms") or k.startswith("speedup_")]
    out = {k: _median([row[k] for row in rows]) for k in keys}
    out["theirs_cost_over_ours"] = _median([row["theirs_cost_over_ours"] for row in rows])
    for what in ("total", "scp"):
        for ours in ("ours_check", "ours_nocheck"):
            out[f"ratio_of_medians_{what}_{ours}"] = (
                out[f"theirs_{what}_ms"] / out[f"{ours}_{what}_ms"]
            )
    return out


def outcome_counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    """How many instances each side converged on and was feasible on."""
    done = Status.CONVERGED.value
    return {
        "n": len(rows),
        "ours_converged_verified": sum(r["ours_check_status"] == done for r in rows),
        "ours_nocheck_converged": sum(r["ours_nocheck_status"] == done for r in rows),
        "theirs_converged": sum(r["theirs_status"].startswith("converged") for r in rows),
        "theirs_returned_plan": sum(r["theirs_passes_our_check"] != "-" for r in rows),
        "theirs_passes_our_check": sum(r["theirs_passes_our_check"] == "yes" for r in rows),
        "theirs_with_inaccurate": sum(r["theirs_inaccurate_subproblems"] > 0 for r in rows),
    }


def markdown(
    rows: list[dict[str, Any]], med: dict[str, float], counts: dict[str, int], header: list[str]
) -> str:
    """The report: the summary table, the counts, then one line per instance."""
    lines = ["# Our verified rendezvous SCP vs the public ART code's `solve_scp`", "", *header, ""]
    lines += [
        "| median over instances [ms] | CVX + SCP | SCP alone |",
        "| --- | ---: | ---: |",
        f"| ours, verified (with the replay check) | {med['ours_check_total_ms']:.1f} "
        f"| {med['ours_check_scp_ms']:.1f} |",
        f"| ours without the check | {med['ours_nocheck_total_ms']:.1f} "
        f"| {med['ours_nocheck_scp_ms']:.1f} |",
        f"| theirs (`ocp_cvx` + `solve_scp`) | {med['theirs_total_ms']:.1f} "
        f"| {med['theirs_scp_ms']:.1f} |",
        f"| speed-up vs ours verified: ratio of medians | "
        f"{med['ratio_of_medians_total_ours_check']:.1f}x "
        f"| {med['ratio_of_medians_scp_ours_check']:.1f}x |",
        f"| speed-up vs ours verified: median per-instance ratio | "
        f"{med['speedup_total_ours_check']:.1f}x | {med['speedup_scp_ours_check']:.1f}x |",
        f"| speed-up vs ours without the check: ratio of medians | "
        f"{med['ratio_of_medians_total_ours_nocheck']:.1f}x "
        f"| {med['ratio_of_medians_scp_ours_nocheck']:.1f}x |",
        f"| speed-up vs ours without the check: median per-instance ratio | "
        f"{med['speedup_total_ours_nocheck']:.1f}x | {med['speedup_scp_ours_nocheck']:.1f}x |",
        "",
        f"Our replay check: median {med['ours_check_replay_ms']:.1f} ms per solve. "
        f"Median cost ratio theirs / ours: {med['theirs_cost_over_ours']:.4f}.",
        "",
        f"Outcomes on {counts['n']} instances: ours converged and verified on "
        f"{counts['ours_converged_verified']} (converged without the check: "
        f"{counts['ours_nocheck_converged']}); theirs stopped before K on "
        f"{counts['theirs_converged']}, returned a plan on {counts['theirs_returned_plan']}, "
        f"and that plan passes our replay check on {counts['theirs_passes_our_check']}; "
        f"ECOS returned `optimal_inaccurate` on some SCP subproblem (accepted by their loop) "
        f"on {counts['theirs_with_inaccurate']}.",
        "",
        "| # | ours verified ms | ours no check ms | theirs ms (SCP) | cost ours / theirs mm/s "
        "| iterations ours / theirs | status ours / theirs | theirs passes our check |",
        "| ---: | ---: | ---: | ---: | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['instance']} | {r['ours_check_total_ms']:.1f} | {r['ours_nocheck_total_ms']:.1f}"
            f" | {r['theirs_total_ms']:.0f} ({r['theirs_scp_ms']:.0f}) "
            f"| {r['ours_check_cost_mm_s']:.2f} / {r['theirs_cost_mm_s']:.2f} "
            f"| {r['ours_check_iterations']} / {r['theirs_iterations']} "
            f"| {r['ours_check_status']} / {r['theirs_status']} | {r['theirs_passes_our_check']} |"
        )
    return "\n".join(lines) + "\n"


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--art-repo", type=Path, required=True)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--our-solver", default="clarabel", choices=("clarabel", "ecos", "qoco"))
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    for name in ("n", "repeats"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    try:
        art_root(args.art_repo)
    except FileNotFoundError as err:
        parser.error(str(err))
    ocp, scenario, mosek_note = load_public_art(args.art_repo)
    load_before = os.getloadavg()
    instances = sample_instances(np.random.default_rng(args.seed), args.n)
    check_same_constants(scenario, instances[0])
    models = [problem.linear_model(instance) for instance in instances]
    inputs = [public_inputs(scenario, i, m) for i, m in zip(instances, models, strict=True)]
    config = RendezvousSolverConfig(scp=replace(SCPParameters(), solver=args.our_solver))
    runs = measure(ocp, instances, inputs, config, args.repeats)
    load_after = os.getloadavg()
    passes = [
        their_plan_passes(i, m, r["theirs"][-1])
        for i, m, r in zip(instances, models, runs, strict=True)
    ]
    rows = instance_rows(instances, runs, passes)
    med, counts = summary(rows), outcome_counts(rows)
    header = [
        f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} CPUs; "
        f"load average (1, 5, 15 min) before {', '.join(f'{v:.2f}' for v in load_before)}, after "
        f"{', '.join(f'{v:.2f}' for v in load_after)}.",
        f"{args.n} instances (seed {args.seed}), {args.repeats} repeats each, medians over the "
        f"repeats, then over the instances. Our solver: {args.our_solver}; theirs: ECOS. "
        f"Public code: {art_root(args.art_repo)}; {mosek_note}.",
    ]
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "per_instance.csv", rows)
    report = markdown(rows, med, counts, header)
    (args.out / "report.md").write_text(report)
    print(report)
    print(f"wrote {args.out / 'per_instance.csv'} and {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
