"""Task functions for the dead-worker tests: importable by name in pool workers, they kill their own process
with SIGKILL (as the OOM killer would) when their input says so."""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DOOMED_SEED = 13  # `render_or_die` kills its worker for the recording of this seed, every time


@dataclass(frozen=True)
class Job:
    """value: the input; kill: "never", "once" (the first attempt dies: marker file in `marker_dir`) or
    "always"; sleep_s: work time, so that jobs run side by side."""

    value: int
    kill: str = "never"
    marker_dir: str = ""
    sleep_s: float = 0.0


def die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def square_or_die(job: Job) -> tuple[int, int]:
    """(value, value**2), unless this attempt is to die."""
    if job.kill == "always":
        die()
    if job.kill == "once":
        marker = Path(job.marker_dir) / f"killed-{job.value}"
        if not marker.exists():
            marker.write_text("killed once\n")
            die()
    time.sleep(job.sleep_s)
    return job.value, job.value ** 2


def fail(job: Job) -> int:
    raise ValueError(f"bad job {job.value}")


def render_or_die(job: Any) -> Any:
    """`crowdsim.generate.render_job` of a `RecordingJob`, except that the recording of seed DOOMED_SEED kills its
    worker. (The simulator is imported here, not at the top, so that the pool tests' workers start fast.)"""
    from crowdsim.generate import render_job

    if job.spec.seed == DOOMED_SEED:
        die()
    return render_job(job)
