"""Detours round wall corners (`crowdsim.detour`): before them, people pushed round a corner pressed against the
wall that hid their goal for the rest of the run (the default 24-person crossing and plaza, 600 s, seeds
2000-2003: five people in the crossing stuck for 100-420 s, three in the plaza; none with detours)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from crowdsim.config import GroupConfig, SimConfig, SocialForceParams
from crowdsim.detour import Corners, aims, corner_waypoints, sight_blocked, wall_ends
from crowdsim.scenarios import make_scenario
from crowdsim.sim import CrowdSimulator

CROSSING = make_scenario("crossing").walls  # streets 6 m wide; inner corners at (+-3, +-3)


def test_waypoints_lie_outside_each_corner_and_beyond_free_ends():
    points = corner_waypoints(CROSSING, 0.6)
    inner = 3.0 - 0.6 / np.sqrt(2.0)
    for sx in (-1, 1):
        for sy in (-1, 1):
            assert np.min(np.linalg.norm(points - [sx * inner, sy * inner], axis=1)) < 1e-9
    gate = corner_waypoints(make_scenario("plaza").walls, 0.6)  # the west gate of the plaza: jambs at (0, 8), (0, 12)
    assert np.min(np.linalg.norm(gate - [0.0, 8.6], axis=1)) < 1e-9
    assert np.min(np.linalg.norm(gate - [0.0, 11.4], axis=1)) < 1e-9
    assert corner_waypoints(CROSSING, 0.0).shape == (0, 2)


def test_a_line_that_grazes_a_corner_is_out_of_sight_and_a_clear_one_is_not():
    ends = wall_ends(CROSSING)
    start = np.array([[2.5, 3.6], [2.5, 3.6], [-5.0, 0.0]])
    end = np.array([[11.0, 2.4], [2.5, -9.0], [9.0, 1.0]])
    # through the wall; past the corner (3, 3) 0.5 m away, inside the 0.3 m margin? no: clear; along the street
    np.testing.assert_array_equal(sight_blocked(start, end, CROSSING, ends, 0.3), [True, False, False])
    grazing = np.array([[2.75, 2.5]]), np.array([[2.75, 9.0]])  # passes 0.25 m from the corner (3, 3)
    assert sight_blocked(*grazing, CROSSING, ends, 0.3)[0] and not sight_blocked(*grazing, CROSSING, ends, 0.2)[0]


def test_aims_are_the_goals_themselves_when_every_goal_is_in_sight():
    pos, goal = np.array([[-5.0, 0.0], [0.0, -5.0]]), np.array([[11.0, 0.5], [0.5, 11.0]])
    assert aims(pos, goal, Corners.of(CROSSING, 0.6), 1.0) is goal


def test_someone_behind_a_corner_aims_round_it_without_slowing():
    pos, goal = np.array([[2.5, 3.6]]), np.array([[11.0, 2.4]])  # in the north street, its goal down the east one
    aim = aims(pos, goal, Corners.of(CROSSING, 0.6), 1.0)[0]
    heading = (aim - pos[0]) / np.linalg.norm(aim - pos[0])
    corner = np.array([3.0, 3.0]) - 0.6 / np.sqrt(2.0)
    np.testing.assert_allclose(heading, (corner - pos[0]) / np.linalg.norm(corner - pos[0]))
    assert np.linalg.norm(aim - pos[0]) >= 1.0 - 1e-12  # at least the slowdown radius away


def _walker_behind_the_corner(clearance_m: float) -> tuple[CrowdSimulator, int]:
    """A crossing with one person, put in the north street just above the corner (3, 3) with its goal down the east
    street (where people pushed round the corner got stuck); returns the simulator and the person's id."""
    config = SimConfig(scenario="crossing", n_pedestrians=1, groups=GroupConfig(size_poisson_rate=0.0, max_size=1),
                       social=replace(SocialForceParams(), detour_clearance_m=clearance_m))
    sim = CrowdSimulator(config)
    sim.reset(0)
    slot = int(np.flatnonzero(sim.slots.active)[0])
    sim.slots.pos[slot] = [2.55, 3.6]
    sim.slots.goal[slot] = [11.2, 2.4]
    sim.world.teleport(slot, sim.slots.pos[slot])
    return sim, int(sim.slots.ped_id[slot])


@pytest.mark.parametrize("clearance_m, leaves", [(0.6, True), (0.0, False)])
def test_a_walker_pushed_round_a_corner_walks_round_it_and_leaves(clearance_m, leaves):
    sim, ped = _walker_behind_the_corner(clearance_m)
    for _ in range(50):  # 20 s: 9 m to walk
        state = sim.step()
    assert (ped not in state.ped_id[state.active]) == leaves


@pytest.mark.parametrize("scenario", ["crossing", "plaza"])
def test_nobody_stays_for_minutes_in_a_scenario_crowd(scenario):
    """The default 24-person crowd with the corner fix on (0.6 m), 600 s: every group present at the end entered
    less than 2 minutes before (a walk across takes ~15 s)."""
    social = replace(SocialForceParams(), detour_clearance_m=0.6)
    for seed in (10, 11):
        sim = CrowdSimulator(SimConfig(scenario=scenario, n_pedestrians=24, social=social))
        sim.reset(seed)
        for _ in range(1500):
            sim.step()
        ages = [sim.time_s - since for since, _ in sim.book.entered.values()]
        assert max(ages) < 120.0, (seed, sorted(ages)[-3:])


@pytest.mark.parametrize("scenario", ["crossing", "plaza"])
def test_the_compiled_aims_match_the_numpy_reference(scenario):
    from crowdsim import kernels

    scene = make_scenario(scenario)
    corners = Corners.of(scene.walls, 0.6)
    rng = np.random.default_rng(0)
    lo, hi = np.array(scene.bounds[:2]) - 1.0, np.array(scene.bounds[2:]) + 1.0
    pos, goal = rng.uniform(lo, hi, (400, 2)), rng.uniform(lo, hi, (400, 2))
    reference = aims(pos, goal, corners, 1.0)
    assert (reference != goal).any(axis=1).mean() > 0.05  # some of these lines are out of sight and go round
    np.testing.assert_allclose(kernels.aims(pos, goal, corners, 1.0), reference, rtol=0, atol=1e-12)
