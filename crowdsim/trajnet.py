"""TrajNet++ files: a recording as ndjson scenes and tracks (write), and such a file back as rows (read).

The format of vita-epfl's trajnetplusplustools / trajnetplusplusdataset: one JSON object per line, either

* ``{"scene": {"id": 0, "p": 3, "s": 40, "e": 240, "fps": 2.5, "tag": 0}}``: scene ``id`` around primary
  pedestrian ``p`` from frame ``s`` to frame ``e`` (inclusive), ``fps`` rows per second, ``tag`` the trajectory
  category (0: not categorised; TrajNet++'s own categoriser writes ``[type, [subtypes]]``), or
* ``{"track": {"f": 40, "p": 3, "x": 1.2345, "y": -0.5, "group": 2}}``: pedestrian ``p`` at frame ``f``, position
  in metres. ``group`` is crowdsim's extra field: the row's ground-truth group label (`crowdsim.export` labels
  file); TrajNet++ readers ignore keys they do not know.

What the writer does (the choices, documented in docs/crowdsim.md):

* frame ids and positions as the ETH/UCY export (`crowdsim.export`): frames advance by `FRAME_STRIDE` per
  recorded step, positions with 4 decimals (TrajNet++'s own files round to 2), so that ETH/UCY -> TrajNet++ ->
  ETH/UCY returns the same rows;
* every track row of the recording is written (TrajNet++ keeps only the frames of its scenes), so the
  predictor's windows are the same from either format;
* scenes of `SCENE_LEN` = 21 rows (9 observed + 12 predicted at 2.5 fps, TrajNet++'s convention), one per
  pedestrian every `SCENE_STRIDE` rows of its track where 21 consecutive steps are all present, ids in
  (pedestrian, start frame) order; none of TrajNet++'s scene filters (minimum motion, proximity) is applied;
* scene lines first, then track lines in (frame, ped) order, as TrajNet++ writes them.

The reader (`read_trajnet`) accepts tracks before scenes and extra keys; anything else raises
`TrajnetFormatError` (a ValueError) naming ``file:line``: a line that is not a JSON object with one of ``scene``
or ``track``, a missing key, a non-numeric or non-finite value, an id that is not a whole number below 2**53, a
(frame, ped) pair or scene id given twice, ``group`` on some track rows but not on others, no track rows.
The predictor, which may not import crowdsim, keeps a twin reader (`predictor.trajnet`), checked equal in tests.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

SUFFIX = ".ndjson"
SCENE_OBS, SCENE_PRED = 9, 12  # TrajNet++'s observed and predicted rows of a scene
SCENE_LEN = SCENE_OBS + SCENE_PRED
SCENE_STRIDE = 3  # rows between the starts of a pedestrian's scenes (TrajNet++'s default chunk stride)
MAX_ID = 2**53
TRACK_KEYS, SCENE_KEYS = ("f", "p", "x", "y"), ("id", "p", "s", "e")


class TrajnetFormatError(ValueError):
    """A TrajNet++ ndjson file does not follow the format (see `crowdsim.trajnet`)."""


@dataclass(frozen=True)
class TrajnetFile:
    """What a TrajNet++ file holds.

    Attributes:
        rows: (R, 4) float64 ``frame, ped, x, y`` of the track lines, file order; x, y in metres.
        labels: (R,) int64 group label of each row (the ``group`` field), or None when the file has none.
        scenes: (S, 4) int64 ``id, primary ped, start frame, end frame`` of the scene lines, file order.
        fps: rows per second of the scenes (None without scenes or ``fps``).
    """

    rows: np.ndarray
    labels: np.ndarray | None
    scenes: np.ndarray
    fps: float | None

    def table(self) -> np.ndarray:
        """(R, 5) ``frame, ped, x, y, label`` in (frame, ped) order, a `TrajectoryLog.table()` (label -1 without
        labels): what `crowdsim.export.table_files` writes back as ETH/UCY files."""
        labels = self.labels if self.labels is not None else np.full(len(self.rows), -1)
        t = np.column_stack([self.rows, labels.astype(np.float64)])
        return t[np.lexsort((t[:, 1], t[:, 0]))]


def scene_windows(table: np.ndarray, frame_step: float, length: int = SCENE_LEN,
                  stride: int = SCENE_STRIDE) -> np.ndarray:
    """(S, 3) int64 ``ped, start frame, end frame`` of the scenes of a table ((R, >=2) ``frame, ped, ...``): per
    pedestrian in id order, a window every `stride` rows of its track whose `length` rows are consecutive steps
    (`frame_step` frame ids apart: `crowdsim.export.FRAME_STRIDE` for crowdsim's files)."""
    out = []
    t = table[np.lexsort((table[:, 0], table[:, 1]))]
    peds, starts = np.unique(t[:, 1], return_index=True)
    for ped, frames in zip(peds, np.split(t[:, 0], starts[1:]), strict=True):
        for i in range(0, len(frames) - length + 1, stride):
            if abs(frames[i + length - 1] - frames[i] - (length - 1) * frame_step) < 1e-9:
                out.append((int(ped), int(frames[i]), int(frames[i + length - 1])))
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def trajnet_text(table: np.ndarray, fps: float, frame_step: float, labels: bool = True) -> str:
    """The ndjson text of a (R, 5) ``frame, ped, x, y, label`` table in (frame, ped) order: the scene lines
    (`scene_windows`, frames `frame_step` apart), then one track line per row, x and y rounded to 4 decimals,
    with ``group`` if `labels`."""
    if not np.all(np.isfinite(table[:, :4])):
        raise ValueError("a TrajNet++ file needs finite frames, ids and positions")
    lines = [json.dumps({"scene": {"id": k, "p": p, "s": s, "e": e, "fps": fps, "tag": 0}})
             for k, (p, s, e) in enumerate(scene_windows(table, frame_step).tolist())]
    for f, p, x, y, g in table.tolist():
        track: dict[str, Any] = {"f": int(f), "p": int(p), "x": round(x, 4), "y": round(y, 4)}
        if labels:
            track["group"] = int(g)
        lines.append(json.dumps({"track": track}))
    return "".join(line + "\n" for line in lines)


def _fail(path: Path, lineno: int, message: str) -> TrajnetFormatError:
    return TrajnetFormatError(f"{path}:{lineno}: {message}")


def _record(path: Path, lineno: int, line: str) -> tuple[str, dict[str, Any]]:
    """("scene" or "track", its fields) of one line."""
    try:
        obj = json.loads(line)
    except ValueError as exc:
        raise _fail(path, lineno, f"not JSON ({exc.msg}): {line.strip()[:80]!r}") from None
    kinds = [k for k in ("scene", "track") if isinstance(obj, dict) and k in obj]
    if len(kinds) != 1 or not isinstance(obj[kinds[0]], dict):
        raise _fail(path, lineno, f'expected an object {{"scene": {{...}}}} or {{"track": {{...}}}}, got '
                                  f"{line.strip()[:80]!r}")
    return kinds[0], obj[kinds[0]]


def _number(path: Path, lineno: int, fields: dict[str, Any], key: str, whole: bool) -> float:
    """fields[key] as a finite float (a whole number below 2**53 if `whole`)."""
    if key not in fields:
        raise _fail(path, lineno, f"missing key {key!r}")
    value = fields[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(path, lineno, f"{key} is not a number: {value!r}")
    if not math.isfinite(value):
        raise _fail(path, lineno, f"{key} is not finite: {value!r}")
    if whole and (value != round(value) or abs(value) >= MAX_ID):
        raise _fail(path, lineno, f"{key} {value!r} is not a whole number below 2**53")
    return float(value)


def _lines(path: Path) -> list[tuple[int, str]]:
    """(1-based line number, text) of the non-blank lines of a UTF-8 file."""
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise TrajnetFormatError(f"{path}: not a UTF-8 text file") from None
    return [(i, ln) for i, ln in enumerate(text.splitlines(), start=1) if ln.strip()]


def read_trajnet(path: str | Path) -> TrajnetFile:
    """Read a TrajNet++ ndjson file (see the module docstring for what is refused)."""
    path = Path(path)
    rows, labels, scenes = [], [], []
    seen: dict[tuple[float, float], int] = {}
    scene_lines: dict[float, int] = {}
    fps: float | None = None
    first_track: tuple[int, bool] | None = None  # line and whether it had a group
    for lineno, line in _lines(path):
        kind, fields = _record(path, lineno, line)
        if kind == "scene":
            sid, ped, s, e = (_number(path, lineno, fields, k, whole=True) for k in SCENE_KEYS)
            if sid in scene_lines:
                raise _fail(path, lineno, f"scene id {int(sid)} is given twice (first at line {scene_lines[sid]})")
            if e < s:
                raise _fail(path, lineno, f"scene {int(sid)} ends (e={int(e)}) before it starts (s={int(s)})")
            scene_lines[sid] = lineno
            scenes.append((sid, ped, s, e))
            if "fps" in fields:
                fps = fps or _number(path, lineno, fields, "fps", whole=False)
            continue
        f, p, x, y = (_number(path, lineno, fields, k, whole=k in "fp") for k in TRACK_KEYS)
        if (f, p) in seen:
            raise _fail(path, lineno, f"pedestrian {int(p)} appears twice in frame {int(f)} (first at line "
                                      f"{seen[f, p]})")
        seen[f, p] = lineno
        has_group = "group" in fields
        first_track = first_track or (lineno, has_group)
        if has_group != first_track[1]:
            raise _fail(path, lineno, f"'group' is {'present' if has_group else 'missing'} here but not on the first "
                                      f"track row (line {first_track[0]}): all rows or none")
        if has_group:
            labels.append(_number(path, lineno, fields, "group", whole=True))
        rows.append((f, p, x, y))
    if not rows:
        raise TrajnetFormatError(f"{path}: no track rows")
    return TrajnetFile(rows=np.asarray(rows, dtype=np.float64),
                       labels=np.asarray(labels, dtype=np.int64) if labels else None,
                       scenes=np.asarray(scenes, dtype=np.int64).reshape(-1, 4), fps=fps)
