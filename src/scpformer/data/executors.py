"""Where instances are solved: a local process pool (default) or actors on a Ray cluster.

Both backends run the same :func:`run_task` on one instance index at a time per worker, so a
dataset is the same for any worker count or backend: instance ``i`` draws theta from its own
stream ``SeedSequence(seed, spawn_key=(i,))`` (the ``i``-th child of ``SeedSequence(seed)``),
never from a stream shared with other instances.

Each worker warms up (e.g. compiles the convex subproblem) before it takes a task; the time
limit then counts the solve alone. A worker that runs past the limit is killed and replaced, and
the instance is recorded with status ``timeout``; a worker that dies is replaced and its
instance recorded as ``worker_crashed``. Neither stops the run.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import multiprocessing.connection as mpc
import os
import signal
import socket
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from scpformer.data.errors import DatasetError
from scpformer.data.family import ERROR, TIMEOUT, WORKER_CRASHED, DatasetFamily

MAX_STARTUP_FAILURES = 3  # consecutive warm-up deaths of one worker before giving up


@dataclass(frozen=True)
class TaskResult:
    """One instance's outcome as it travels back from a worker."""

    index: int  # instance index
    status: str
    message: str
    fields: dict[str, Any]  # the family's schema fields (possibly only theta)
    wall_time: float  # s to sample and solve, in the worker
    solve_time: float = 0.0  # s inside the family's solver


def instance_rng(seed: int, index: int) -> np.random.Generator:
    """The random stream of instance ``index``: child ``index`` of ``SeedSequence(seed)``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))


def run_task(family: DatasetFamily, seed: int, index: int) -> TaskResult:
    """Sample instance ``index`` and solve it; an exception becomes status ``error``."""
    start = time.perf_counter()
    try:
        instance = family.sample(instance_rng(seed, index))
        result = family.solve(instance)
    except Exception as err:  # a bug on one instance must not end the run
        last = traceback.format_exception_only(type(err), err)[-1].strip()
        return failed_task(family, seed, index, ERROR, last, time.perf_counter() - start)
    return TaskResult(
        index=index,
        status=result.status,
        message=result.message,
        fields=result.fields,
        wall_time=time.perf_counter() - start,
        solve_time=result.solve_time,
    )


def failed_task(
    family: DatasetFamily, seed: int, index: int, status: str, message: str, wall_time: float
) -> TaskResult:
    """A result for an instance whose solve did not return: theta only, with ``status``."""
    try:
        fields = family.encode_instance(family.sample(instance_rng(seed, index)))
    except Exception:  # the sampler itself failed: store the status alone
        fields = {}
    return TaskResult(index, status, message, fields, wall_time)


class Executor(Protocol):
    """A set of workers that solve instance indices (see the module docstring)."""

    n_workers: int
    backend: str  # "local" or "ray"
    startup_time: float  # s until every worker had warmed up (nan before)

    def submit(self, indices: Iterable[int]) -> None:
        """Queue instance indices; they are handed out in order."""

    def pending(self) -> int:
        """Indices queued or running."""

    def wait(self, timeout: float) -> list[TaskResult]:
        """Results that arrived within ``timeout`` s (timeouts and crashes included)."""

    def close(self) -> None:
        """Stop every worker."""


@dataclass
class _OneAtATime:
    """A pool of workers (:meth:`_workers`: slots or actors, each with the ``index`` it runs,
    None when idle, since ``started``) that solve one instance of ``family`` at a time each,
    from the pool's queue ``_queue`` of instance indices."""

    family: DatasetFamily
    seed: int
    n_workers: int | None
    time_limit: float

    def _workers(self) -> list[Any]:
        raise NotImplementedError

    def submit(self, indices: Iterable[int]) -> None:
        self._queue.extend(indices)

    def pending(self) -> int:
        return len(self._queue) + sum(w.index is not None for w in self._workers())

    def _time_to_deadlines(self) -> list[float]:
        """Seconds until each running instance reaches the time limit."""
        now = time.perf_counter()
        return [w.started + self.time_limit - now for w in self._workers() if w.index is not None]


# -- local process pool ----------------------------------------------------------------------
def _worker_main(conn: mpc.Connection, family: DatasetFamily, seed: int) -> None:
    """Serve instance indices until told to stop; a vanished parent ends it quietly."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the parent's handler (start method fork)
    try:
        _serve(conn, family, seed)
    except (BrokenPipeError, ConnectionResetError, EOFError):
        pass  # the parent stopped (SIGTERM, disk full): no traceback from every worker


def _serve(conn: mpc.Connection, family: DatasetFamily, seed: int) -> None:
    try:
        family.warm_up()
    except Exception as err:
        conn.send(("failed", f"{type(err).__name__}: {err}"))
        return
    conn.send(("ready", None))
    while True:
        try:
            index = conn.recv()
        except (EOFError, OSError):
            return
        if index is None:
            return
        conn.send(("result", run_task(family, seed, index)))


@dataclass
class _Slot:
    process: Any  # multiprocessing Process
    conn: mpc.Connection
    ready: bool = False
    index: int | None = None
    started: float = 0.0
    startup_failures: int = 0


@dataclass
class LocalPool(_OneAtATime):
    """Worker processes on this machine, one instance at a time each."""

    n_workers: int
    start_method: str = "forkserver"
    backend: str = "local"
    startup_time: float = float("nan")
    _queue: deque[int] = field(default_factory=deque)
    _slots: list[_Slot] = field(default_factory=list)
    _t0: float = 0.0

    def __post_init__(self) -> None:
        self._ctx = mp.get_context(self.start_method)
        if self.start_method == "forkserver":
            self._ctx.set_forkserver_preload([type(self.family).__module__])
        self._t0 = time.perf_counter()
        self._slots = [self._start() for _ in range(self.n_workers)]

    def _start(self, failures: int = 0) -> _Slot:
        parent, child = self._ctx.Pipe()
        process = self._ctx.Process(
            target=_worker_main, args=(child, self.family, self.seed), daemon=True
        )
        process.start()
        child.close()
        return _Slot(process=process, conn=parent, startup_failures=failures)

    def _workers(self) -> list[_Slot]:
        return self._slots

    def wait(self, timeout: float) -> list[TaskResult]:
        self._dispatch()
        wait_for = min([timeout, *self._time_to_deadlines()])
        objects = [s.conn for s in self._slots] + [s.process.sentinel for s in self._slots]
        mpc.wait(objects, timeout=max(wait_for, 0.0))
        results = []
        for number, slot in enumerate(self._slots):
            results += self._collect(number, slot)
        results += self._enforce_time_limit()
        self._dispatch()
        return results

    def _collect(self, number: int, slot: _Slot) -> list[TaskResult]:
        try:
            if slot.conn.poll():
                return self._receive(number, slot, slot.conn.recv())
        except (EOFError, OSError):
            pass
        if slot.process.is_alive():
            return []
        return self._died(number, slot)

    def _receive(self, number: int, slot: _Slot, message: tuple[str, Any]) -> list[TaskResult]:
        kind, payload = message
        if kind == "failed":
            self.close()
            raise DatasetError(f"worker failed to warm up: {payload}")
        if kind == "ready":
            slot.ready, slot.startup_failures = True, 0
            if all(s.ready for s in self._slots) and np.isnan(self.startup_time):
                self.startup_time = time.perf_counter() - self._t0
            return []
        slot.index = None
        return [payload]

    def _died(self, number: int, slot: _Slot) -> list[TaskResult]:
        code = slot.process.exitcode
        slot.conn.close()
        if slot.index is None:
            failures = slot.startup_failures + (0 if slot.ready else 1)
            if failures >= MAX_STARTUP_FAILURES:
                self.close()
                raise DatasetError(
                    f"a worker process died {failures} times while warming up (exit code {code})"
                )
            self._slots[number] = self._start(failures)
            return []
        index, wall = slot.index, time.perf_counter() - slot.started
        self._slots[number] = self._start()
        message = f"worker process died (exit code {code}) while solving instance {index}"
        return [failed_task(self.family, self.seed, index, WORKER_CRASHED, message, wall)]

    def _enforce_time_limit(self) -> list[TaskResult]:
        def stop(slot: _Slot) -> None:
            _stop(slot.process, grace=0.0)
            slot.conn.close()

        return _time_out_overdue(self, self._slots, stop)

    def _dispatch(self) -> None:
        for slot in self._slots:
            if not self._queue:
                return
            if slot.ready and slot.index is None and slot.process.is_alive():
                index = self._queue.popleft()
                try:
                    slot.conn.send(index)
                except (BrokenPipeError, OSError):
                    self._queue.appendleft(index)  # the death is noticed by the next wait
                    continue
                slot.index, slot.started = index, time.perf_counter()

    def close(self) -> None:
        for slot in self._slots:
            try:
                slot.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
        for slot in self._slots:
            _stop(slot.process, grace=2.0)
            slot.conn.close()
        self._slots = []


def _time_out_overdue(
    pool: Any, workers: list[Any], stop: Callable[[Any], None]
) -> list[TaskResult]:
    """Stop each of ``pool``'s ``workers`` (slots or actors) whose instance has run past
    ``pool.time_limit``, start a fresh one in its place, and report the instance as timed out."""
    results = []
    now = time.perf_counter()
    for number, worker in enumerate(workers):
        if worker.index is None or now - worker.started <= pool.time_limit:
            continue
        stop(worker)
        index, wall = worker.index, now - worker.started
        workers[number] = pool._start()
        message = f"exceeded the {pool.time_limit:g} s time limit; worker restarted"
        results.append(failed_task(pool.family, pool.seed, index, TIMEOUT, message, wall))
    return results


def _stop(process: Any, grace: float) -> None:
    process.join(grace)
    if process.is_alive():
        process.kill()
        process.join(5.0)


# -- Ray ---------------------------------------------------------------------------------------
class RayWorker:
    """A Ray actor holding one warmed-up family (the remote twin of a local worker)."""

    def __init__(self, family: DatasetFamily, seed: int) -> None:
        self.family, self.seed = family, seed

    def warm_up(self) -> bool:
        self.family.warm_up()
        return True

    def run(self, index: int) -> TaskResult:
        return run_task(self.family, self.seed, index)


@dataclass
class _Actor:
    handle: Any
    ready_ref: Any
    ready: bool = False
    index: int | None = None
    ref: Any = None
    started: float = 0.0


RAY_CONNECT_TIMEOUT = 3.0  # s to wait for a TCP connection to a Ray head before giving up


def check_ray_address(address: str, timeout: float = RAY_CONNECT_TIMEOUT) -> None:
    """Fail fast when a ``host:port`` or ``ray://host:port`` address does not answer.

    ``ray.init`` itself retries for ~20 s and logs many lines first; ``local`` and ``auto``
    are left to it.

    Raises
    ------
    DatasetError
        Naming the address, when it is malformed or nothing listens there.
    """
    if address in ("local", "auto"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise DatasetError(
            f"--ray {address!r}: expected 'local', 'auto', 'host:port' or 'ray://host:port'"
        )
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as err:
        reason = err.strerror or type(err).__name__
        raise DatasetError(
            f"--ray {address!r}: no Ray cluster answers there ({reason} within {timeout:g} s); "
            "start one with `ray start --head`, or use --ray local"
        ) from None


def connect_ray(address: str, workers: int | None) -> bool:
    """``ray.init`` for ``address`` ("local" starts a private local instance).

    Returns whether this call started Ray (and so should shut it down).
    """
    try:
        import ray
    except ImportError:
        raise DatasetError("--ray needs the ray package: pip install 'ray>=2.9'") from None
    if ray.is_initialized():
        return False
    check_ray_address(address)
    kwargs: dict[str, Any] = {
        "log_to_driver": False,
        "include_dashboard": False,
        "logging_level": logging.ERROR,
    }
    if address == "local":
        kwargs["num_cpus"] = workers or os.cpu_count()
    try:
        ray.init(address=address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise DatasetError(f"cannot connect to the Ray cluster at {address!r}: {err}") from None
    return True


@dataclass
class RayPool(_OneAtATime):
    """One Ray actor per worker (``num_cpus=1`` each), one instance at a time each."""

    address: str = "local"
    backend: str = "ray"
    startup_time: float = float("nan")
    _queue: deque[int] = field(default_factory=deque)
    _actors: list[_Actor] = field(default_factory=list)

    def __post_init__(self) -> None:
        import ray

        self._owns_ray = connect_ray(self.address, self.n_workers)
        self._ray = ray
        if self.n_workers is None:  # one actor per CPU of the cluster
            self.n_workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._remote = ray.remote(num_cpus=1, max_restarts=0)(RayWorker)
        self._family_ref = ray.put(self.family)
        self._t0 = time.perf_counter()
        self._actors = [self._start() for _ in range(self.n_workers)]

    def _start(self) -> _Actor:
        handle = self._remote.remote(self._family_ref, self.seed)
        return _Actor(handle=handle, ready_ref=handle.warm_up.remote())

    def _workers(self) -> list[_Actor]:
        return self._actors

    def wait(self, timeout: float) -> list[TaskResult]:
        self._dispatch()
        refs = {self._watched(a): n for n, a in enumerate(self._actors)}
        refs.pop(None, None)
        limits = self._time_to_deadlines()
        if refs:
            wait_for = max(min([timeout, *limits]), 0.0)
            self._ray.wait(list(refs), num_returns=1, timeout=wait_for)
            done, _ = self._ray.wait(list(refs), num_returns=len(refs), timeout=0)
        else:
            done = []
        results = []
        for ref in done:
            results += self._collect(refs[ref], ref)
        results += self._enforce_time_limit()
        self._dispatch()
        return results

    @staticmethod
    def _watched(actor: _Actor) -> Any:
        return actor.ref if actor.ready else actor.ready_ref

    def _collect(self, number: int, ref: Any) -> list[TaskResult]:
        actor = self._actors[number]
        ray = self._ray
        try:
            value = ray.get(ref)
        except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError) as err:
            return self._died(number, actor, err)
        except ray.exceptions.RayTaskError as err:
            if not actor.ready:
                self.close()
                raise DatasetError(f"Ray worker failed to warm up: {err.cause!r}") from None
            return self._died(number, actor, err)
        if not actor.ready:
            actor.ready = True
            if all(a.ready for a in self._actors) and np.isnan(self.startup_time):
                self.startup_time = time.perf_counter() - self._t0
            return []
        actor.index, actor.ref = None, None
        return [value]

    def _died(self, number: int, actor: _Actor, err: Exception) -> list[TaskResult]:
        if actor.index is None:
            self.close()
            raise DatasetError(f"Ray worker died while warming up: {type(err).__name__}")
        index, wall = actor.index, time.perf_counter() - actor.started
        self._actors[number] = self._start()
        message = f"Ray worker died ({type(err).__name__}) while solving instance {index}"
        return [failed_task(self.family, self.seed, index, WORKER_CRASHED, message, wall)]

    def _enforce_time_limit(self) -> list[TaskResult]:
        return _time_out_overdue(
            self, self._actors, lambda actor: self._ray.kill(actor.handle, no_restart=True)
        )

    def _dispatch(self) -> None:
        for actor in self._actors:
            if not self._queue:
                return
            if actor.ready and actor.index is None:
                actor.index = self._queue.popleft()
                actor.ref = actor.handle.run.remote(actor.index)
                actor.started = time.perf_counter()

    def close(self) -> None:
        for actor in self._actors:
            self._ray.kill(actor.handle, no_restart=True)
        self._actors = []
        if self._owns_ray:
            self._ray.shutdown()
            self._owns_ray = False
