"""The one atomic-write helper: write to a temporary file beside the target, then rename it over the target."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

FILE_MODE = 0o644  # mkstemp creates 0600 files; reports are meant to be shared


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


def write_text_atomic(path: str | Path, text: str) -> None:
    """Text written atomically (see `write_atomic`)."""
    write_atomic(path, lambda tmp: Path(tmp).write_text(text))


def write_json_atomic(path: str | Path, obj: Any) -> None:
    """JSON (strict: no NaN or inf) written atomically."""
    text = json.dumps(obj, indent=2, allow_nan=False) + "\n"
    write_text_atomic(path, text)


def append_line(path: str | Path, line: str) -> None:
    """Append one line with a single `write` on an O_APPEND descriptor, then fsync: concurrent appenders never
    interleave inside a line, and a crash leaves at most a partial last line (which readers skip)."""
    if "\n" in line:
        raise ValueError("append_line takes a single line without newlines")
    data = (line + "\n").encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, FILE_MODE)
    try:
        written = os.write(fd, data)
        if written != len(data):
            raise OSError(f"short append to {path}: {written} of {len(data)} bytes")
        os.fsync(fd)
    finally:
        os.close(fd)


def check_writable_dir(path: str | Path) -> Path:
    """Check, without creating anything, that folder `path` exists or can be created and written into; raise
    OSError naming the path otherwise. Called before any episode runs, so a bad output path fails fast and a
    misuse leaves nothing behind."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OSError(f"{path} exists and is not a folder")
    probe = path.absolute()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise OSError(f"cannot create {path}: {probe} is a file")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OSError(f"cannot write into {probe}")
    return path


def check_writable_file(path: str | Path) -> Path:
    """Check that file `path` can be written (not a folder; its folder exists or can be created)."""
    path = Path(path)
    if path.is_dir():
        raise OSError(f"{path} is a folder, expected a file path")
    check_writable_dir(path.parent)
    return path
