"""The Ray backend of `envs.runner.run_tasks`: each episode is a Ray task (ray is an optional extra).

It uses crowdsim's Ray helper (`crowdsim.distributed.run_on_ray`): connect to a running cluster (`address`
"auto" or "HOST:PORT") or start a local instance of `workers` CPUs; an already initialised Ray is used as it is.
Workers run the same `envs.runner.run_task` as the local pool, so records are identical across backends.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from crowdsim.distributed import RayUnavailableError, import_ray
from crowdsim.distributed import run_on_ray as _run_on_ray


def require_ray() -> Any:
    """The ray module, or ValueError saying how to install it."""
    try:
        return import_ray()
    except RayUnavailableError as exc:
        raise ValueError(str(exc)) from exc


def run_on_ray(tasks: Sequence[Any], workers: int, address: str | None) -> Iterator[tuple[int, dict[str, Any]]]:
    """Yield (index, result) of each task as its Ray task finishes; unfinished tasks are cancelled on exit."""
    from envs.runner import run_task

    require_ray()
    yield from _run_on_ray(run_task, tasks, address, None if address else workers)
