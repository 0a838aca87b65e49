"""A task function for the dead-worker tests of `envs.evaluation.pool`: importable by name in pool workers, it kills
its own process with SIGKILL (as the OOM killer would) for the marked seeds, then runs the episode as usual."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

from envs.evaluation.episode import EpisodeTask, run_task

DOOMED_SEED = 3  # its worker dies every time
ONCE_SEED = 5  # its worker dies on the first attempt (marker file in the task's error_dir)


def run_or_die(task: EpisodeTask) -> dict[str, Any]:
    """`envs.evaluation.episode.run_task`, except for DOOMED_SEED and the first attempt of ONCE_SEED."""
    marker = Path(task.error_dir or ".") / f"killed-{task.seed}"
    if task.seed == DOOMED_SEED or (task.seed == ONCE_SEED and not marker.exists()):
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text("killed\n")
        os.kill(os.getpid(), signal.SIGKILL)
    return run_task(task)
