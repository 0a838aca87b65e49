"""Readers for ETH/UCY-format trajectory files and crowdsim group-label files.

A trajectory file has one row per (frame, pedestrian): ``frame ped x y`` separated by tabs or
whitespace, positions in metres. A group file (``X.groups.txt`` beside ``X.txt``) holds one group
per line, member pedestrian ids separated by whitespace; blank lines are allowed. crowdsim exports may
also carry ``X.labels.tsv`` (``frame ped group`` per row of ``X.txt``): exact per-frame labels, which take
precedence over the group file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

GROUP_SUFFIX = ".groups.txt"
LABELS_SUFFIX = ".labels.tsv"


class DataFormatError(ValueError):
    """A trajectory or group file does not follow the expected format."""


@dataclass(frozen=True)
class Recording:
    """One trajectory file.

    Attributes:
        path: source file.
        rows: (R, 4) float64 array of ``frame, ped, x, y`` (x, y in metres).
        groups: ground-truth groups as a tuple of tuples of ped ids, or None when no group file exists.
        frame_labels: (L, 3) float64 ``frame, ped, group`` per-frame labels, or None without a labels file.
    """

    path: Path
    rows: np.ndarray
    groups: tuple[tuple[int, ...], ...] | None = None
    frame_labels: np.ndarray | None = None


def read_table(path: str | Path, fields: str = "frame ped x y") -> np.ndarray:
    """Read whitespace-separated numeric rows with the given field names; returns (R, n_fields) float64.

    Raises:
        DataFormatError: naming the file and 1-based line for a row that is not n finite numbers.
    """
    path = Path(path)
    width = len(fields.split())
    rows: list[list[float]] = []
    with path.open() as f:
        for lineno, line in enumerate(f, start=1):
            parts = line.split()
            if not parts:
                continue
            if len(parts) != width:
                raise DataFormatError(
                    f"{path}:{lineno}: expected {width} fields '{fields}', got {len(parts)}: {line.strip()!r}"
                )
            try:
                values = [float(p) for p in parts]
            except ValueError:
                raise DataFormatError(f"{path}:{lineno}: non-numeric field in {line.strip()!r}") from None
            if not all(np.isfinite(values)):
                raise DataFormatError(f"{path}:{lineno}: non-finite value in {line.strip()!r}")
            rows.append(values)
    if not rows:
        return np.zeros((0, width))
    return np.asarray(rows, dtype=np.float64)


def read_trajectory_file(path: str | Path) -> np.ndarray:
    """Read ``frame ped x y`` rows (tabs or spaces); returns a (R, 4) float64 array, x and y in metres."""
    return read_table(path, "frame ped x y")


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
    lpath = path.with_name(path.name[: -len(".txt")] + LABELS_SUFFIX)
    labels = read_table(lpath, "frame ped group") if lpath.exists() else None
    return Recording(path=path, rows=rows, groups=groups, frame_labels=labels)


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
