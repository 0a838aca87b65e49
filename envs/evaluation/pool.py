"""Where episodes run: `run_tasks` over the local process pool (the default), this process, or Ray tasks.

The local pool uses "forkserver" on Linux (torch is not fork-safe). The Ray backend (the optional `ray` extra) uses
crowdsim's Ray helper (`crowdsim.distributed.run_on_ray`): connect to a running cluster (`address` "auto" or
"HOST:PORT") or start a local instance of `workers` CPUs; an already initialised Ray is used as it is. Every backend
runs the same `envs.evaluation.episode.run_task`, so records are identical across backends and worker counts.
"""

from __future__ import annotations

import multiprocessing
import sys
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from crowdsim.distributed import RayUnavailableError, import_ray
from crowdsim.distributed import run_on_ray as _run_on_ray
from envs.evaluation.episode import EpisodeTask, run_task

BACKENDS = ("local", "ray")


def require_ray() -> Any:
    """The ray module, or ValueError saying how to install it."""
    try:
        return import_ray()
    except RayUnavailableError as exc:
        raise ValueError(str(exc)) from exc


def _mp_context() -> multiprocessing.context.BaseContext:
    if sys.platform.startswith("linux") and "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["envs.evaluation.episode"])  # imports once (no torch: not fork-safe)
        return ctx
    return multiprocessing.get_context("spawn")


def run_tasks(tasks: Sequence[EpisodeTask], workers: int = 1, backend: str = "local",
              address: str | None = None) -> Iterator[tuple[int, dict[str, Any]]]:
    """Run the tasks, yielding (index into `tasks`, result) as each finishes (order not guaranteed).

    backend "local": `workers` processes (1: this process); "ray": Ray tasks on the cluster at `address`
    ("auto", "HOST:PORT") or, with None, a local Ray instance of `workers` CPUs. An error that is not a
    policy's (e.g. an env that cannot be built) stops the run and is raised.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; valid names: {', '.join(BACKENDS)}")
    if backend == "ray":
        require_ray()
        yield from _run_on_ray(run_task, tasks, address, None if address else workers)
    elif workers <= 1 or len(tasks) <= 1:
        for i, task in enumerate(tasks):
            yield i, run_task(task)
    else:
        with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=_mp_context()) as pool:
            futures = {pool.submit(run_task, task): i for i, task in enumerate(tasks)}
            pending = set(futures)
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in done:
                        yield futures[fut], fut.result()
            finally:
                for fut in pending:
                    fut.cancel()
