"""The project's one reader of ETH/UCY-format files: trajectories, group files and crowdsim's label files.

torch-free (numpy only), so `envs` (replay) and the tests of every package use it without loading the model.
Formats, one record per non-blank line, fields separated by any run of spaces or tabs:

* trajectories ``X.txt``: ``frame ped x y``, positions in metres;
* group files ``X.groups.txt``: the whole-number ped ids of one group per line;
* crowdsim label files ``X.labels.tsv``: ``frame ped group`` per row of ``X.txt``.

One policy for all readers; anything else raises `DataFormatError` (a `ValueError`) naming ``file:line``:

* every field must be a finite number (no NaN or inf);
* frame, ped and group ids must be whole numbers of magnitude below 2**53 (exact in float64);
* a (frame, ped) pair may appear only once (a duplicate row is an error, never silently merged);
* a pedestrian belongs to at most one group, and is listed once (`read_groups(..., overlaps="merge")` merges
  the groups of a pedestrian listed twice instead, with a `GroupFileWarning` naming the lines);
* the file must be UTF-8 text with at least one record;
* blank lines are skipped. Other separators, such as commas, are errors.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np

MAX_ID = 2**53  # ids must be exactly representable in float64
# The ETH/UCY forecasting protocol (Social-GAN, Social-STGCNN, SGCN, GP-Graph): rows 0.4 s apart, 8 observed rows
# (3.2 s, the last one now) and 12 predicted steps (4.8 s). The one definition in the project: the predictor
# windows its data with it, `envs.timing.DEFAULT_TIMING` is built from it, and the planner receives the step as a
# parameter (`PedPrediction.step_s`). crowdsim's `SimConfig.record_dt_s` default is a declared twin (crowdsim
# may not import predictor), checked equal in tests/test_shared_facts.py.
STEP_S = 0.4
OBS_LEN = 8
PRED_LEN = 12
TRAJECTORY_FIELDS = "frame ped x y"
LABEL_FIELDS = "frame ped group"
# Where the ETH/UCY data lives (one folder per scene: eth, hotel, univ, zara1, zara2, each with train/val/test in the
# leave-one-out layout). The one definition in the project: the benchmark suites (`envs.evaluation.suite.DEFAULT_DATA`,
# `crowdnav --data`), the scripts and the tests use it. Relative to the working folder (the repository root, where the
# shared data sits beside it at ../shared); the environment variable ETH_UCY_DIR points it elsewhere.
DATA_DIR_ENV = "ETH_UCY_DIR"
DEFAULT_DATA_DIR = Path(os.environ.get(DATA_DIR_ENV) or "../shared/datasets/eth_ucy")


class DataFormatError(ValueError):
    """A trajectory, group or label file does not follow the ETH/UCY format (see `predictor.ethucy`)."""


def _lines(path: str | Path) -> list[tuple[int, str]]:
    """(1-based line number, text) of the non-blank lines of a UTF-8 text file."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise DataFormatError(f"{path}: not a UTF-8 text file") from None
    if "\x00" in text:
        raise DataFormatError(f"{path}: contains NUL bytes (a binary file?)")
    return [(i, line) for i, line in enumerate(text.splitlines(), start=1) if line.strip()]


def _numbers(path: Path, lineno: int, line: str, width: int, fields: str) -> list[float]:
    parts = line.split()
    if len(parts) != width:
        raise DataFormatError(f"{path}:{lineno}: expected {width} fields '{fields}' separated by spaces or tabs, "
                              f"got {len(parts)}: {line.strip()[:80]!r}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise DataFormatError(f"{path}:{lineno}: non-numeric field in {line.strip()[:80]!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise DataFormatError(f"{path}:{lineno}: non-finite value (NaN or inf) in {line.strip()[:80]!r}")
    return values


def _check_id(path: Path, lineno: int, name: str, value: float) -> None:
    if value != round(value) or abs(value) >= MAX_ID:
        raise DataFormatError(f"{path}:{lineno}: {name} {value!r} is not a whole number below 2**53")


def _read_keyed(path: str | Path, fields: str, n_ids: int) -> np.ndarray:
    """Rows of `fields` whose first `n_ids` fields are whole-number ids; (frame, ped) unique. (R, width)."""
    path = Path(path)
    names = fields.split()
    rows, seen = [], {}
    for lineno, line in _lines(path):
        values = _numbers(path, lineno, line, len(names), fields)
        for name, value in zip(names[:n_ids], values[:n_ids], strict=True):
            _check_id(path, lineno, name, value)
        key = (values[0], values[1])
        if key in seen:
            raise DataFormatError(f"{path}:{lineno}: pedestrian {int(values[1])} appears twice in frame "
                                  f"{int(values[0])} (first at line {seen[key]})")
        seen[key] = lineno
        rows.append(values)
    if not rows:
        raise DataFormatError(f"{path}: no records (empty file)")
    return np.asarray(rows, dtype=np.float64)


def read_trajectories(path: str | Path) -> np.ndarray:
    """``frame ped x y`` rows of a trajectory file, file order: (R, 4) float64, x and y in metres."""
    return _read_keyed(path, TRAJECTORY_FIELDS, n_ids=2)


def read_labels(path: str | Path) -> np.ndarray:
    """``frame ped group`` rows of a crowdsim label file, file order: (L, 3) float64 of whole numbers."""
    return _read_keyed(path, LABEL_FIELDS, n_ids=3)


GROUP_OVERLAPS = ("error", "merge")  # what read_groups does with a pedestrian listed on two lines


class GroupFileWarning(UserWarning):
    """A group file was read with `overlaps="merge"` and listed somebody twice: the groups were merged."""


def read_groups(path: str | Path, overlaps: str = "error") -> tuple[tuple[int, ...], ...]:
    """The groups of a group file, one tuple of ped ids per non-blank line, file order.

    A pedestrian listed twice (on two lines, or twice on one) is a `DataFormatError` naming both lines, unless
    `overlaps` is "merge": then the lines that share somebody become one group (in the place of the first of them,
    members in order of first mention, each once), with one `GroupFileWarning` per pedestrian listed twice, naming
    the lines. The published students003 annotation needs it (four pedestrians on two lines each)."""
    if overlaps not in GROUP_OVERLAPS:
        raise ValueError(f"unknown overlaps {overlaps!r}; valid: {', '.join(GROUP_OVERLAPS)}")
    path = Path(path)
    groups: list[tuple[int, ...]] = []
    linenos: list[int] = []
    where: dict[int, int] = {}  # ped -> index of the first line that lists it
    parent: list[int] = []  # union-find over line indices (merge)
    for lineno, line in _lines(path):
        try:
            values = [float(tok) for tok in line.split()]
        except ValueError:
            raise DataFormatError(f"{path}:{lineno}: non-numeric ped id in {line.strip()[:80]!r}") from None
        for value in values:
            if not math.isfinite(value):
                raise DataFormatError(f"{path}:{lineno}: non-finite ped id in {line.strip()[:80]!r}")
            _check_id(path, lineno, "ped id", value)
        ids = tuple(int(v) for v in values)
        parent.append(len(groups))
        for ped in ids:
            if ped in where:
                first = linenos[where[ped]] if where[ped] < len(linenos) else lineno
                if overlaps == "error":
                    raise DataFormatError(f"{path}:{lineno}: pedestrian {ped} is already listed (line {first}); "
                                          "overlaps='merge' (crowdnav --group-overlaps merge) merges such groups")
                warnings.warn(f"{path}: pedestrian {ped} is listed on lines {first} and {lineno}: their groups are "
                              "merged into one", GroupFileWarning, stacklevel=2)
                here, there = _root(parent, len(groups)), _root(parent, where[ped])
                parent[max(here, there)] = min(here, there)  # the earliest line represents the merged group
            else:
                where[ped] = len(groups)
        groups.append(ids)
        linenos.append(lineno)
    if overlaps == "error":
        return tuple(groups)  # an empty file: no groups (everyone alone)
    merged: dict[int, list[int]] = {}
    for i, ids in enumerate(groups):
        members = merged.setdefault(_root(parent, i), [])
        members.extend(p for p in ids if p not in members)
    return tuple(tuple(m) for m in merged.values())


def _root(parent: list[int], i: int) -> int:
    """The representative line of line index i's merged group (union-find, the earliest line of it)."""
    while parent[i] != i:
        i = parent[i]
    return i
