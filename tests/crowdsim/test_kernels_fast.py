"""crowdsim's compiled step helpers (`crowdsim.kernels`) give the numpy code's numbers bit for bit (the gaze
sub-groups are checked beside their numpy reference in `tests/envs/test_env_fast_paths.py`)."""

from __future__ import annotations

import numpy as np

from crowdsim import forces
from crowdsim.kernels import any_within, cap_speed_rows


def test_speed_cap_and_arrival_check_match_numpy() -> None:
    rng = np.random.default_rng(6)
    for _ in range(500):
        c = int(rng.integers(1, 40))
        vel, speed = rng.normal(0, 1.5, (c, 2)), rng.uniform(0.5, 1.6, c)
        vel[rng.random(c) < 0.1] = 0.0
        idx = np.flatnonzero(rng.random(c) < 0.7)
        want = vel.copy()
        want[idx] = forces.cap_speed(vel[idx], speed[idx] * 1.3)
        cap_speed_rows(vel, idx, speed, 1.3)
        assert np.array_equal(vel, want)
        pos, goal = rng.normal(0, 3, (c, 2)), rng.normal(0, 3, (c, 2))
        d = pos[idx] - goal[idx]
        assert any_within(pos, goal, idx, 1.0) == bool((np.sqrt(np.einsum("ij,ij->i", d, d)) < 1.0).any())
