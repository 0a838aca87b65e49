"""Where independent tasks run: a local process pool that survives dead workers, or Ray tasks.

`run_in_processes` runs tasks on this machine's cores (a `ProcessPoolExecutor`, rebuilt when a worker dies) and
is the local backend of both `crowdsim.generate.make_dataset` and `envs.evaluation.pool.run_tasks`.
`run_on_ray` is their Ray backend (the optional `ray` extra): one Ray task per job. `ray` is imported inside the
functions only, so crowdsim imports and runs without it. The tasks return the recording's files as texts and
the caller writes them (atomically, on the machine that asked for the dataset), so a multi-node cluster needs
no shared file system and the bytes equal the local backend's.
"""

from __future__ import annotations

import multiprocessing
import signal
import sys
from collections.abc import Callable, Generator, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.context import BaseContext
from types import ModuleType
from typing import Any, TypeVar

from crowdsim.names import unknown_name

BACKENDS = ("local", "ray")  # where independent tasks run: this machine's processes, or Ray tasks
RAY_MISSING = "--backend ray needs the 'ray' extra (pip install ray)"

J = TypeVar("J")
R = TypeVar("R")


def check_backend(backend: str) -> None:
    """ValueError naming the valid backends unless `backend` is one of `BACKENDS`."""
    if backend not in BACKENDS:
        raise ValueError(unknown_name("backend", backend, BACKENDS))


class RayUnavailableError(ImportError):
    """`ray` cannot be imported."""


def import_ray() -> ModuleType:
    """The `ray` module, or RayUnavailableError (message: RAY_MISSING) when the extra is not installed."""
    try:
        import ray
    except ImportError as exc:
        raise RayUnavailableError(RAY_MISSING) from exc
    return ray


@contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None) -> Iterator[ModuleType]:
    """Yield the `ray` module, initialised.

    An already initialised Ray is used as it is and left running. Otherwise address None starts a local
    instance with `num_cpus` CPUs (None: all cores) and "auto" or "HOST:PORT" connects to a running
    cluster; either is shut down on exit.
    """
    if address is not None and num_cpus is not None:
        raise ValueError("num_cpus sizes a local Ray instance; with an address the cluster's CPUs decide")
    ray = import_ray()
    started = not ray.is_initialized()
    if started:
        if address is None:
            ray.init(num_cpus=num_cpus, include_dashboard=False)
        else:
            ray.init(address=address)
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


def run_on_ray(fn: Callable[[J], R], jobs: Sequence[J], address: str | None = None,
               num_cpus: int | None = None) -> Iterator[tuple[int, R | WorkerDied]]:
    """Run `fn(job)` for every job as a Ray task of one CPU, yielding (index in jobs, result) in order of
    completion. `fn` must be importable by name on the workers (a module-level function of an installed
    package); address and num_cpus as in `ray_session`. As in `run_in_processes`, a task whose worker dies is
    run once more (Ray's own retry), and after a second death yields `WorkerDied` naming the cause. Tasks still
    pending when the caller stops (an error, or the generator closed) are cancelled."""
    with ray_session(address, num_cpus) as ray:
        from ray.exceptions import OutOfMemoryError, WorkerCrashedError

        task = ray.remote(num_cpus=1, max_retries=1)(fn)
        index: dict[Any, int] = {task.remote(job): i for i, job in enumerate(jobs)}
        pending = list(index)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    try:
                        result: R | WorkerDied = ray.get(ref)
                    except (WorkerCrashedError, OutOfMemoryError) as exc:
                        what = "killed by Ray's memory monitor" if isinstance(exc, OutOfMemoryError) else "died"
                        result = WorkerDied(f"Ray worker process {what} twice while running this task")
                    yield index[ref], result
        finally:
            for ref in pending:
                ray.cancel(ref)


# --- the local process pool ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class WorkerDied:
    """What `run_in_processes` yields for a task whose worker process died twice while running it (an OOM
    kill, a crash in native code), instead of its result. message: the cause, e.g. "worker process died
    (signal 9, SIGKILL) twice while running this task"."""

    message: str

    def __str__(self) -> str:
        return self.message


def process_context(preload: Sequence[str] = ()) -> BaseContext:
    """The start method of the local pools: forkserver where available (no fork of a threaded parent; torch is
    not fork-safe), with `preload` modules imported once in the server; spawn elsewhere."""
    if sys.platform.startswith("linux") and "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        if preload:
            ctx.set_forkserver_preload(list(preload))
        return ctx
    return multiprocessing.get_context("spawn")


def describe_exit(exitcode: int | None) -> str:
    """How a worker process ended, from its exit code (negative: the signal that killed it)."""
    if exitcode is None or exitcode == 0:
        return "worker process died"
    if exitcode < 0:
        try:
            return f"worker process died (signal {-exitcode}, {signal.Signals(-exitcode).name})"
        except ValueError:
            return f"worker process died (signal {-exitcode})"
    return f"worker process died (exit code {exitcode})"


_STARTED: Any = None  # in a worker of run_in_processes: the queue on which it announces each task it starts


def _init_worker(started: Any) -> None:
    """In each worker: keep the announcement pipe, and ignore SIGINT. A terminal's Ctrl-C reaches the whole process
    group; the parent alone handles it (it stops submitting and waits for the running jobs), so a worker inside a
    solve neither prints a stray KeyboardInterrupt nor dies half-way through writing a file."""
    global _STARTED
    _STARTED = started
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _call(fn: Callable[[J], R], index: int, job: J) -> R:
    """Run in a worker: announce `index` (a synchronous pipe write, so it survives a SIGKILL a moment later),
    then run the job."""
    _STARTED.put(index)
    return fn(job)


class _Lane:
    """One process pool and the jobs submitted to it. After a break: `unfinished` (no result), `started` (the
    jobs the workers announced, i.e. those that may have been running when a worker died) and `cause`."""

    def __init__(self, fn: Callable[[J], R], jobs: Sequence[J], indices: Sequence[int], width: int,
                 ctx: BaseContext) -> None:
        self.queue = ctx.SimpleQueue()
        self.pool = ProcessPoolExecutor(max_workers=width, mp_context=ctx, initializer=_init_worker,
                                        initargs=(self.queue,))
        self.futures: dict[Future, int] = {}
        self.unsubmitted: list[int] = []  # jobs left out because a worker died while the pool was being filled
        for k, i in enumerate(indices):
            try:
                self.futures[self.pool.submit(_call, fn, i, jobs[i])] = i
            except BrokenProcessPool:  # an early job already killed its worker: the rest never started
                self.unsubmitted = list(indices[k:])
                break
        self.started: set[int] = set()
        self.unfinished: list[int] = []
        self.cause = ""

    def drain(self) -> None:
        """Read the start announcements (also keeps the pipe from filling up on long runs)."""
        while not self.queue.empty():
            self.started.add(self.queue.get())

    def settle_broken(self, yielded: set[Future]) -> list[tuple[int, Any]]:
        """After a BrokenProcessPool: wait for the pool to wind down, return (index, result) of the jobs that
        finished but were not yet `yielded`, and set `unfinished`, `started` and `cause` (from the exit codes of
        the pool's processes: the pool terminates the survivors with SIGTERM, so another code names the death
        when there is one)."""
        processes = list((getattr(self.pool, "_processes", None) or {}).values())  # private; None after shutdown
        self.pool.shutdown(wait=True)
        self.drain()
        codes = [p.exitcode for p in processes if p.exitcode not in (0, None)]
        self.cause = describe_exit(([c for c in codes if c != -signal.SIGTERM] or codes or [None])[0])
        done = []
        self.unfinished.extend(self.unsubmitted)  # not started: they simply run again
        for fut, i in self.futures.items():
            if fut in yielded:
                continue
            if isinstance(fut.exception(), BrokenProcessPool):
                self.unfinished.append(i)
            else:
                done.append((i, fut.result()))  # a job's own exception is raised here, as in a healthy pool
        return done


def _run_lanes(lanes: list[_Lane]) -> Generator[tuple[int, Any], None, list[_Lane]]:
    """Yield (index, result) of the lanes' jobs as they finish; return the lanes that broke (settled)."""
    owner = {fut: lane for lane in lanes for fut in lane.futures}
    yielded: set[Future] = set()
    broken: list[_Lane] = []
    while owner:
        done, _ = wait(owner, return_when=FIRST_COMPLETED)
        for lane in {owner[f] for f in done}:
            lane.drain()
        for fut in done:
            lane = owner.pop(fut, None)
            if lane is None:  # settled with its broken lane
                continue
            if not isinstance(fut.exception(), BrokenProcessPool):
                yielded.add(fut)
                yield lane.futures[fut], fut.result()
                continue
            broken.append(lane)
            for other in lane.futures:
                owner.pop(other, None)
            yield from lane.settle_broken(yielded)
    return broken


def run_in_processes(fn: Callable[[J], R], jobs: Sequence[J], workers: int,
                     mp_context: BaseContext | None = None) -> Iterator[tuple[int, R | WorkerDied]]:
    """Run `fn(job)` for every job in a pool of `workers` processes, yielding (index in jobs, result) in order of
    completion. `fn` must be importable by name in the workers (a module-level function).

    A worker that dies (SIGKILL by the OOM killer, a segfault) does not end the run: the pool is rebuilt and the
    jobs without a result run again. The pool cannot tell which of the jobs running at that moment killed it,
    so each of them (a suspect) runs again alone, in a pool of its own: a job whose lone worker dies too is
    yielded as `WorkerDied` naming the cause, and the jobs that merely ran beside it finish normally. Jobs that
    had not started are simply resubmitted. An exception raised by `fn` is raised here, as by a plain pool.
    When the caller stops early (an error, or the generator closed), pending jobs are cancelled and the
    running ones waited for. mp_context: default `process_context()`.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    ctx = mp_context or process_context()
    todo, suspects = list(range(len(jobs))), []
    deaths: dict[int, int] = {}  # job -> deaths of a worker while it was running
    idle_breaks = 0  # consecutive breaks in which no job was running (a worker that dies at start-up)
    lanes: list[_Lane] = []
    try:
        while todo or suspects:
            if suspects:  # one pool per suspect, so that a death names its job
                lanes = [_Lane(fn, jobs, [i], 1, ctx) for i in suspects[:workers]]
                suspects = suspects[workers:]
            else:
                lanes, todo = [_Lane(fn, jobs, todo, min(workers, len(todo)), ctx)], []
            broken = yield from _run_lanes(lanes)
            for lane in lanes:
                lane.pool.shutdown(wait=True)
            for lane in broken:
                running = [i for i in lane.unfinished if i in lane.started]
                todo.extend(i for i in lane.unfinished if i not in lane.started)
                idle_breaks = 0 if running else idle_breaks + 1
                if idle_breaks >= 2:
                    raise RuntimeError(f"{lane.cause} twice before running a task; the process pool cannot start")
                for i in running:
                    deaths[i] = deaths.get(i, 0) + 1
                    if deaths[i] >= 2:
                        yield i, WorkerDied(f"{lane.cause} twice while running this task")
                    else:
                        suspects.append(i)
            todo.sort()
    finally:
        for lane in lanes:
            lane.pool.shutdown(wait=True, cancel_futures=True)
