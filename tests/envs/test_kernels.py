"""The env's compiled per-step paths (`envs.scoring.kernels`) give the numpy code's numbers bit for bit.

Episodes must not change when a step gets faster, so each kernel is compared with the straightforward numpy
code it replaces (kept here as the reference) on random inputs, edge cases included (ties, zeros, pedestrians
on the robot, out-of-range rows, duplicate and collinear group members).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from envs.config import CrowdNavConfig
from envs.observation import build_observation, observation_space, rotation
from envs.scoring.geometry import intruded_groups, swept_distances
from envs.scoring.kernels import _intruded, step_distances
from envs.scoring.kernels import intruded_groups as fast_intruded_groups
from planner import RobotConfig


def _fma(a: float, b: float, c: float) -> float:
    return float(Fraction(a) * Fraction(b) + Fraction(c))


def _blas_rounds_with_fma() -> bool:
    """Whether numpy's small products here round as `envs.scoring.kernels` assumes (OpenBLAS on x86-64 with FMA)."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        p, r = rng.normal(0, 5, (3, 2)), rotation(float(rng.uniform(-3, 3)))
        got = p @ r.T
        if any(got[k, i] != _fma(p[k, 1], r[i, 1], _fma(p[k, 0], r[i, 0], 0.0)) for k in range(3) for i in range(2)):
            return False
    return True


def _observation_reference(cfg, space, robot_state, goal, time_left, pos, vel, radius, group_id):
    """The observation's numpy code before it was compiled (robot, pedestrians, mask and group ids)."""
    p = cfg.observation.max_pedestrians
    unicycle = cfg.robot.model == "unicycle"
    rot = rotation(float(robot_state[2])) if unicycle else np.eye(2)
    here = robot_state[:2]
    goal_rel = rot @ (goal - here)
    robot_vel = robot_state[3:5] if unicycle else robot_state[2:4]
    robot = np.array([goal_rel[0], goal_rel[1], np.linalg.norm(goal - here), robot_vel[0], robot_vel[1],
                      cfg.robot.radius_m, time_left])
    d = pos - here
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    order = np.argsort(dist, kind="stable")
    rows = order[dist[order] <= cfg.observation.sensor_range_m][:p]
    n = len(rows)
    peds = np.zeros((p, 5))
    peds[:n, :2] = (pos[rows] - here) @ rot.T
    peds[:n, 2:4] = vel[rows] @ rot.T
    peds[:n, 4] = radius[rows]
    mask = np.zeros(p)
    mask[:n] = 1.0
    groups, rank = np.full(p, -1.0), {}
    groups[:n] = [rank.setdefault(i, len(rank)) for i in group_id[rows].tolist()]
    out = {"robot": robot, "pedestrians": peds, "pedestrian_mask": mask, "group_ids": groups}
    return {k: np.clip(v, space[k].low, space[k].high).astype(np.float32) for k, v in out.items()}


@pytest.mark.skipif(not _blas_rounds_with_fma(), reason="numpy's BLAS here rounds small products another way")
@pytest.mark.parametrize("model", ["unicycle", "holonomic"])
def test_observation_kernel_matches_the_numpy_code_bit_for_bit(model: str) -> None:
    cfg = CrowdNavConfig(robot=RobotConfig(model=model))
    space = observation_space(cfg)
    rng = np.random.default_rng(1)
    for t in range(3000):
        n = int(rng.integers(0, 30))
        pos, vel = rng.normal(0, 6, (n, 2)), rng.normal(0, 1, (n, 2))
        radius, gid = rng.uniform(0.2, 0.4, n), rng.integers(0, max(1, n // 2), n)
        state = rng.normal(0, 3, 5 if model == "unicycle" else 4)
        goal = rng.normal(0, 8, 2)
        if t % 3 == 0 and n:
            vel[rng.random(n) < 0.5] = 0.0  # standing people: signed zeros
        if t % 4 == 0 and n > 2:
            pos[1] = pos[0]  # a tie in distance: the stable order decides
        if t % 7 == 0 and n:
            pos[0] = state[:2]  # someone on the robot
        if t % 9 == 0:
            pos *= 10.0  # out of the sensor range and of the boxes
        if t % 13 == 0:
            goal = state[:2].copy()
        got = build_observation(cfg, space, state, goal, 0.5, pos, vel, radius, gid, None)
        want = _observation_reference(cfg, space, state, goal, 0.5, pos, vel, radius, gid)
        assert list(got) == list(want)
        for key in want:
            assert got[key].dtype == np.float32 and got[key].tobytes() == want[key].tobytes(), (t, key)


def test_step_distances_match_the_numpy_code() -> None:
    rng = np.random.default_rng(2)
    for t in range(3000):
        s = int(rng.integers(0, 30))
        pos0 = rng.normal(0, 4, (s, 2))
        pos = pos0.copy() if t % 5 == 0 else pos0 + rng.normal(0, 0.15, (s, 2))
        radius = rng.uniform(0.2, 0.35, s)
        active, active0 = rng.random(s) < 0.8, rng.random(s) < 0.8
        ped = rng.integers(0, 50, s)
        ped0 = np.where(rng.random(s) < 0.9, ped, ped + 1)  # some slots hold somebody else at the start
        pos[~active], pos0[~active0] = np.nan, np.nan
        start = rng.normal(0, 3, 2)
        here = start.copy() if t % 7 == 0 else start + rng.normal(0, 0.1, 2)
        centre, surface = step_distances(here, start, pos, radius, active, ped, pos0, active0, ped0, 0.3)
        want_centre = np.hypot(*(pos[active] - here).T)
        want = want_centre - radius[active] - 0.3
        both = (active0 & active & (ped0 == ped))[active]
        rows = np.flatnonzero(active)[both]
        if len(rows):
            swept = swept_distances(start, here, pos0[rows], pos[rows]) - radius[rows] - 0.3
            want[both] = np.minimum(want[both], swept)
        assert np.array_equal(centre, want_centre) and np.array_equal(surface, want)


def test_intrusion_kernel_finds_the_same_groups() -> None:
    rng = np.random.default_rng(3)
    hits = left = 0
    for t in range(5000):
        n = int(rng.integers(0, 14))
        pos, radius = rng.uniform(-3.0, 3.0, (n, 2)), rng.uniform(0.2, 0.3, n)
        if t % 3 == 0:
            pos = np.round(pos, 0)  # duplicate and collinear members
        group = rng.integers(0, 4, n)
        robot = pos[0].copy() if t % 5 == 0 and n else rng.uniform(-3.0, 3.0, 2)
        dist = np.hypot(*(pos - robot).T) if n else np.zeros(0)
        want = intruded_groups(robot, 0.6, pos, radius, group, 2.5, dist)
        assert fast_intruded_groups(robot, 0.6, pos, radius, group, 2.5, dist) == want
        if n:
            _, compiled = _intruded(float(robot[0]), float(robot[1]), 0.6, pos, radius, group, 2.5**2, 3.6, dist)
            left += not compiled  # a group standing on one point: handed to the numpy function
        hits += bool(want)
    assert hits > 200 and 0 < left < 250


def test_min_time_to_collision_matches_the_numpy_metric_bit_for_bit() -> None:
    """The env's per-step time to collision is the minimum of `envs.scoring.social_metrics.time_to_collision` over the
    present rows, to the last bit: in contact, receding, approaching, absent rows (NaN positions) and nobody present."""
    from envs.scoring.kernels import min_time_to_collision
    from envs.scoring.social_metrics import time_to_collision

    rng = np.random.default_rng(3)
    for trial in range(300):
        n = int(rng.integers(0, 12))
        pos = rng.uniform(-6, 6, (n, 2))
        vel = rng.uniform(-1.5, 1.5, (n, 2))
        radius = rng.uniform(0.2, 0.4, n)
        active = rng.random(n) < 0.8
        pos[~active] = np.nan  # absent rows hold anything
        start, robot_vel = rng.uniform(-1, 1, 2), rng.uniform(-1.2, 1.2, 2)
        if trial % 7 == 0 and active.any():  # somebody on the robot
            pos[np.flatnonzero(active)[0]] = start + 0.1
        got = min_time_to_collision(start, robot_vel, pos, vel, radius, active, 0.3)
        want = time_to_collision(pos[active] - start, vel[active] - robot_vel, radius[active] + 0.3)
        assert got == (float(want.min()) if active.any() else np.inf)
    head_on = min_time_to_collision(np.zeros(2), np.array([1.0, 0.0]), np.array([[3.0, 0.0]]), np.zeros((1, 2)),
                                    np.array([0.3]), np.array([True]), 0.3)
    assert head_on == pytest.approx(2.4)  # 3 m apart, closing at 1 m/s, touching at 0.6 m
