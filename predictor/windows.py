"""Cut recordings into 8 observed + 12 predicted step windows (the standard ETH/UCY rules).

Rules (``../shared/datasets/README.md``): a window is ``obs_len + pred_len`` consecutive unique frame ids
of one file (stride 1); a pedestrian counts only if present in every frame of the window; a window is
kept when at least ``min_peds`` (2) pedestrians count. Coordinates are rounded to 4 decimals, as the
reference loaders do.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from predictor.data import Recording, read_split
from predictor.ethucy import OBS_LEN, PRED_LEN


@dataclass(frozen=True)
class Window:
    """One scene window.

    Attributes:
        obs: (8, N, 2) observed absolute positions, m, oldest first.
        pred: (12, N, 2) future absolute positions, m.
        ped_ids: (N,) int pedestrian ids from the file.
        group_id: (N,) int ground-truth group ids 0..G-1, or None when the file has no group labels.
        source: file name the window comes from.
        start_frame: frame id of the first observed step.
    """

    obs: np.ndarray
    pred: np.ndarray
    ped_ids: np.ndarray
    group_id: np.ndarray | None
    source: str = ""
    start_frame: float = 0.0

    @property
    def n_peds(self) -> int:
        return int(self.obs.shape[1])


def labels_for(ped_ids: np.ndarray, groups: tuple[tuple[int, ...], ...]) -> np.ndarray:
    """Group ids 0..G-1 for ``ped_ids`` (N,); a ped in no listed group is its own group of one.

    Ids are numbered by first appearance along ``ped_ids``.
    """
    owner = {pid: gi for gi, members in enumerate(groups) for pid in members}
    raw = [owner.get(int(p), -1 - i) for i, p in enumerate(ped_ids)]
    remap: dict[int, int] = {}
    return np.array([remap.setdefault(r, len(remap)) for r in raw], dtype=np.int64)


def _presence(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Dense (F, P) presence and (F, P, 2) position tables of one recording, frames and peds sorted."""
    frames, f_idx = np.unique(rows[:, 0], return_inverse=True)
    peds, p_idx = np.unique(rows[:, 1], return_inverse=True)
    present = np.zeros((len(frames), len(peds)), dtype=bool)
    pos = np.zeros((len(frames), len(peds), 2))
    present[f_idx, p_idx] = True
    pos[f_idx, p_idx] = np.round(rows[:, 2:4], 4)
    return frames, peds, present, pos


def _label_table(frame_labels: np.ndarray, frames: np.ndarray, peds: np.ndarray) -> np.ndarray:
    """Dense (F, P) per-frame group labels (-1 where a row has none) aligned with ``_presence``."""
    table = -np.ones((len(frames), len(peds)), dtype=np.int64)
    fi = np.searchsorted(frames, frame_labels[:, 0])
    pi = np.searchsorted(peds, frame_labels[:, 1])
    ok = (fi < len(frames)) & (pi < len(peds))
    ok[ok] &= (frames[fi[ok]] == frame_labels[ok, 0]) & (peds[pi[ok]] == frame_labels[ok, 1])
    table[fi[ok], pi[ok]] = frame_labels[ok, 2].astype(np.int64)
    return table


def _window_labels(
    rec: Recording, table: np.ndarray | None, frame: int, cols: np.ndarray, ids: np.ndarray
) -> np.ndarray | None:
    """Window group ids: per-frame labels at the last observed frame, else the group file, else None."""
    if table is not None:
        raw = table[frame, cols]
        raw = np.where(raw < 0, -1 - np.arange(len(raw)), raw)  # unlabelled rows: own groups
        remap: dict[int, int] = {}
        return np.array([remap.setdefault(int(r), len(remap)) for r in raw], dtype=np.int64)
    return labels_for(ids, rec.groups) if rec.groups is not None else None


def recording_windows(
    rec: Recording, obs_len: int = OBS_LEN, pred_len: int = PRED_LEN, min_peds: int = 2
) -> list[Window]:
    """All windows of one recording, in frame order; peds within a window in increasing id order."""
    if len(rec.rows) == 0:
        return []
    seq_len = obs_len + pred_len
    frames, peds, present, pos = _presence(rec.rows)
    if len(frames) < seq_len:
        return []
    labels = _label_table(rec.frame_labels, frames, peds) if rec.frame_labels is not None else None
    csum = np.concatenate([np.zeros((1, len(peds)), dtype=np.int64), np.cumsum(present, axis=0)])
    full = (csum[seq_len:] - csum[:-seq_len]) == seq_len  # (F - seq_len + 1, P)
    out: list[Window] = []
    for start in np.flatnonzero(full.sum(axis=1) >= min_peds):
        cols = np.flatnonzero(full[start])
        traj = pos[start : start + seq_len, cols]
        ids = peds[cols].astype(np.int64)
        gid = _window_labels(rec, labels, start + obs_len - 1, cols, ids)
        out.append(
            Window(
                obs=traj[:obs_len].copy(),
                pred=traj[obs_len:].copy(),
                ped_ids=ids,
                group_id=gid,
                source=rec.path.name,
                start_frame=float(frames[start]),
            )
        )
    return out


def load_windows(folder: str | Path, min_peds: int = 2) -> list[Window]:
    """Windows of every trajectory file in one split folder (files in sorted name order)."""
    windows: list[Window] = []
    for rec in read_split(folder):
        windows.extend(recording_windows(rec, min_peds=min_peds))
    return windows


def rotate_window(window: Window, angle: float) -> Window:
    """Rotate a window by ``angle`` radians (counter-clockwise) about its last observed centroid."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    centre = window.obs[-1].mean(axis=0)
    obs = (window.obs - centre) @ rot.T + centre
    pred = (window.pred - centre) @ rot.T + centre
    return Window(obs, pred, window.ped_ids, window.group_id, window.source, window.start_frame)


def augment_rotations(windows: list[Window], rng: np.random.Generator) -> list[Window]:
    """A uniformly random rotation in [0, 2 pi) for each window (training augmentation)."""
    return [rotate_window(w, float(rng.uniform(0.0, 2.0 * np.pi))) for w in windows]


def has_labels(windows: list[Window]) -> bool:
    """Whether every window carries ground-truth group labels."""
    return bool(windows) and all(w.group_id is not None for w in windows)


def window_tracks(rows: np.ndarray, windows: list[Window], steps: int) -> list[np.ndarray]:
    """Each window's pedestrians' longer past: (steps, N, 2) m per window of ``recording_windows(rows)``, the
    recording's frames up to the window's last observed one (its 8 observed rows are the last 8), NaN before the
    run of consecutive frames in which a pedestrian is present up to the window (and before the recording starts).
    This is what a group rule may read instead of the 8 steps (``predictor.api``'s ``track``)."""
    if steps < OBS_LEN:
        raise ValueError(f"steps must be >= {OBS_LEN} (the observed window), got {steps}")
    frames, peds, present, pos = _presence(rows)
    out = []
    for w in windows:
        end = int(np.searchsorted(frames, w.start_frame)) + OBS_LEN  # one past the last observed frame
        cols = np.searchsorted(peds, w.ped_ids)
        track = np.full((steps, len(cols), 2), np.nan)
        lo = max(0, end - steps)
        seen = present[lo:end, cols]  # (rows, N)
        # a row counts only if the pedestrian is present there and in every later row up to the window
        run = np.flip(np.cumprod(np.flip(seen, axis=0), axis=0), axis=0).astype(bool)
        block = np.where(run[..., None], pos[lo:end, cols], np.nan)
        track[steps - (end - lo):] = block
        out.append(track)
    return out
