"""Writing files safely: atomic writes and the check that an output folder can really be written.

The project's one implementation of both for crowdsim and envs (envs imports it: `envs.atomic`). The predictor may
not import crowdsim and keeps a twin for its checkpoints and reports (`predictor.checkpoint.write_atomic`).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

FILE_MODE = 0o644  # mkstemp creates 0600 files; outputs are meant to be shared


def write_atomic(path: str | Path, write: Callable[[str], None]) -> None:
    """Call `write(tmp_path)` on a temporary file in `path`'s folder, then rename it over `path`; the temporary
    file is removed when `write` raises (Ctrl-C included), so `path` is either the old file or the complete new one.
    A process killed by a signal meanwhile leaves only a hidden `.<name>.<random>.part` file."""
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
    """UTF-8 text with "\\n" line ends, written atomically (see `write_atomic`)."""
    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
    write_atomic(path, write)


def check_writable_dir(path: str | Path) -> Path:
    """`path` if it is, or can be created as, a folder this process can write into; OSError naming the path
    otherwise. Tried for real (a probe folder made and removed at once in the nearest existing ancestor), since
    permission bits do not tell: root may write anywhere, yet not under /proc or on a read-only mount. Creates and
    leaves nothing, so a bad output path fails before any work."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OSError(f"{path} exists and is not a folder")
    for p in (path.absolute(), *path.absolute().parents):
        if p.exists():
            if not p.is_dir():
                raise OSError(f"{p} is a file, not a folder")
            try:
                os.rmdir(tempfile.mkdtemp(prefix=".probe-", dir=p))
            except OSError as exc:
                raise OSError(f"cannot create folders in {p} ({exc.strerror or exc})") from None
            return path
    return path  # unreachable: the root exists


def check_writable_file(path: str | Path) -> Path:
    """`path` if file `path` can be written (not a folder; its folder exists or can be created); OSError otherwise."""
    path = Path(path)
    if path.is_dir():
        raise OSError(f"{path} is a folder, expected a file path")
    check_writable_dir(path.parent)
    return path
