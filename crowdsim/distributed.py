"""Ray backend of `make_dataset`: one Ray task per recording (the optional `ray` extra).

`ray` is imported inside the functions only, so crowdsim imports and runs without it. The tasks return
the recording's files as texts and the caller writes them (atomically, on the machine that asked for the
dataset), so a multi-node cluster needs no shared file system and the bytes equal the local backend's.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from types import ModuleType
from typing import Any, TypeVar

RAY_MISSING = "--backend ray needs the 'ray' extra (pip install ray)"

J = TypeVar("J")
R = TypeVar("R")


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
               num_cpus: int | None = None) -> Iterator[tuple[int, R]]:
    """Run `fn(job)` for every job as a Ray task of one CPU, yielding (index in jobs, result) in order of
    completion. `fn` must be importable by name on the workers (a module-level function of an installed
    package); address and num_cpus as in `ray_session`. Tasks still pending when the caller stops (an
    error, or the generator closed) are cancelled."""
    with ray_session(address, num_cpus) as ray:
        task = ray.remote(num_cpus=1)(fn)
        index: dict[Any, int] = {task.remote(job): i for i, job in enumerate(jobs)}
        pending = list(index)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    yield index[ref], ray.get(ref)
        finally:
            for ref in pending:
                ray.cancel(ref)
