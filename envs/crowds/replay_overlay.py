"""A denser crowd from a sparse recording: K circularly time-shifted copies of it superimposed.

`overlay_rows(rows, copies)` takes ETH/UCY rows `frame ped x y` (frame ids, file ids, m) and returns the rows of
the superimposed recording, on the original frame grid and over the original duration:
- copy j (j = 0 .. K-1) is the recording shifted later by j * n // K annotation steps, where n is the number of
  annotation steps the recording spans (first to last frame, inclusive); what is shifted past the end wraps
  round to the start, so every copy covers the whole duration;
- copy j's pedestrian ids are `id + 2 * j * B`, where B is the smallest power of ten above the largest id; a
  track cut by the wrap continues from the start under `id + 2 * j * B + B` (a new pedestrian there);
- copy 0 is the recording itself (same ids, same frames).

The copies do not avoid each other (a replay's people do not avoid the robot either); the density rises K-fold
while each track keeps its recorded speed and shape. Used to train and tune on crowds as dense as the ETH/UCY
test scenes without touching those (`ReplayConfig.overlay`).
"""

from __future__ import annotations

import math

import numpy as np


def overlay_rows(rows: np.ndarray, copies: int, frame_increment: float) -> np.ndarray:
    """(R, 4) rows `frame ped x y` -> (K * R, 4) rows of `copies` superimposed shifted copies, sorted by frame
    then id. `frame_increment`: frame-id difference of one annotation step (> 0)."""
    rows = np.asarray(rows, dtype=float)
    if rows.ndim != 2 or rows.shape[1] != 4 or len(rows) == 0:
        raise ValueError(f"overlay needs (R, 4) rows 'frame ped x y', got shape {rows.shape}")
    if copies < 1 or int(copies) != copies:
        raise ValueError(f"overlay copies must be an integer >= 1, got {copies}")
    if not (math.isfinite(frame_increment) and frame_increment > 0):
        raise ValueError(f"frame_increment must be > 0, got {frame_increment}")
    if copies == 1:
        return rows.copy()
    f0 = rows[:, 0].min()
    u = (rows[:, 0] - f0) / frame_increment  # annotation steps from the first frame
    span = int(round(u.max())) + 1
    if span < copies:
        raise ValueError(f"a recording of {span} annotation steps cannot hold {copies} shifted copies")
    base = 10 ** len(str(int(max(rows[:, 1].max(), 0))))  # smallest power of ten above the largest id
    parts = []
    for j in range(copies):
        shifted = u + j * span // copies
        wrapped = shifted >= span - 1e-9
        ids = rows[:, 1] + 2 * j * base + wrapped * base
        frames = f0 + np.where(wrapped, shifted - span, shifted) * frame_increment
        parts.append(np.column_stack([frames, ids, rows[:, 2], rows[:, 3]]))
    out = np.concatenate(parts)
    return out[np.lexsort((out[:, 1], out[:, 0]))]
