"""``scpformer bench art``: ART generation speed, with and without the key-value cache.

Rolls out Algorithm 2 of the ART paper (dynamics in the loop) for a whole horizon: at every
step the model predicts the control from the [target,] R, C, x tokens, the exact linear ROE
dynamics of a sampled ISS rendezvous instance (``linear_model(instance)``, Eq. 10) give the
next state, and R and C are updated (Eq. 20 and the keep-out check of Eq. 21). Side by side:

* ``cached``: one call per step through the preallocated key-value cache (the control token
  of step i rides with the tokens of step i+1, :meth:`feed_action`);
* ``cached, 2 calls``: the control token fed alone (:meth:`predict_state`, as Algorithm 1
  needs for its state prediction);
* ``cached, bf16`` (with ``--bf16``): as ``cached``, multiplying by bfloat16 copies of the
  weights (``model.start(..., bf16=True)``);
* ``cached, int8`` (with ``--int8``): as ``cached``, with int8 weights and dynamically
  quantized activations (``model.start(..., int8=True)``);
* ``no cache``: the full teacher-forcing forward over the whole prefix at every step.

bf16 and int8 kernels do not run on every x86-64 CPU (:mod:`scpformer.models.capabilities`):
where they don't, ``--bf16`` / ``--int8`` print one line saying so, their rows are left out,
and the other modes are timed as usual (exit status 0).

Beside the times: ``vs no cache``, the speed-up over ``no cache`` at the same batch, and
``vs cached``, the relative error of a mode's controls against the float32 ``cached`` run
(float rounding for ``no cache`` and ``2 calls``; the approximation for bf16 and int8).

Times are the median over ``--repeats`` rounds after one untimed run of each mode, the modes
interleaved within a round (see :func:`time_plan`), on ``--threads`` threads;
``wall`` is elapsed time, ``cpu`` this process's CPU time (less sensitive to other load on a
shared machine). torch is imported when the command runs, not when the CLI starts.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from scpformer.files import require_model_path

MODES = ("cached", "cached, 2 calls", "cached, bf16", "cached, int8", "no cache")
FORMATS = {"cached, bf16": "bf16", "cached, int8": "int8"}  # mode -> start() keyword
R_T1 = -0.2  # R(t_1) [m/s] of the random-weight runs: a typical -J_CVX of Table 1 instances


# ======================================================================================
# the rollout
# ======================================================================================
@dataclass(frozen=True)
class Dynamics:
    """Exact linear ROE dynamics of one rendezvous instance (Eq. 10), as float64 tensors."""

    x0: Any  # (6,) initial ROE [m]
    Phi: Any  # (N, 6, 6) STMs
    B: Any  # (N, 6, 3) control input matrices [s]
    Psi: Any  # (N+1, 6, 6) ROE -> RTN
    E_koz: Any  # (3, 3) keep-out ellipsoid: inside when |dr E_koz| < 1 (Eq. 21)
    n_waypoint: int  # N_wp: the keep-out constraint applies at nodes 0..N_wp


def rendezvous_dynamics(steps: int, seed: int) -> Dynamics:
    """The linear model of an instance sampled from Table 1 with N = ``steps``."""
    import torch

    from scpformer.problems.rendezvous.instance import sample_instances
    from scpformer.problems.rendezvous.problem import linear_model
    from scpformer.problems.rendezvous.scenario import RendezvousScenario

    scenario = RendezvousScenario(n_nodes=steps)
    instance = sample_instances(np.random.default_rng(seed), 1, scenario=scenario)[0]
    model = linear_model(instance)
    as_tensor = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
    return Dynamics(
        x0=as_tensor(instance.roe0_m),
        Phi=as_tensor(model.Phi),
        B=as_tensor(model.B),
        Psi=as_tensor(model.Psi),
        E_koz=as_tensor(scenario.E_koz),
        n_waypoint=scenario.n_waypoint,
    )


class CachedPolicy:
    """Controls from the key-value cache; ``two_calls`` feeds each control token alone."""

    def __init__(
        self,
        model,
        batch: int,
        steps: int,
        target,
        two_calls: bool,
        bf16: bool = False,
        int8: bool = False,
    ) -> None:
        self.model, self.two_calls = model, two_calls
        self.cache = model.start(batch, target, max_steps=steps, bf16=bf16, int8=int8)

    def act(self, k: int, rtg, ctg, state):
        return self.model.predict_action(self.cache, rtg, ctg, state)

    def observe(self, k: int, action) -> None:
        if self.two_calls:
            self.model.predict_state(self.cache, action)
        else:
            self.model.feed_action(self.cache, action)


class UncachedPolicy:
    """Controls from a full forward over the whole prefix at every step (no cache)."""

    def __init__(self, model, batch: int, steps: int, target) -> None:
        import torch

        self.model = model
        width = {"rtg": 1, "ctg": 1, "state": model.codec.state_dim}
        width["action"] = model.codec.action_dim
        self.buffers = {key: torch.zeros(batch, steps, w) for key, w in width.items()}
        self.target = target

    def act(self, k: int, rtg, ctg, state):
        import torch

        for key, value in (("rtg", rtg), ("ctg", ctg), ("state", state)):
            self.buffers[key][:, k] = value
        prefix = {key: value[:, : k + 1] for key, value in self.buffers.items()}
        if self.target is not None:
            prefix["target"] = self.target
        with torch.no_grad():
            predictions, _ = self.model(prefix)
        return predictions["action"][:, k]

    def observe(self, k: int, action) -> None:
        self.buffers["action"][:, k] = action


def rollout(policy, dynamics: Dynamics, normalization, frame: str, batch: int, steps: int):
    """Algorithm 2: controls (B, N, 3) [m/s] and states (B, N+1, 6) ROE [m].

    Each step's maps are composed before the loop (:func:`step_maps`), so that one step
    outside the model is a handful of small products.
    """
    import torch

    maps = step_maps(dynamics, normalization, frame, steps)
    state_map, state_shift, action_gain, action_shift, keep_out, Phi_t, Phi_B_t = (
        t.unbind(0)  # per-step views, made once
        for t in (maps.state_map, maps.state_shift, maps.action_gain, maps.action_shift,
                  maps.keep_out, maps.Phi_t, maps.Phi_B_t)
    )  # fmt: skip
    x = dynamics.x0.expand(batch, 6).clone()  # (B, 6) ROE [m]
    rtg = torch.full((batch, 1), R_T1, dtype=torch.float64)  # R(t_1) [m/s]
    ctg = torch.zeros(batch, 1, dtype=torch.float64)  # C(t_1)
    states, actions = [x], []
    for k in range(steps):
        u_norm = policy.act(
            k,
            (rtg * maps.rtg_gain).float(),
            (ctg * maps.ctg_gain).float(),
            torch.addmm(state_shift[k], x, state_map[k]).float(),
        )  # (B, 3), the model's inputs normalized as normalization.encode does
        policy.observe(k, u_norm)
        u = torch.addcmul(action_shift[k], u_norm.double(), action_gain[k])  # [m/s]
        rtg = rtg - u.norm(dim=1, keepdim=True)  # Eq. 20
        if k <= dynamics.n_waypoint:  # Eq. 21: keep-out violation at node k
            ctg = ctg - ((x @ keep_out[k]).norm(dim=1, keepdim=True) < 1.0).double()
        x = torch.addmm(x @ Phi_t[k], u, Phi_B_t[k])  # Eq. 10: Phi (x + B u)
        states.append(x)
        actions.append(u)
    return torch.stack(actions, 1), torch.stack(states, 1)


@dataclass(frozen=True)
class StepMaps:
    """Per-step linear maps of :func:`rollout` (row vectors: ``y = x M + c``), float64."""

    state_map: Any  # (N, 6, 6): ROE -> normalized model input (frame change / std)
    state_shift: Any  # (N, 6)
    rtg_gain: float  # normalized R per m/s
    ctg_gain: float
    action_gain: Any  # (N, 3): normalized control -> m/s
    action_shift: Any  # (N, 3)
    keep_out: Any  # (N, 6, 3): ROE -> dr E_koz (Eq. 21)
    Phi_t: Any  # (N, 6, 6): Phi_k^T
    Phi_B_t: Any  # (N, 3, 6): (Phi_k B_k)^T


def step_maps(dynamics: Dynamics, normalization, frame: str, steps: int) -> StepMaps:
    """The maps of :func:`rollout`, the normalization's affine maps read off its encode and
    decode (of zeros and ones, so that they are the normalization's own statistics)."""
    import torch

    def affine(method, key: str, width: int, rows: int):
        zero = torch.zeros(1, rows, width, dtype=torch.float64)
        shift = method(key, zero)[0]  # (N, w)
        return method(key, zero + 1.0)[0] - shift, shift

    gain, shift = affine(normalization.encode, "state", 6, steps)  # (N, 6) each
    frame_t = dynamics.Psi[:steps].transpose(1, 2) if frame == "rtn" else torch.eye(6).double()
    action_gain, action_shift = affine(normalization.decode, "action", 3, steps)
    one = torch.ones(1, 1, 1, dtype=torch.float64)
    return StepMaps(
        state_map=frame_t * gain[:, None, :],
        state_shift=shift,
        rtg_gain=float(normalization.encode("rtg", one)),
        ctg_gain=float(normalization.encode("ctg", one)),
        action_gain=action_gain,
        action_shift=action_shift,
        keep_out=dynamics.Psi[:steps, :3].transpose(1, 2) @ dynamics.E_koz,
        Phi_t=dynamics.Phi.transpose(1, 2),
        Phi_B_t=(dynamics.Phi @ dynamics.B).transpose(1, 2),
    )


def unit_normalization(steps: int, state_dim: int, action_dim: int):
    """Statistics of the random-weight runs: zero means, typical Table 1 magnitudes."""
    from scpformer.models.normalization import ArtNormalization

    return ArtNormalization(
        state_mean=np.zeros((steps + 1, state_dim)),
        state_std=np.full((steps + 1, state_dim), 100.0),  # [m]
        action_mean=np.zeros((steps, action_dim)),
        action_std=np.full((steps, action_dim), 0.01),  # [m/s]
        rtg_scale=0.2,
        ctg_scale=10.0,
    )


# ======================================================================================
# timing
# ======================================================================================
@dataclass(frozen=True)
class Timing:
    mode: str
    batch: int
    wall_s: float  # median elapsed time of one rollout
    cpu_s: float  # median process CPU time of one rollout
    repeats: int
    error: float | None = None  # |u - u_cached| / |u_cached| of the controls (same batch)

    @property
    def per_second(self) -> float:
        """Trajectories per second (wall)."""
        return self.batch / self.wall_s


def time_runs(run: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """Median (wall, cpu) seconds of ``repeats`` calls after one untimed call."""
    run()
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        run()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def rollout_of(setup: dict[str, Any], mode: str, batch: int) -> Callable[[], Any]:
    """One call: a fresh policy of ``mode`` and a whole rollout; returns the controls."""
    model, steps = setup["model"], setup["steps"]
    target = setup["target"]
    target = None if target is None else target.expand(batch, -1)

    def run():
        if mode == "no cache":
            policy = UncachedPolicy(model, batch, steps, target)
        else:
            fmt = {FORMATS[mode]: True} if mode in FORMATS else {}
            policy = CachedPolicy(model, batch, steps, target, mode == "cached, 2 calls", **fmt)
        actions, _ = rollout(
            policy, setup["dynamics"], setup["normalization"], setup["frame"], batch, steps
        )
        return actions

    return run


def time_plan(
    setup: dict[str, Any], plan: list[tuple[str, int]], repeats: int, progress: bool = False
) -> list[Timing]:
    """Median (wall, cpu) seconds of each (mode, batch) of ``plan`` over ``repeats`` rounds.

    Every mode runs once untimed, then the rounds interleave the modes (one timed rollout
    of each per round), so that a change of the machine's load hits them alike and their
    ratios stay meaningful on a shared machine.
    """
    runs = {key: rollout_of(setup, *key) for key in plan}
    controls = {key: run() for key, run in runs.items()}  # untimed warm-up
    walls: dict[tuple[str, int], list[float]] = {key: [] for key in plan}
    cpus: dict[tuple[str, int], list[float]] = {key: [] for key in plan}
    for r in range(repeats):
        for key, run in runs.items():
            wall, cpu = time.perf_counter(), time.process_time()
            run()
            walls[key].append(time.perf_counter() - wall)
            cpus[key].append(time.process_time() - cpu)
        if progress:
            print(f"  round {r + 1}/{repeats} done", flush=True)
    timings = []
    for mode, batch in plan:
        reference = controls.get(("cached", batch))
        error = None
        if mode != "cached" and reference is not None:
            diff = controls[mode, batch] - reference
            error = float(diff.norm() / reference.norm().clamp_min(1e-300))
        wall, cpu = statistics.median(walls[mode, batch]), statistics.median(cpus[mode, batch])
        timings.append(Timing(mode, batch, wall, cpu, repeats, error))
    return timings


def time_mode(setup: dict[str, Any], mode: str, batch: int, repeats: int) -> Timing:
    """:func:`time_plan` of one mode."""
    return time_plan(setup, [(mode, batch)], repeats)[0]


def load_setup(args: argparse.Namespace) -> dict[str, Any]:
    """Model, normalization, frame and dynamics of the bench."""
    import torch

    torch.manual_seed(args.seed)
    if args.model is not None and args.preset is not None:
        raise ValueError("--preset sizes random weights; --model gives a trained run")
    if args.model is not None:
        from scpformer.models.checkpoint import load_checkpoint

        checkpoint = load_checkpoint(require_model_path(args.model))
        model, frame = checkpoint.model, checkpoint.frame
        normalization = checkpoint.normalization
        label = f"{args.model} ({checkpoint.kind}, {checkpoint.family}, {frame})"
    else:
        from scpformer.models import build_model, preset

        preset_name = args.preset or "small"
        config = preset("art", preset_name, target_dim=6 if args.target else 0)
        model, frame, normalization = build_model("art", config), "rtn", None
        label = f"ART {preset_name} preset, random weights"
    model.eval()
    codec = model.codec
    if args.steps > codec.context:
        raise ValueError(f"--steps {args.steps} exceeds the model's context {codec.context}")
    if normalization is None:
        normalization = unit_normalization(args.steps, codec.state_dim, codec.action_dim)
    target = torch.zeros(1, codec.target_dim) if codec.target_dim else None
    return {
        "model": model,
        "label": label,
        "frame": frame,
        "normalization": normalization,
        "target": target,  # normalized target state 0 (the training mean) when it has one
        "steps": args.steps,
        "dynamics": rendezvous_dynamics(args.steps, args.seed),
    }


def check_args(args: argparse.Namespace) -> None:
    for name in ("batch", "repeats", "threads"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be at least 1, got {getattr(args, name)}")
    if args.steps < 11:
        raise ValueError(
            f"--steps must be at least 11 (the waypoint is 10 before), got {args.steps}"
        )
    if args.model is not None and args.target:
        raise ValueError("--target applies to random weights; a trained --model has its own")


def report(setup: dict[str, Any], timings: list[Timing], threads: int) -> list[str]:
    model = setup["model"]
    uncached = {t.batch: t for t in timings if t.mode == "no cache"}
    lines = [
        f"{setup['label']}: {model.num_parameters() / 1e6:.2f} M parameters, "
        f"{setup['steps']} steps, dynamics in the loop (rendezvous linear model), "
        f"{threads} thread(s), median of {timings[0].repeats} interleaved runs",
        f"{'mode':<17} {'batch':>5} {'wall ms':>9} {'cpu ms':>9} {'traj/s':>8} "
        f"{'vs no cache':>11} {'vs cached':>9}",
    ]
    for t in timings:
        slow = uncached.get(t.batch)
        ratio = f"{slow.wall_s / t.wall_s:>10.1f}x" if slow and slow is not t else f"{'':>11}"
        error = f"{t.error:>9.1e}" if t.error is not None else f"{'':>9}"
        lines.append(
            f"{t.mode:<17} {t.batch:>5} {1e3 * t.wall_s:>9.1f} {1e3 * t.cpu_s:>9.1f} "
            f"{t.per_second:>8.1f} {ratio} {error}"
        )
    lines.append(
        "vs no cache: speed-up of wall time over the run without the cache (same batch); "
        "vs cached: relative error of the controls against the float32 cached run"
    )
    return lines


def low_precision_note(flag: str) -> str | None:
    """None when ``--bf16`` / ``--int8`` kernels run here, else the one line saying they don't."""
    from scpformer.models.capabilities import unavailable_reason

    reason = unavailable_reason(flag)
    if reason is None:
        return None
    return f"--{flag}: {flag} generation is not available on this machine ({reason}); rows skipped"


def run_bench(args: argparse.Namespace) -> int:
    check_args(args)
    import torch

    torch.set_num_threads(args.threads)
    setup = load_setup(args)
    plan = [("cached", 1), ("cached, 2 calls", 1)]
    if not args.skip_uncached:
        plan.append(("no cache", 1))
    plan.append(("cached", args.batch))
    for flag, mode in (("int8", "cached, int8"), ("bf16", "cached, bf16")):
        note = low_precision_note(flag) if getattr(args, flag) else "not asked"
        if note is None:
            plan[1:1] = [(mode, 1)]
            plan.append((mode, args.batch))
        elif note != "not asked":
            print(note, flush=True)
    plan = list(dict.fromkeys(plan))  # --batch 1: each (mode, batch) once
    timings = time_plan(setup, plan, args.repeats, progress=True)
    print("\n".join(report(setup, timings, args.threads)))
    return 0
