"""The predictor's reader of TrajNet++ ndjson files (``X.ndjson``), numpy only.

A twin of `crowdsim.trajnet.read_trajnet` (the predictor may not import crowdsim; the tests check that both read
the same rows from the same file), reduced to what training needs: the track rows and, when every track row
carries crowdsim's extra ``group`` field, the per-frame labels. Lines are one JSON object each:
``{"scene": {"id", "p", "s", "e", ...}}`` or ``{"track": {"f", "p", "x", "y"[, "group"]}}``; scenes are checked and
skipped (the predictor cuts its own windows from the rows). The same policy as `predictor.ethucy`: anything off
(not JSON, a missing key, a non-finite value, a non-whole id, a (frame, ped) pair twice, ``group`` on some rows
only, no track rows) is a `DataFormatError` naming ``file:line``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from predictor.ethucy import MAX_ID, DataFormatError

SUFFIX = ".ndjson"


def _value(where: str, fields: dict[str, Any], key: str, whole: bool) -> float:
    """fields[key] as a finite float (whole, below 2**53, if `whole`); `where` is ``file:line``."""
    value = fields.get(key)
    if key not in fields:
        raise DataFormatError(f"{where}: missing key {key!r}")
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise DataFormatError(f"{where}: {key} is not a finite number: {value!r}")
    if whole and (value != round(value) or abs(value) >= MAX_ID):
        raise DataFormatError(f"{where}: {key} {value!r} is not a whole number below 2**53")
    return float(value)


def _record(where: str, line: str) -> tuple[str, dict[str, Any]]:
    try:
        obj = json.loads(line)
    except ValueError as exc:
        raise DataFormatError(f"{where}: not JSON ({exc.msg}): {line.strip()[:80]!r}") from None
    kinds = [k for k in ("scene", "track") if isinstance(obj, dict) and k in obj]
    if len(kinds) != 1 or not isinstance(obj[kinds[0]], dict):
        raise DataFormatError(f'{where}: expected {{"scene": {{...}}}} or {{"track": {{...}}}}, '
                              f"got {line.strip()[:80]!r}")
    return kinds[0], obj[kinds[0]]


def read_trajnet_rows(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(rows (R, 4) float64 ``frame, ped, x, y`` in file order, x and y in m; labels (R, 3) ``frame, ped, group``
    or None when the rows carry no ``group``)."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise DataFormatError(f"{path}: not a UTF-8 text file") from None
    rows, groups, seen, first = [], [], {}, None
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        where = f"{path}:{lineno}"
        kind, fields = _record(where, line)
        if kind == "scene":
            for key in ("id", "p", "s", "e"):
                _value(where, fields, key, whole=True)
            continue
        f, p = _value(where, fields, "f", True), _value(where, fields, "p", True)
        x, y = _value(where, fields, "x", False), _value(where, fields, "y", False)
        if (f, p) in seen:
            raise DataFormatError(f"{where}: pedestrian {int(p)} appears twice in frame {int(f)} (first at line "
                                  f"{seen[f, p]})")
        seen[f, p] = lineno
        first = first or (lineno, "group" in fields)
        if ("group" in fields) != first[1]:
            raise DataFormatError(f"{where}: 'group' on some track rows only (first track row: line {first[0]})")
        if first[1]:
            groups.append(_value(where, fields, "group", True))
        rows.append((f, p, x, y))
    if not rows:
        raise DataFormatError(f"{path}: no track rows")
    table = np.asarray(rows, dtype=np.float64)
    return table, (np.column_stack([table[:, :2], groups]) if groups else None)
