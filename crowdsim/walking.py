"""Walking-speed measurements for the realism checks and calibrations (tests/crowdsim/test_fundamental_diagram.py,
scripts/calibrate_group_speed.py).

Two medians answer different questions. Over people (each pedestrian's mean speed over its walk) is what field
studies of free-walking speed report: one value per person observed. Over recorded steps (every |velocity|
sample) weights each person by the time it spends in view, so slow walkers count more (the space-mean speed of
traffic engineering, below the time-mean speed of the same crowd).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdsim.config import SimConfig
from crowdsim.sim import CrowdSimulator


@dataclass(frozen=True)
class WalkingSpeeds:
    """per_person (P,) m/s: each pedestrian's mean |velocity| over its recorded walk; group_size (P,) int: the
    size of its group for most of that walk; samples (S,) m/s: every |velocity| sample that went into them."""

    per_person: np.ndarray
    group_size: np.ndarray
    samples: np.ndarray

    def mean_by_size(self, size: int) -> float:
        """Mean over pedestrians of group `size` (m/s); NaN if there were none."""
        chosen = self.per_person[self.group_size == size]
        return float(chosen.mean()) if len(chosen) else float("nan")


def walking_speeds(config: SimConfig, seeds: list[int] | tuple[int, ...], steps: int = 1000,
                   skip: int = 5) -> WalkingSpeeds:
    """Run `config` for `steps` recorded steps per seed and measure how fast people walk, leaving out each
    pedestrian's first `skip` steps (its acceleration from rest as it walks in)."""
    per_person, group_size, samples = [], [], []
    for seed in seeds:
        sim = CrowdSimulator(config)
        sim.reset(seed)
        first: dict[int, int] = {}
        walks: dict[int, list[tuple[int, float]]] = {}
        for k in range(steps):
            s = sim.step()
            act = np.flatnonzero(s.active)
            labels, counts = np.unique(s.label[act], return_counts=True)
            size_of = dict(zip(labels.tolist(), counts.tolist(), strict=True))
            speeds = np.hypot(s.vel[act, 0], s.vel[act, 1])
            for a, speed in zip(act.tolist(), speeds.tolist(), strict=True):
                pid = int(s.ped_id[a])
                if k - first.setdefault(pid, k) >= skip:
                    walks.setdefault(pid, []).append((size_of[int(s.label[a])], speed))
        for walk in walks.values():
            sizes, speeds = np.array(walk).T
            per_person.append(speeds.mean())
            group_size.append(np.bincount(sizes.astype(int)).argmax())
            samples.extend(speeds.tolist())
    return WalkingSpeeds(np.array(per_person), np.array(group_size, dtype=int), np.array(samples))
