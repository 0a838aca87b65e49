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
With `fmt="trajnet"` the rows and their labels go instead into one TrajNet++ file `X.ndjson` (`crowdsim.trajnet`:
scenes and tracks, the label as a `group` field), beside the same `X.json`.
Files are written atomically (temporary file, then rename), and identical inputs give identical bytes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.files import write_text_atomic
from crowdsim.state import CrowdState
from crowdsim.trajnet import SUFFIX as TRAJNET_SUFFIX
from crowdsim.trajnet import scene_windows, trajnet_text

FRAME_STRIDE = 10  # frame ids per recording step, as in the ETH/UCY benchmark files


@dataclass
class TrajectoryLog:
    """Rows collected from successive states: frame id, ped id, x, y and the global group label."""

    rows: list[np.ndarray] = field(default_factory=list)

    def add(self, state: CrowdState) -> None:
        """Append the active rows of `state` in ped id order, with their stable group labels (`state.label`)."""
        act = np.flatnonzero(state.active)
        act = act[np.argsort(state.ped_id[act], kind="stable")]
        block = np.empty((len(act), 5))
        block[:, 0] = state.frame * FRAME_STRIDE
        block[:, 1] = state.ped_id[act]
        block[:, 2:4] = state.pos[act]
        block[:, 4] = state.label[act]
        self.rows.append(block)

    def table(self) -> np.ndarray:
        """(R, 5) array: frame, ped, x, y, label, ordered by frame then ped id (rows with equal keys in the
        order they were added)."""
        if not self.rows:
            return np.empty((0, 5))
        t = np.concatenate(self.rows)
        frame, ped = t[:, 0], t[:, 1]
        if np.all((frame[1:] > frame[:-1]) | ((frame[1:] == frame[:-1]) & (ped[1:] > ped[:-1]))):
            return t  # the usual case, states added frame after frame: already in order, no sort needed
        return t[np.lexsort((ped, frame))]


# Text is built with numpy, all rows at once: each field of each row becomes a fixed-width run of ASCII
# codes in one (rows, width) uint8 array, 0 marking "no character" (leading zeros, a missing sign), and the
# text is that array read row by row with the 0 bytes dropped. The bytes are those of the plain f-string
# formatting (`trajectories_text_reference`), which the fast path falls back to where it could differ.
_TAB, _NEWLINE, _DOT, _MINUS, _ZERO = (ord(c) for c in "\t\n.-0")
_FIXED_LIMIT = 2.0**33  # |x| * 1e4 below this is exact to < 1e-6, inside the 1e-5 margin kept around ties


def _four_digit_table() -> np.ndarray:
    """(20000,) uint32, each the 4 ASCII bytes of a number: entry n < 10000 is n zero-padded ("0042"),
    entry 10000 + n is n right-aligned with its leading zeros as 0 ("\\0\\0" "42"; "\\0\\0\\0" "0" for 0)."""
    n = np.arange(10000)
    digits = n[:, None] // np.array([1000, 100, 10, 1]) % 10
    padded = (digits + _ZERO).astype(np.uint8)
    leading = np.where(n[:, None] < np.array([1000, 100, 10, 0]), 0, padded).astype(np.uint8)
    return np.concatenate([padded, leading]).view(np.uint32).ravel()


_FOUR_DIGITS = _four_digit_table()


def _four_chars(index: np.ndarray) -> np.ndarray:
    """(R, 4) uint8: the table entries `index` (R,)."""
    return np.take(_FOUR_DIGITS, index).view(np.uint8).reshape(-1, 4)


def _digit_chars(mag: np.ndarray) -> np.ndarray:
    """(R, w) uint8: the decimal digits of the non-negative int64 values mag (R,), right-aligned, leading
    zeros as 0 (no character); the units digit is always written. Four digits per table look-up."""
    if not len(mag) or mag.max() < 10000:
        return _four_chars(mag + 10000)
    short = mag < 10000
    high = _digit_chars(mag // 10000)
    high[short] = 0
    return np.hstack([high, _four_chars(mag % 10000 + 10000 * short)])


def _with_sign(negative: np.ndarray, chars: np.ndarray) -> np.ndarray:
    """chars (R, w) preceded by a "-" column where `negative` (R,), if any row is."""
    if not negative.any():
        return chars
    return np.hstack([np.where(negative, _MINUS, 0).astype(np.uint8)[:, None], chars])


def _ints_ok(columns: np.ndarray) -> bool:
    """Whether `int(v)` of every value is an int64 (finite, below 2^53 in magnitude)."""
    return bool(np.all(np.abs(columns) < 2.0**53))  # False for NaN


def _int_chars(values: np.ndarray) -> np.ndarray:
    """Characters of `str(int(v))` for each integer-valued float v (R,)."""
    ints = values.astype(np.int64)
    return _with_sign(ints < 0, _digit_chars(np.abs(ints)))


def _fixed4_chars(values: np.ndarray) -> np.ndarray | None:
    """Characters of `f"{v:.4f}"` for each float v (R,); None if a value is non-finite or too large for the
    exact fast path. Python rounds the exact binary value half to even; rint of |v| * 1e4 does the same
    unless the product's rounding moved it across a tie, so values within 1e-5 of a tie are formatted by
    Python itself."""
    scaled = np.abs(values) * 1e4
    if not np.all(scaled < _FIXED_LIMIT):  # also catches NaN
        return None
    q = np.rint(scaled).astype(np.int64)
    for k in np.flatnonzero(np.abs(scaled - np.floor(scaled) - 0.5) < 1e-5):
        q[k] = int(f"{abs(values[k]):.4f}".replace(".", ""))
    units, decimals = np.divmod(q, 10000)
    dot = np.full((len(q), 1), _DOT, np.uint8)
    # "-" also before a negative value that rounds to zero and before -0.0, as Python writes them
    return _with_sign(np.signbit(values), np.hstack([_digit_chars(units), dot, _four_chars(decimals)]))


def _lines(fields: list[np.ndarray]) -> str:
    """One line per row: the rows' fields (each (R, w_k) uint8) joined by tabs."""
    rows = len(fields[0])
    tab, newline = np.full((rows, 1), _TAB, np.uint8), np.full((rows, 1), _NEWLINE, np.uint8)
    parts = [part for f in fields for part in (f, tab)]
    parts[-1] = newline
    chars = np.hstack(parts)
    return chars[chars != 0].tobytes().decode("ascii")


def trajectories_text_reference(table: np.ndarray) -> str:
    """`frame<TAB>ped<TAB>x<TAB>y` lines, row by row in Python: the definition `trajectories_text` matches."""
    return "".join(f"{int(f)}\t{int(p)}\t{x:.4f}\t{y:.4f}\n" for f, p, x, y, _ in table)


def labels_text_reference(table: np.ndarray) -> str:
    """`frame<TAB>ped<TAB>label` lines, row by row in Python: the definition `labels_text` matches."""
    return "".join(f"{int(f)}\t{int(p)}\t{int(g)}\n" for f, p, _, _, g in table)


def trajectories_text(table: np.ndarray) -> str:
    """The trajectory file of a table, byte for byte `trajectories_text_reference`, vectorised."""
    if not len(table):
        return ""
    x, y = (_fixed4_chars(table[:, k]) for k in (2, 3))
    if not _ints_ok(table[:, :2]) or x is None or y is None:  # never for a simulated crowd
        return trajectories_text_reference(table)
    return _lines([_int_chars(table[:, 0]), _int_chars(table[:, 1]), x, y])


def labels_text(table: np.ndarray) -> str:
    """The label file of a table, byte for byte `labels_text_reference`, vectorised."""
    if not len(table):
        return ""
    if not _ints_ok(table[:, [0, 1, 4]]):  # never for a simulated crowd
        return labels_text_reference(table)
    return _lines([_int_chars(table[:, 0]), _int_chars(table[:, 1]), _int_chars(table[:, 4])])


def majority_labels(table: np.ndarray) -> dict[int, int]:
    """Each pedestrian's most frequent label over its rows (ties: the smallest label), in ped id order."""
    if not len(table):
        return {}
    peds = table[:, 1].astype(np.int64)
    labels = table[:, 4].astype(np.int64)
    # count every (ped, label) pair, then keep per ped the pair with the largest count, smallest label
    span = int(labels.max()) - int(labels.min()) + 1
    if (int(peds.max()) - int(peds.min()) + 1) * span < 2**62:  # one int64 key per pair
        keys, counts = np.unique((peds - peds.min()) * span + (labels - labels.min()), return_counts=True)
        pair_peds, pair_labels = keys // span + peds.min(), keys % span + labels.min()
    else:
        pairs, counts = np.unique(np.column_stack([peds, labels]), axis=0, return_counts=True)
        pair_peds, pair_labels = pairs[:, 0], pairs[:, 1]
    order = np.lexsort((pair_labels, -counts, pair_peds))
    pair_peds, pair_labels = pair_peds[order], pair_labels[order]
    first = np.ones(len(order), bool)
    first[1:] = pair_peds[1:] != pair_peds[:-1]
    return dict(zip(pair_peds[first].tolist(), pair_labels[first].tolist(), strict=True))


def groups_text(table: np.ndarray) -> str:
    """A partition in BIWI format: one line per group of two or more, each pedestrian in the group whose
    label it carried for most of its frames (exact per-frame labels are in the labels file)."""
    members: dict[int, list[int]] = {}
    for ped, label in majority_labels(table).items():
        members.setdefault(label, []).append(ped)
    lines = [" ".join(str(p) for p in sorted(m)) for _, m in sorted(members.items()) if len(m) >= 2]
    return "\n".join(lines) + ("\n" if lines else "")


RecordingFiles = dict[str, tuple[str, str]]  # kind ("trajectories", ...) -> (file name, text)
FORMATS = ("ethucy", "trajnet")  # file formats of a recording: ETH/UCY text files, or TrajNet++ ndjson


def check_format(fmt: str) -> str:
    """`fmt` if it is one of `FORMATS`; ValueError listing them otherwise."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; valid: {', '.join(FORMATS)}")
    return fmt


def recording_files(name: str, log: TrajectoryLog, metadata: dict[str, Any], fmt: str = "ethucy") -> RecordingFiles:
    """The files of recording `name` as texts, in memory (what `write_recording` writes): kind -> (file name,
    text). "ethucy": kinds "trajectories", "groups", "labels", "metadata" in that order; "trajnet": kinds
    "trajectories" (`X.ndjson`) and "metadata"."""
    return table_files(name, log.table(), metadata, fmt)


def trajnet_files(name: str, table: np.ndarray, metadata: dict[str, Any]) -> RecordingFiles:
    """`X.ndjson` (`crowdsim.trajnet.trajnet_text`, scenes at the recording's rate) and `X.json`, which also
    counts the scenes and the groups of two or more (`groups_text`'s partition)."""
    fps = 1.0 / float(metadata.get("record_dt_s", 0.4))
    names = {"trajectories": f"{name}{TRAJNET_SUFFIX}", "metadata": f"{name}.json"}
    meta = dict(metadata)
    meta.update(rows=len(table), pedestrians=len(np.unique(table[:, 1])) if len(table) else 0,
                frame_stride=FRAME_STRIDE, files=names, format="trajnet", fps=fps,
                scenes=len(scene_windows(table, FRAME_STRIDE)),
                groups_of_two_or_more=len(groups_text(table).splitlines()))
    return {
        "trajectories": (names["trajectories"], trajnet_text(table, fps, FRAME_STRIDE)),
        "metadata": (names["metadata"], json.dumps(meta, indent=2, sort_keys=True) + "\n"),
    }


def table_files(name: str, table: np.ndarray, metadata: dict[str, Any], fmt: str = "ethucy") -> RecordingFiles:
    """`recording_files` of a `TrajectoryLog.table()`."""
    if check_format(fmt) == "trajnet":
        return trajnet_files(name, table, metadata)
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
    """Write each (file name, text) of `files` atomically into folder (created if needed); kind -> path. If
    interrupted (Ctrl-C, an error), the files of this call already written are removed again: a recording is on
    disk whole or not at all."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    try:
        for kind, (file_name, text) in files.items():
            write_text_atomic(folder / file_name, text)
            paths[kind] = folder / file_name
    except BaseException:
        for path in paths.values():
            path.unlink(missing_ok=True)
        raise
    return paths


def write_recording(folder: Path, name: str, log: TrajectoryLog, metadata: dict[str, Any],
                    fmt: str = "ethucy") -> dict[str, Path]:
    """Write X.txt, X.groups.txt, X.labels.tsv and X.json ("trajnet": X.ndjson and X.json) into folder; returns
    their paths by kind."""
    return write_files(folder, recording_files(name, log, metadata, fmt))
