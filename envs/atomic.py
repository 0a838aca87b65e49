"""The env's file writing: atomic writes and the writable-folder check are crowdsim's (`crowdsim.files`, the one
implementation); JSON reports and the append-only record lines are built on them here."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from crowdsim.files import FILE_MODE, check_writable_dir, check_writable_file, write_atomic, write_text_atomic

__all__ = ["append_line", "check_writable_dir", "check_writable_file", "write_atomic", "write_json_atomic",
           "write_text_atomic"]


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
