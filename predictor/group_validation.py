"""Grouping on real annotated people: PW and G-MITRE of a predictor's groups on every window of labelled recordings.

``gpgraph groups`` runs it. For each group file ``GROUPS/X.groups.txt`` the recording ``X.txt`` is looked up in
the test folders of the ETH/UCY data (``DATA/*/test/X.txt``); every standard window of it (8 + 12 steps, the
people present throughout, at least 2) is scored: the predictor sees the 8 observed steps and its group ids are
compared with the annotation (a pedestrian on no line walks alone). Counts are summed over the windows of a file,
and over all files for the pooled row, so a pair seen in many windows counts in each.

The UCY annotations in ``../shared/datasets/eth_ucy_groups`` are for validation only: never train on them.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from predictor.data import Recording, read_trajectory_file
from predictor.ethucy import GROUP_OVERLAPS, DataFormatError, GroupFileWarning, read_groups
from predictor.metrics import GroupScores, f1
from predictor.windows import Window, recording_windows

GROUP_FILE_SUFFIX = ".groups.txt"
ABSENT_IDS = ("error", "drop")  # what to do with a listed pedestrian the recording does not have


@dataclass(frozen=True)
class LabelledRecording:
    """One annotated recording: its name (``X``), its scene (the data folder it is the test recording of, e.g.
    "zara1"), its windows (group ids from the file) and what reading noted."""

    name: str
    scene: str
    windows: list[Window]
    notes: tuple[str, ...] = field(default_factory=tuple)
    rows: np.ndarray | None = None  # the recording's (frame, ped, x, y) rows, for ``window_tracks``


def find_recording(data: Path, name: str) -> Path:
    """``DATA/*/test/NAME.txt``: the one test recording of that name (FileNotFoundError if none)."""
    found = sorted(data.glob(f"*/test/{name}.txt"))
    if not found:
        raise FileNotFoundError(f"no recording {name}.txt in any test folder of {data} (DATA/*/test/)")
    return found[0]


def read_labelled(data: Path, group_file: Path, overlaps: str = "error",
                  absent_ids: str = "error") -> LabelledRecording:
    """The windows of the recording ``group_file`` annotates, labelled by it.

    overlaps: ``predictor.ethucy.read_groups``'s policy for a pedestrian listed twice ("merge" notes each merge).
    absent_ids: "error" refuses a file that lists pedestrians the recording does not have (DataFormatError naming
    them); "drop" leaves them out and notes which. A recording with no window of 20 steps and 2 people is an error.
    """
    if absent_ids not in ABSENT_IDS:
        raise ValueError(f"unknown absent_ids {absent_ids!r}; valid: {', '.join(ABSENT_IDS)}")
    if overlaps not in GROUP_OVERLAPS:
        raise ValueError(f"unknown overlaps {overlaps!r}; valid: {', '.join(GROUP_OVERLAPS)}")
    name = group_file.name[: -len(GROUP_FILE_SUFFIX)]
    path = find_recording(data, name)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", GroupFileWarning)
        groups = read_groups(group_file, overlaps=overlaps)
    notes = [str(w.message) for w in caught if issubclass(w.category, GroupFileWarning)]
    rows = read_trajectory_file(path)
    present = set(np.unique(rows[:, 1]).astype(np.int64).tolist())
    absent = sorted({p for g in groups for p in g} - present)
    if absent and absent_ids == "error":
        raise DataFormatError(f"{group_file}: pedestrians {absent[:10]} are not in {path} "
                              f"({len(absent)} absent); --absent-ids drop leaves them out")
    if absent:
        notes.append(f"{group_file.name}: pedestrians {absent} are not in {path.name}: left out")
        groups = tuple(kept for g in groups if len(kept := tuple(p for p in g if p in present)) > 0)
    windows = recording_windows(Recording(path=path, rows=rows, groups=groups))
    if not windows:
        raise DataFormatError(f"{path}: no window of 20 consecutive frames with 2 or more people present")
    return LabelledRecording(name, path.parent.parent.name, windows, tuple(notes), rows)


def read_annotations(data: Path, groups_dir: Path, overlaps: str = "error",
                     absent_ids: str = "error") -> list[LabelledRecording]:
    """Every ``*.groups.txt`` of ``groups_dir`` with its recording's windows, in file-name order."""
    files = sorted(groups_dir.glob(f"*{GROUP_FILE_SUFFIX}"))
    if not files:
        raise FileNotFoundError(f"no *{GROUP_FILE_SUFFIX} group files in {groups_dir}")
    return [read_labelled(data, f, overlaps, absent_ids) for f in files]


def score_windows(windows: list[Window], groups_of: Callable[[Window], np.ndarray]) -> GroupScores:
    """PW and G-MITRE counts of ``groups_of(window)`` (N,) against each window's annotation."""
    scores = GroupScores()
    for w in windows:
        scores.add(w.group_id, groups_of(w))
    return scores


def summary(scores: GroupScores) -> dict[str, float]:
    """Precision, recall and F1 of PW and G-MITRE, plus the window count's pairs (``pairs_true``)."""
    r = scores.result()
    return {**r, "pw_f1": f1(r["pw_precision"], r["pw_recall"]),
            "gmitre_f1": f1(r["gmitre_precision"], r["gmitre_recall"]), "pairs_true": int(scores.counts[2])}


def validate(recordings: list[LabelledRecording],
             groups_for: Callable[[LabelledRecording], Callable[[Window], np.ndarray]]) -> dict[str, dict[str, float]]:
    """Per recording and pooled ("all") scores; ``groups_for(recording)`` gives the grouping to use on it (e.g.
    its scene's leave-one-out predictor)."""
    out: dict[str, dict[str, float]] = {}
    pooled = GroupScores()
    for rec in recordings:
        s = score_windows(rec.windows, groups_for(rec))
        pooled.counts += s.counts
        out[rec.name] = summary(s) | {"windows": len(rec.windows)}
    out["all"] = summary(pooled) | {"windows": sum(len(r.windows) for r in recordings)}
    return out
