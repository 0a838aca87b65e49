"""The Ray backend of `envs.runner.run_tasks`: each episode is a Ray task (ray is an optional extra).

Connects to a running cluster (`address` "auto" or "HOST:PORT") or starts a local instance with `workers` CPUs;
an already initialised Ray is used as it is. Workers run the same `envs.runner.run_task` as the local pool, so
records are identical across backends.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any


def require_ray() -> Any:
    """The ray module, or ValueError saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise ValueError("--backend ray needs the 'ray' extra (pip install 'groupnav-testbed[ray]')") from exc
    return ray


def init_ray(workers: int, address: str | None) -> Any:
    """Initialise Ray once (connect to `address`, or start a local instance of `workers` CPUs)."""
    ray = require_ray()
    if not ray.is_initialized():
        kw: dict[str, Any] = {"address": address} if address else {"num_cpus": workers}
        ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False, **kw)
    return ray


def run_on_ray(tasks: Sequence[Any], workers: int, address: str | None) -> Iterator[tuple[int, dict[str, Any]]]:
    """Yield (index, result) of each task as its Ray task finishes; unfinished tasks are cancelled on exit."""
    ray = init_ray(workers, address)
    from envs.runner import run_task

    remote = ray.remote(num_cpus=1, max_retries=0)(run_task)
    refs = {remote.remote(task): i for i, task in enumerate(tasks)}
    pending = list(refs)
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield refs[ref], ray.get(ref)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
