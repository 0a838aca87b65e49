"""Atomic file writes for the predictor (torch-free): write to a temporary file beside the target, then rename.

A declared twin of `crowdsim.files.write_atomic` (the predictor may not import crowdsim), checked to behave the same
in tests/test_shared_facts.py. Checkpoints, training logs, evaluation reports and predictions are written with it.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

FILE_MODE = 0o644  # mkstemp creates 0600 files; outputs are meant to be shared


def write_atomic(path: str | Path, write: Callable[[str], None]) -> None:
    """Call `write(tmp_path)` on a temporary file in `path`'s folder, then rename it over `path`; the temporary
    file is removed when `write` raises, so `path` is either the old file or the complete new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
