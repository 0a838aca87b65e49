"""Where episodes run: `run_tasks` over the local process pool (the default), this process, or Ray tasks.

The local pool is crowdsim's (`crowdsim.distributed.run_in_processes`, "forkserver" on Linux: torch is not
fork-safe): a worker that dies (the OOM killer's SIGKILL) does not end the run; its episodes run again on a fresh
worker, and one whose worker dies twice becomes an error record naming the cause, with one line on stderr. The
Ray backend (the optional `ray` extra) uses crowdsim's Ray helper (`crowdsim.distributed.run_on_ray`): connect to a
running cluster (`address` "auto" or "HOST:PORT") or start a local instance of `workers` CPUs; an already
initialised Ray is used as it is. Every backend runs the same `envs.evaluation.episode.run_task`, so records are
identical across backends and worker counts.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from contextlib import closing
from typing import Any

from crowdsim.distributed import (
    RayUnavailableError,
    WorkerDied,
    check_backend,
    import_ray,
    process_context,
    run_in_processes,
)
from crowdsim.distributed import run_on_ray as _run_on_ray
from envs.evaluation.episode import EpisodeTask, error_record, run_task


def require_ray() -> Any:
    """The ray module, or ValueError saying how to install it."""
    try:
        return import_ray()
    except RayUnavailableError as exc:
        raise ValueError(str(exc)) from exc


def run_tasks(tasks: Sequence[EpisodeTask], workers: int = 1, backend: str = "local",
              address: str | None = None) -> Iterator[tuple[int, dict[str, Any]]]:
    """Run the tasks, yielding (index into `tasks`, result) as each finishes (order not guaranteed).

    backend "local": `workers` processes (1: this process); "ray": Ray tasks on the cluster at `address`
    ("auto", "HOST:PORT") or, with None, a local Ray instance of `workers` CPUs. An error that is not a
    policy's (e.g. an env that cannot be built) stops the run and is raised. A task whose worker process died
    twice (local pool or Ray) yields {"record": error record} (outcome "error", the cause in `error`).
    """
    check_backend(backend)
    if backend == "ray":
        require_ray()
        results = _run_on_ray(run_task, tasks, address, None if address else workers)
    elif workers <= 1 or len(tasks) <= 1:
        results = ((i, run_task(task)) for i, task in enumerate(tasks))
    else:
        ctx = process_context(["envs.evaluation.episode"])  # imported once (no torch: not fork-safe)
        results = run_in_processes(run_task, tasks, min(workers, len(tasks)), ctx)
    with closing(results):
        for i, result in results:
            if isinstance(result, WorkerDied):
                task = tasks[i]
                _warn(f"crowdnav: episode {task.cell or 'episode'}/{task.policy.name}/seed {task.seed} recorded as "
                      f"an error: {result}")
                result = {"record": error_record(task, str(result))}
            yield i, result


def _warn(line: str) -> None:
    """One line on stderr, without breaking a progress bar."""
    from tqdm.auto import tqdm

    tqdm.write(line, file=sys.stderr)
