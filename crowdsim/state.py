"""Crowd state as small dataclasses of arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CrowdState:
    """The crowd at one instant. Arrays are capacity-sized (C rows); rows with active=False are unused
    (positions NaN, ids -1).

    pos (C, 2) m, vel (C, 2) m/s, goal (C, 2) m, radius (C,) m, group_id (C,) int dense 0..G-1 over the
    active rows, ped_id (C,) int stable over a run and never reused, active (C,) bool; label (C,) int the
    stable group label (the same group keeps it for its lifetime and no other group ever gets it; -1 on
    inactive rows), which the exporters write; frame is the recording step index and time_s = frame *
    record_dt_s.
    """

    pos: np.ndarray
    vel: np.ndarray
    goal: np.ndarray
    radius: np.ndarray
    group_id: np.ndarray
    ped_id: np.ndarray
    active: np.ndarray
    label: np.ndarray
    frame: int
    time_s: float

    @property
    def n_active(self) -> int:
        return int(self.active.sum())


@dataclass
class Slots:
    """Mutable per-slot storage of the simulator. `label` is the global group label (never reused)."""

    pos: np.ndarray
    vel: np.ndarray
    goal: np.ndarray
    radius: np.ndarray
    speed: np.ndarray  # desired speed, m/s
    label: np.ndarray
    ped_id: np.ndarray
    active: np.ndarray

    @classmethod
    def empty(cls, capacity: int) -> Slots:
        return cls(
            pos=np.zeros((capacity, 2)), vel=np.zeros((capacity, 2)), goal=np.zeros((capacity, 2)),
            radius=np.zeros(capacity), speed=np.zeros(capacity), label=np.full(capacity, -1, np.int64),
            ped_id=np.full(capacity, -1, np.int64), active=np.zeros(capacity, bool),
        )

    def activate(self, slot: int, ped_id: int, label: int, pos: np.ndarray, goal: np.ndarray,
                 radius: float, speed: float) -> None:
        self.pos[slot] = pos
        self.vel[slot] = 0.0
        self.goal[slot] = goal
        self.radius[slot] = radius
        self.speed[slot] = speed
        self.label[slot] = label
        self.ped_id[slot] = ped_id
        self.active[slot] = True

    def deactivate(self, slot: int) -> None:
        self.active[slot] = False
        self.label[slot] = -1
        self.ped_id[slot] = -1

    def dense_labels(self, idx: np.ndarray) -> np.ndarray:
        """Group labels of rows idx renumbered 0..G-1 in order of first label value."""
        _, dense = np.unique(self.label[idx], return_inverse=True)
        return dense.astype(np.int64)

    def snapshot(self, frame: int, time_s: float, dense: np.ndarray | None = None) -> CrowdState:
        """The state now; dense: the active rows' dense labels if the caller has them (else computed)."""
        act = self.active.copy()
        nan2 = np.where(act[:, None], 1.0, np.nan)
        group = np.full(len(act), -1, np.int64)
        group[act] = self.dense_labels(np.flatnonzero(act)) if dense is None else dense
        return CrowdState(
            pos=self.pos * nan2, vel=self.vel * nan2, goal=self.goal * nan2,
            radius=np.where(act, self.radius, np.nan), group_id=group, ped_id=self.ped_id.copy(),
            active=act, label=np.where(act, self.label, -1), frame=frame, time_s=time_s,
        )
