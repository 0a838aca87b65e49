"""Walking-speed measurements for the realism checks and calibrations (tests/crowdsim/test_fundamental_diagram.py,
scripts/calibrate_group_speed.py).

Two medians answer different questions. Over people (each pedestrian's mean speed over its walk) is what field
studies of free-walking speed report: one value per person observed. Over recorded steps (every |velocity|
sample) weights each person by the time it spends in view, so slow walkers count more (the space-mean speed of
traffic engineering, below the time-mean speed of the same crowd).

How much slower groups of each size walk than people alone is the difference of their mean speeds
(`mean_by_size`), but that difference is dominated by the draw of each group's desired speed (N(mean, 0.26) m/s
per group; a 40-seed sparse plaza leaves groups of 5 scattered by about 0.015 m/s). `relative_speed_by_size`
estimates the same quantity with that draw replaced by its expectation: the configured drop of the desired speed
with size plus how far below their own desired speed the members walk, measured against people alone (a
control variate; the same mean, a fifth of the spread).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdsim.config import SimConfig
from crowdsim.sim import CrowdSimulator


@dataclass(frozen=True)
class WalkingSpeeds:
    """per_person (P,) m/s: each pedestrian's mean |velocity| over its recorded walk; group_size (P,) int: the
    size of its group for most of that walk; samples (S,) m/s: every |velocity| sample that went into them;
    desired (P,) m/s: each pedestrian's mean desired speed over the same steps."""

    per_person: np.ndarray
    group_size: np.ndarray
    samples: np.ndarray
    desired: np.ndarray

    def mean_by_size(self, size: int) -> float:
        """Mean over pedestrians of group `size` (m/s); NaN if there were none."""
        chosen = self.per_person[self.group_size == size]
        return float(chosen.mean()) if len(chosen) else float("nan")

    def shortfall_by_size(self, size: int) -> float:
        """Mean over pedestrians of group `size` of how far below their desired speed they walk (m/s; desired
        minus walked); NaN if there were none."""
        chosen = self.group_size == size
        return float((self.desired[chosen] - self.per_person[chosen]).mean()) if chosen.any() else float("nan")

    def relative_speed_by_size(self, size: int, drop_per_member_mps: float) -> float:
        """Walking speed of groups of `size` relative to people alone (m/s, negative: slower), with the draw of
        desired speeds replaced by its expectation: -drop_per_member_mps (size - 1) (the configured
        `GroupConfig.speed_drop_per_member_mps`) minus the extra shortfall below the desired speed of the
        group's members over that of people alone. Its expectation is that of mean_by_size(size) -
        mean_by_size(1) (up to the clipping of desired speeds); see the module docstring."""
        return -drop_per_member_mps * (size - 1) - (self.shortfall_by_size(size) - self.shortfall_by_size(1))


def walking_speeds(config: SimConfig, seeds: list[int] | tuple[int, ...], steps: int = 1000,
                   skip: int = 5) -> WalkingSpeeds:
    """Run `config` for `steps` recorded steps per seed and measure how fast people walk, leaving out each
    pedestrian's first `skip` steps (its acceleration from rest as it walks in)."""
    per_person, group_size, samples, desired = [], [], [], []
    for seed in seeds:
        sim = CrowdSimulator(config)
        sim.reset(seed)
        first: dict[int, int] = {}
        walks: dict[int, list[tuple[int, float, float]]] = {}
        for k in range(steps):
            s = sim.step()
            act = np.flatnonzero(s.active)
            labels, counts = np.unique(s.label[act], return_counts=True)
            size_of = dict(zip(labels.tolist(), counts.tolist(), strict=True))
            speeds = np.hypot(s.vel[act, 0], s.vel[act, 1])
            wanted = sim.slots.speed[act]
            for a, speed, want in zip(act.tolist(), speeds.tolist(), wanted.tolist(), strict=True):
                pid = int(s.ped_id[a])
                if k - first.setdefault(pid, k) >= skip:
                    walks.setdefault(pid, []).append((size_of[int(s.label[a])], speed, want))
        for walk in walks.values():
            sizes, speeds, wants = np.array(walk).T
            per_person.append(speeds.mean())
            desired.append(wants.mean())
            group_size.append(np.bincount(sizes.astype(int)).argmax())
            samples.extend(speeds.tolist())
    return WalkingSpeeds(np.array(per_person), np.array(group_size, dtype=int), np.array(samples),
                         np.array(desired))


def group_pair_geometry(obs: np.ndarray, group_id: np.ndarray, dt_s: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    """How far apart and how coherently the members of each group walk in one observed window.

    obs (T, N, 2) m: positions of N people at T frames dt_s apart (an ETH/UCY window: T = 8, 0.4 s);
    group_id (N,) int. Returns, for every pair of members of the same group, its mean distance over the window (m)
    and its mean relative speed |v_i - v_j| over the T - 1 frame differences (m/s), each (P,)."""
    iu, ju = np.triu_indices(obs.shape[1], 1)
    same = group_id[iu] == group_id[ju]
    iu, ju = iu[same], ju[same]
    dist = np.linalg.norm(obs[:, iu] - obs[:, ju], axis=-1).mean(axis=0)
    vel = np.diff(obs, axis=0) / dt_s
    rel = np.linalg.norm(vel[:, iu] - vel[:, ju], axis=-1).mean(axis=0)
    return dist, rel
