"""Shared helpers for crowdsim tests."""

from __future__ import annotations

import numpy as np

from crowdsim.config import GroupConfig, SimConfig
from crowdsim.sim import CrowdSimulator


def run(config: SimConfig, seed: int, steps: int) -> tuple[CrowdSimulator, list]:
    """Reset and step; returns the simulator and the list of states (initial state included)."""
    sim = CrowdSimulator(config)
    states = [sim.reset(seed)]
    for _ in range(steps):
        states.append(sim.step())
    return sim, states


def singles(n: int, **kw) -> SimConfig:
    """A config with no groups (every pedestrian alone)."""
    return SimConfig(n_pedestrians=n, groups=GroupConfig(size_poisson_rate=0.0, max_size=1), **kw)


def max_overlap(state) -> float:
    """Largest interpenetration r_i + r_j - d_ij (m) among active pedestrians (negative: none)."""
    act = state.active
    p, r = state.pos[act], state.radius[act]
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(np.max(r[:, None] + r[None] - d))
