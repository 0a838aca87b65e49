"""Readers for ETH/UCY-format trajectory files and crowdsim group-label files.

A trajectory file has one row per (frame, pedestrian): ``frame ped x y`` separated by tabs or
whitespace, positions in metres. A group file (``X.groups.txt`` beside ``X.txt``) holds one group
per line, member pedestrian ids separated by whitespace; blank lines are allowed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

GROUP_SUFFIX = ".groups.txt"


class DataFormatError(ValueError):
    """A trajectory or group file does not follow the expected format."""


@dataclass(frozen=True)
class Recording:
    """One trajectory file.

    Attributes:
        path: source file.
        rows: (R, 4) float64 array of ``frame, ped, x, y`` (x, y in metres).
        groups: ground-truth groups as a tuple of tuples of ped ids, or None when no group file exists.
    """

    path: Path
    rows: np.ndarray
    groups: tuple[tuple[int, ...], ...] | None = None


def read_trajectory_file(path: str | Path) -> np.ndarray:
    """Read ``frame ped x y`` rows; returns a (R, 4) float64 array.

    Raises:
        DataFormatError: naming the file and 1-based line for a row that is not four finite numbers.
    """
    path = Path(path)
    rows: list[list[float]] = []
    with path.open() as f:
        for lineno, line in enumerate(f, start=1):
            parts = line.split()
            if not parts:
                continue
            if len(parts) != 4:
                raise DataFormatError(
                    f"{path}:{lineno}: expected 4 fields 'frame ped x y', got {len(parts)}: {line.strip()!r}"
                )
            try:
                values = [float(p) for p in parts]
            except ValueError:
                raise DataFormatError(f"{path}:{lineno}: non-numeric field in {line.strip()!r}") from None
            if not all(np.isfinite(values)):
                raise DataFormatError(f"{path}:{lineno}: non-finite value in {line.strip()!r}")
            rows.append(values)
    if not rows:
        return np.zeros((0, 4))
    return np.asarray(rows, dtype=np.float64)


def read_group_file(path: str | Path) -> tuple[tuple[int, ...], ...]:
    """Read a group file: one group per line, integer ped ids; blank lines are skipped.

    Raises:
        DataFormatError: for a non-integer id or an id listed in two groups.
    """
    path = Path(path)
    groups: list[tuple[int, ...]] = []
    seen: set[int] = set()
    with path.open() as f:
        for lineno, line in enumerate(f, start=1):
            parts = line.split()
            if not parts:
                continue
            try:
                ids = tuple(int(float(p)) for p in parts)
            except ValueError:
                raise DataFormatError(f"{path}:{lineno}: non-integer ped id in {line.strip()!r}") from None
            dup = seen.intersection(ids)
            if dup:
                raise DataFormatError(f"{path}:{lineno}: ped id(s) {sorted(dup)} already in another group")
            seen.update(ids)
            groups.append(ids)
    return tuple(groups)


def group_file_for(path: Path) -> Path:
    """Return the group-file path that belongs to trajectory file ``path`` (``X.txt`` -> ``X.groups.txt``)."""
    return path.with_name(path.name[: -len(".txt")] + GROUP_SUFFIX)


def read_recording(path: str | Path) -> Recording:
    """Read a trajectory file and its sibling group file when one exists."""
    path = Path(path)
    rows = read_trajectory_file(path)
    gpath = group_file_for(path)
    groups = read_group_file(gpath) if gpath.exists() else None
    return Recording(path=path, rows=rows, groups=groups)


def list_trajectory_files(folder: str | Path) -> list[Path]:
    """Sorted ``*.txt`` trajectory files in ``folder`` (group files excluded)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no such data folder: {folder}")
    return sorted(p for p in folder.glob("*.txt") if not p.name.endswith(GROUP_SUFFIX))


def read_split(folder: str | Path) -> list[Recording]:
    """Read every trajectory file of one split folder (e.g. ``eth/test``)."""
    files = list_trajectory_files(folder)
    if not files:
        raise FileNotFoundError(f"no *.txt trajectory files in {folder}")
    return [read_recording(p) for p in files]
