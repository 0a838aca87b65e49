"""Pad windows into batched tensors (B windows, N = most pedestrians in any of them)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from torch import Tensor

from predictor.windows import Window


@dataclass(frozen=True)
class Batch:
    """Padded tensors; real pedestrians come first in each window.

    Attributes:
        obs_abs: (B, 8, N, 2) observed positions, m.
        obs_rel: (B, 8, N, 2) observed displacements, m/step (first step 0).
        pred_abs: (B, 12, N, 2) future positions, m.
        pred_rel: (B, 12, N, 2) future displacements, m/step (first from the last observed position).
        node_mask: (B, N) bool, real pedestrians.
        gt_groups: (B, N) long ground-truth group labels (-1 for padding), or None without labels.
    """

    obs_abs: Tensor
    obs_rel: Tensor
    pred_abs: Tensor
    pred_rel: Tensor
    node_mask: Tensor
    gt_groups: Tensor | None

    @property
    def counts(self) -> list[int]:
        return self.node_mask.sum(dim=1).tolist()

    def to(self, device: torch.device | str) -> Batch:
        """The same batch with every tensor on ``device`` (``self`` when they are already there)."""
        device = torch.device(device)
        if self.node_mask.device == device:
            return self
        move = lambda a: None if a is None else a.to(device)  # noqa: E731
        return Batch(*(move(getattr(self, f.name)) for f in fields(self)))


def relative(traj: np.ndarray, first: np.ndarray | None = None) -> np.ndarray:
    """Per-step displacements of (T, N, 2) positions; step 0 is relative to ``first`` (N, 2) or zero."""
    rel = np.zeros_like(traj)
    rel[1:] = traj[1:] - traj[:-1]
    if first is not None:
        rel[0] = traj[0] - first
    return rel


def collate(windows: list[Window], dtype: torch.dtype = torch.float32) -> Batch:
    """Stack windows into one padded batch."""
    if not windows:
        raise ValueError("cannot collate an empty list of windows")
    b, n = len(windows), max(w.n_peds for w in windows)
    obs = np.zeros((b, 8, n, 2))
    pred = np.zeros((b, 12, n, 2))
    obs_rel = np.zeros_like(obs)
    pred_rel = np.zeros_like(pred)
    mask = np.zeros((b, n), dtype=bool)
    labelled = all(w.group_id is not None for w in windows)
    groups = -np.ones((b, n), dtype=np.int64)
    for i, w in enumerate(windows):
        k = w.n_peds
        obs[i, :, :k], pred[i, :, :k], mask[i, :k] = w.obs, w.pred, True
        obs_rel[i, :, :k] = relative(w.obs)
        pred_rel[i, :, :k] = relative(w.pred, w.obs[-1])
        if labelled:
            groups[i, :k] = w.group_id
    t = lambda a: torch.as_tensor(a, dtype=dtype)  # noqa: E731
    return Batch(t(obs), t(obs_rel), t(pred), t(pred_rel), torch.from_numpy(mask),
                 torch.from_numpy(groups) if labelled else None)
