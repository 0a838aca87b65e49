"""ETH/UCY recordings and splits for training: files are parsed by `predictor.ethucy` (the one reader).

A trajectory file has one row per (frame, pedestrian): ``frame ped x y`` separated by tabs or
whitespace, positions in metres. A group file (``X.groups.txt`` beside ``X.txt``) holds one group
per line, member pedestrian ids separated by whitespace; blank lines are allowed. crowdsim exports may
also carry ``X.labels.tsv`` (``frame ped group`` per row of ``X.txt``): exact per-frame labels, which take
precedence over the group file. A TrajNet++ file ``X.ndjson`` (`predictor.trajnet`) is read as a trajectory file
too: its track rows, and its ``group`` fields as per-frame labels (it has no group file).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from predictor.ethucy import STEP_S, DataFormatError, read_groups, read_labels, read_trajectories
from predictor.trajnet import SUFFIX as TRAJNET_SUFFIX
from predictor.trajnet import read_trajnet_rows

__all__ = [
    "DataFormatError",
    "Recording",
    "check_data_step",
    "group_file_for",
    "list_trajectory_files",
    "read_group_file",
    "read_recording",
    "read_split",
    "read_trajectory_file",
]

GROUP_SUFFIX = ".groups.txt"
LABELS_SUFFIX = ".labels.tsv"


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


def read_trajectory_file(path: str | Path) -> np.ndarray:
    """``frame ped x y`` rows (R, 4) float64, x and y in metres (`predictor.ethucy.read_trajectories`)."""
    return read_trajectories(path)


def read_group_file(path: str | Path) -> tuple[tuple[int, ...], ...]:
    """The groups of a group file (`predictor.ethucy.read_groups`)."""
    return read_groups(path)


def group_file_for(path: Path) -> Path:
    """Return the group-file path that belongs to trajectory file ``path`` (``X.txt`` -> ``X.groups.txt``)."""
    return path.with_name(path.name[: -len(".txt")] + GROUP_SUFFIX)


def read_recording(path: str | Path) -> Recording:
    """Read a trajectory file and its sibling group file when one exists (a ``.ndjson`` file: its rows and
    labels, `predictor.trajnet`)."""
    path = Path(path)
    if path.suffix == TRAJNET_SUFFIX:
        rows, labels = read_trajnet_rows(path)
        return Recording(path=path, rows=rows, frame_labels=labels)
    rows = read_trajectory_file(path)
    gpath = group_file_for(path)
    groups = read_group_file(gpath) if gpath.exists() else None
    lpath = path.with_name(path.name[: -len(".txt")] + LABELS_SUFFIX)
    labels = read_labels(lpath) if lpath.exists() else None
    return Recording(path=path, rows=rows, groups=groups, frame_labels=labels)


def list_trajectory_files(folder: str | Path) -> list[Path]:
    """Sorted ``*.txt`` and ``*.ndjson`` trajectory files in ``folder`` (group files excluded); a recording in both
    formats (``X.txt`` and ``X.ndjson``) is a DataFormatError, as it would be read twice."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no such data folder: {folder}")
    texts = [p for p in folder.glob("*.txt") if not p.name.endswith(GROUP_SUFFIX)]
    ndjson = list(folder.glob(f"*{TRAJNET_SUFFIX}"))
    both = sorted({p.stem for p in texts} & {p.stem for p in ndjson})
    if both:
        raise DataFormatError(f"{folder}: {both[0]} is there as both .txt and {TRAJNET_SUFFIX}; keep one format")
    return sorted(texts + ndjson)


def check_data_step(folder: str | Path) -> None:
    """Refuse (DataFormatError) a folder whose crowdsim metadata (``X.json`` beside ``X.txt``) records positions
    another ``record_dt_s`` than the protocol's STEP_S apart: a model trained on them would be served at 0.4 s.
    Files without metadata (ETH/UCY) are taken to follow the protocol."""
    for path in list_trajectory_files(folder):
        meta = path.with_suffix(".json")
        if not meta.is_file():
            continue
        try:
            step = json.loads(meta.read_text()).get("record_dt_s", STEP_S)
        except (ValueError, AttributeError):
            raise DataFormatError(f"{meta}: not a JSON object (crowdsim metadata)") from None
        if not isinstance(step, int | float) or abs(float(step) - STEP_S) > 1e-9:
            raise DataFormatError(f"{path}: recorded every {step!r} s ({meta.name}); the predictor is trained and "
                                  f"served on the ETH/UCY protocol's {STEP_S} s steps (SimConfig.record_dt_s)")


def read_split(folder: str | Path) -> list[Recording]:
    """Read every trajectory file of one split folder (e.g. ``eth/test``)."""
    files = list_trajectory_files(folder)
    if not files:
        raise FileNotFoundError(f"no *.txt or *{TRAJNET_SUFFIX} trajectory files in {folder}")
    return [read_recording(p) for p in files]
