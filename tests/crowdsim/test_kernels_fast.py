"""crowdsim's compiled step helpers (`crowdsim.kernels`) give the numpy code's numbers bit for bit."""

from __future__ import annotations

import numpy as np

from crowdsim import forces
from crowdsim.groups import gaze_subgroups
from crowdsim.kernels import _gaze_subgroups, any_within, cap_speed_rows
from crowdsim.kernels import gaze_subgroups as fast_gaze_subgroups


def test_gaze_kernel_matches_the_numpy_function() -> None:
    rng = np.random.default_rng(5)
    left = 0
    for trial in range(1500):
        n = int(rng.integers(1, 120))
        label = np.unique(rng.integers(0, int(rng.integers(1, n + 1)), n), return_inverse=True)[1]
        pos, goal = rng.normal(0, 1, (n, 2)), rng.normal(0, 10, (n, 2))
        if trial % 3 == 0:
            pos = np.round(pos, 1)  # ties in the projection: the stable order decides
        got, compiled = _gaze_subgroups(pos, goal, label, 3)
        if not compiled:  # a group of more than 15 splits: numpy's mean sums pairwise, the numpy path does it
            left += 1
            assert np.bincount(label).max() > 15
        else:
            assert got.dtype == np.int64 and np.array_equal(got, gaze_subgroups(pos, goal, label))
        assert np.array_equal(fast_gaze_subgroups(pos, goal, label), gaze_subgroups(pos, goal, label))
    assert 0 < left < 500


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
