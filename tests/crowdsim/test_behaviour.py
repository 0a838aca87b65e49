"""Emergent behaviour: free walking, contact resolution, group cohesion and formation."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.config import GroupConfig, SimConfig
from crowdsim.sim import CrowdSimulator
from tests.crowdsim.conftest import max_overlap, run, singles


def test_lone_pedestrian_walks_at_its_desired_speed_and_stops_at_its_goal():
    sim = CrowdSimulator(singles(1, scenario="open"))
    sim.reset(3)
    desired = float(sim.slots.speed[0])
    goal = sim.slots.goal[0].copy()
    distance = float(np.linalg.norm(goal - sim.slots.pos[0]))
    speeds = []
    for _ in range(int(distance / desired / 0.4) + 25):
        state = sim.step()
        speeds.append(float(np.linalg.norm(state.vel[0])))
    cruise = np.median(speeds[5: int(0.6 * distance / desired / 0.4)])
    assert abs(cruise - desired) < 0.02 * desired
    assert np.linalg.norm(state.pos[0] - goal) < 0.3
    assert speeds[-1] < 0.05


@pytest.mark.parametrize("seed", [0, 1])
def test_no_overlap_beyond_a_few_centimetres_in_a_bottleneck_at_4_per_m2(seed):
    config = singles(120, scenario="bottleneck", radius_min_m=0.2, radius_max_m=0.24,
                     scenario_options=(("density", 4.0), ("continuous", 0.0), ("room_m", 8.0)))
    sim, states = run(config, seed=seed, steps=60)
    first = states[0].pos[states[0].active]
    box = (first[:, 0] > 4.6) & (first[:, 0] < 7.6) & (first[:, 1] > 1.5) & (first[:, 1] < 6.5)
    assert box.sum() / (3.0 * 5.0) >= 3.8  # in front of the door the crowd starts packed at ~4 persons/m^2
    worst = max(max_overlap(s) for s in states[1:])
    # 120 people pushing for the door: pymunk's contacts hold every pair to within 4 cm
    assert worst < 0.04, f"bodies interpenetrate by {worst:.3f} m"
    assert sim.n_exited > 10  # the crowd drains through the door rather than jamming for good


def _group_frames(states):
    """For each frame and group of 2+, the members' distances to the group centre and their layout."""
    for s in states:
        act = np.flatnonzero(s.active)
        for g in np.unique(s.group_id[act]):
            members = act[s.group_id[act] == g]
            if len(members) >= 2:
                yield s, members


def test_group_members_stay_cohesive_in_free_flow():
    config = SimConfig(scenario="plaza", n_pedestrians=30, groups=GroupConfig(size_poisson_rate=1.5))
    _, states = run(config, seed=1, steps=200)
    dists = []
    for s, members in _group_frames(states[10:]):
        centre = s.pos[members].mean(axis=0)
        dists.extend(np.linalg.norm(s.pos[members] - centre, axis=1))
    dists = np.array(dists)
    assert len(dists) > 1000
    assert np.mean(dists < 1.5) >= 0.95


def test_pairs_walk_abreast_at_low_density():
    config = SimConfig(scenario="corridor", n_pedestrians=16, groups=GroupConfig(size_poisson_rate=1.5),
                       scenario_options=(("length_m", 40.0), ("width_m", 8.0)))
    _, states = run(config, seed=2, steps=150)
    cosines = []
    for s, members in _group_frames(states[10:]):
        if len(members) != 2:
            continue
        v = s.vel[members].mean(axis=0)
        if np.linalg.norm(v) < 0.5:
            continue
        sep = s.pos[members[1]] - s.pos[members[0]]
        cosines.append(abs(sep @ v) / (np.linalg.norm(sep) * np.linalg.norm(v)))
    cosines = np.array(cosines)
    assert len(cosines) > 100
    # abreast: the separation is within 30 degrees of perpendicular to the walking direction
    assert np.mean(cosines < np.sin(np.deg2rad(30))) >= 0.8


def test_visible_robot_is_avoided_and_invisible_robot_is_ignored():
    results = {}
    for visible in (True, False):
        config = singles(1, scenario="open")
        config = SimConfig(**{**config.__dict__, "robot": type(config.robot)(visible=visible)})
        sim = CrowdSimulator(config)
        sim.reset(0)
        start, goal = sim.slots.pos[0].copy(), sim.slots.goal[0].copy()
        robot = start + 4.0 * (goal - start) / np.linalg.norm(goal - start)
        closest = np.inf
        for _ in range(40):
            sim.set_robot(robot, np.zeros(2), 0.3)
            s = sim.step()
            closest = min(closest, float(np.linalg.norm(s.pos[0] - robot)))
        passed = (s.pos[0] - robot) @ (goal - start) > 1.0
        results[visible] = (closest - 0.3 - s.radius[0], passed)
    assert results[True][0] > -0.02 and results[True][1]  # goes around the robot without entering it
    assert results[False][0] < -0.3 and results[False][1]  # walks straight through the invisible robot
