"""ETH/UCY-format export: trajectories, group files, per-frame labels and JSON metadata.

For a recording named `X` the writer produces, in one folder:
- `X.txt`: `frame<TAB>ped<TAB>x<TAB>y`, one row per active pedestrian and recorded frame, frame ids
  advancing by 10 per 0.4 s step as in the benchmark files, positions in metres (4 decimals);
- `X.groups.txt`: one line per group of two or more, member ped ids separated by spaces (the BIWI
  `groups.txt` format); a partition: each pedestrian is in the group it belonged to for most of its
  frames;
- `X.labels.tsv`: `frame<TAB>ped<TAB>group`, the ground-truth label of every row of `X.txt`, so that
  labels that change over time (leave and merge events) are exact per frame;
- `X.json`: scenario, seed, steps and every parameter.
Files are written atomically (temporary file, then rename), and identical inputs give identical bytes.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.state import CrowdState

FRAME_STRIDE = 10  # frame ids per recording step, as in the ETH/UCY benchmark files


@dataclass
class TrajectoryLog:
    """Rows collected from successive states: frame id, ped id, x, y and the global group label."""

    rows: list[np.ndarray] = field(default_factory=list)

    def add(self, state: CrowdState) -> None:
        """Append the active rows of `state`, with their stable group labels (`state.label`)."""
        act = state.active
        n = int(act.sum())
        block = np.empty((n, 5))
        block[:, 0] = state.frame * FRAME_STRIDE
        block[:, 1] = state.ped_id[act]
        block[:, 2:4] = state.pos[act]
        block[:, 4] = state.label[act]
        self.rows.append(block)

    def table(self) -> np.ndarray:
        """(R, 5) array: frame, ped, x, y, label, ordered by frame then ped id."""
        if not self.rows:
            return np.empty((0, 5))
        t = np.concatenate(self.rows)
        return t[np.lexsort((t[:, 1], t[:, 0]))]


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
    os.replace(tmp, path)


def trajectories_text(table: np.ndarray) -> str:
    return "".join(f"{int(f)}\t{int(p)}\t{x:.4f}\t{y:.4f}\n" for f, p, x, y, _ in table)


def labels_text(table: np.ndarray) -> str:
    return "".join(f"{int(f)}\t{int(p)}\t{int(g)}\n" for f, p, _, _, g in table)


def majority_labels(table: np.ndarray) -> dict[int, int]:
    """Each pedestrian's most frequent label over its rows (ties: the earliest label)."""
    out: dict[int, int] = {}
    peds = table[:, 1].astype(np.int64)
    labels = table[:, 4].astype(np.int64)
    for ped in np.unique(peds):
        values, counts = np.unique(labels[peds == ped], return_counts=True)
        out[int(ped)] = int(values[np.argmax(counts)])
    return out


def groups_text(table: np.ndarray) -> str:
    """A partition in BIWI format: one line per group of two or more, each pedestrian in the group whose
    label it carried for most of its frames (exact per-frame labels are in the labels file)."""
    members: dict[int, list[int]] = {}
    for ped, label in majority_labels(table).items():
        members.setdefault(label, []).append(ped)
    lines = [" ".join(str(p) for p in sorted(m)) for _, m in sorted(members.items()) if len(m) >= 2]
    return "\n".join(lines) + ("\n" if lines else "")


RecordingFiles = dict[str, tuple[str, str]]  # kind ("trajectories", ...) -> (file name, text)


def recording_files(name: str, log: TrajectoryLog, metadata: dict[str, Any]) -> RecordingFiles:
    """The four files of recording `name` as texts, in memory (what `write_recording` writes): kind ->
    (file name, text), kinds "trajectories", "groups", "labels", "metadata" in that order."""
    table = log.table()
    names = {"trajectories": f"{name}.txt", "groups": f"{name}.groups.txt", "labels": f"{name}.labels.tsv",
             "metadata": f"{name}.json"}
    meta = dict(metadata)
    meta.update(rows=len(table), pedestrians=len(np.unique(table[:, 1])) if len(table) else 0,
                frame_stride=FRAME_STRIDE, files=names)
    return {
        "trajectories": (names["trajectories"], trajectories_text(table)),
        "groups": (names["groups"], groups_text(table)),
        "labels": (names["labels"], labels_text(table)),
        "metadata": (names["metadata"], json.dumps(meta, indent=2, sort_keys=True) + "\n"),
    }


def write_files(folder: Path, files: RecordingFiles) -> dict[str, Path]:
    """Write each (file name, text) of `files` atomically into folder (created if needed); kind -> path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for kind, (file_name, text) in files.items():
        paths[kind] = folder / file_name
        _atomic_write(paths[kind], text)
    return paths


def write_recording(folder: Path, name: str, log: TrajectoryLog, metadata: dict[str, Any]) -> dict[str, Path]:
    """Write X.txt, X.groups.txt, X.labels.tsv and X.json into folder; returns their paths."""
    return write_files(folder, recording_files(name, log, metadata))
