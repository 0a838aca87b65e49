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

from crowdsim import behaviours
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


@dataclass(frozen=True)
class GroupWalks:
    """Walking speed per group, and the crowd's grouped share over time, of runs of one config over seeds.

    One row per group and run: speed (G,) m/s, the mean over its members of each member's mean |velocity| over
    its walking steps (not stopping or standing, after its first `skip` steps); desired (G,) m/s, the same mean of
    its members' desired speeds; size (G,) int, the group's size over most of those member-steps; seed (G,) int.
    share (R, T): the fraction of the active pedestrians in groups of two or more at each of T recorded steps of
    each of R runs (time record_dt_s apart)."""

    speed: np.ndarray
    desired: np.ndarray
    size: np.ndarray
    seed: np.ndarray
    share: np.ndarray

    def by_size(self, size: int) -> np.ndarray:
        """(g,) walking speeds (m/s) of the groups of `size`."""
        return self.speed[self.size == size]

    def relative_by_size(self, size: int, drop_per_member_mps: float) -> np.ndarray:
        """(g,) m/s per group of `size`: speed - desired - drop_per_member_mps (size - 1), drop the configured
        `GroupConfig.speed_drop_per_member_mps`. Its mean minus that of size 1 estimates mean(by_size(size)) -
        mean(by_size(1)) (up to the clipping of desired speeds) with each group's draw of desired speed (spread
        0.26 m/s) replaced by its expectation, as `WalkingSpeeds.relative_speed_by_size` does."""
        chosen = self.size == size
        return self.speed[chosen] - self.desired[chosen] - drop_per_member_mps * (size - 1)


def group_walks(config: SimConfig, seeds: list[int] | tuple[int, ...] | range, steps: int = 1000,
                skip: int = 5) -> GroupWalks:
    """Run `config` for `steps` recorded steps per seed; see `GroupWalks`. A group's size is counted each step
    among the active pedestrians (a group that is partly through its exit counts as smaller)."""
    rows, share = [], []
    for seed in seeds:
        sim = CrowdSimulator(config)
        sim.reset(seed)
        first: dict[int, int] = {}
        walks: dict[int, list[tuple[int, int, float, float]]] = {}  # ped id -> (label, size, speed, desired)
        shares = []
        for k in range(steps):
            s = sim.step()
            act = np.flatnonzero(s.active)
            counts = np.bincount(s.group_id[act])[s.group_id[act]]
            shares.append(float((counts >= 2).mean()) if len(act) else np.nan)
            moving = ~behaviours.stopped(sim.book, s.label[act]) if sim.book.stops else np.ones(len(act), bool)
            speeds = np.hypot(s.vel[act, 0], s.vel[act, 1])
            for a, n, v, want, go in zip(act.tolist(), counts.tolist(), speeds.tolist(),
                                         sim.slots.speed[act].tolist(), moving.tolist(), strict=True):
                pid = int(s.ped_id[a])
                if k - first.setdefault(pid, k) >= skip and go:
                    walks.setdefault(pid, []).append((int(s.label[a]), n, v, want))
        rows.extend((seed, *row) for row in _group_rows(walks))
        share.append(shares)
    seed_, speed, desired, size = (np.array(c) for c in zip(*rows, strict=True)) if rows else [np.zeros(0)] * 4
    return GroupWalks(speed.astype(float), desired.astype(float), size.astype(int), seed_.astype(int),
                      np.array(share, dtype=float).reshape(len(share), steps))


def _group_rows(walks: dict[int, list[tuple[int, int, float, float]]]) -> list[tuple[float, float, int]]:
    """(speed, desired, size) per group label from per-pedestrian walks (label, size, speed, desired); a member
    counts for the label it held most steps."""
    groups: dict[int, list[tuple[float, float, np.ndarray]]] = {}
    for walk in walks.values():
        labels, sizes, speeds, wants = np.array(walk).T
        label = int(np.bincount(labels.astype(int)).argmax())
        groups.setdefault(label, []).append((speeds.mean(), wants.mean(), sizes.astype(int)))
    rows = []
    for members in groups.values():
        sizes = np.concatenate([m[2] for m in members])
        rows.append((float(np.mean([m[0] for m in members])), float(np.mean([m[1] for m in members])),
                     int(np.bincount(sizes).argmax())))
    return rows
