"""The space-time search layer (planner/spacetime.py): it leaves the goal alone where the straight run is open, and
otherwise points the robot at the gap in an oncoming file of walkers, or keeps it back where nothing is open."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from planner import MPCPlanner, PedPrediction, SpaceTimeConfig
from planner.config import CROWD_MPC
from planner.spacetime import SpaceTimeSearch

GOAL = np.array([10.0, 0.0])


def search() -> SpaceTimeSearch:
    return SpaceTimeSearch(SpaceTimeConfig(), speed_mps=1.2, horizon_s=4.0, robot_radius_m=0.3, wall_clearance_m=0.05)


def file_of_walkers(ys, x0: float = 3.0, speed: float = 1.0) -> PedPrediction:
    """Walkers at x0 and heights ys, walking at `speed` towards a robot at the origin (-x), 12 steps of 0.4 s."""
    ys = np.asarray(ys, float)
    now = np.c_[np.full(len(ys), x0), ys]
    future = now[None, None] + (0.4 * np.arange(1, 13))[None, :, None, None] * np.array([-speed, 0.0])
    n = len(ys)
    return PedPrediction(future, np.full(n, 0.3), np.arange(n), np.ones(n, bool), current=now, step_s=0.4)


def test_nobody_or_an_open_straight_run_keeps_the_goal():
    assert np.array_equal(search().subgoal(np.zeros(2), GOAL, None, None), GOAL)
    beside = file_of_walkers([4.0, 5.0], speed=0.0)  # standing 4 m to the side of the line
    assert np.array_equal(search().subgoal(np.zeros(2), GOAL, beside, None), GOAL)


def test_the_subgoal_leads_into_the_gap_of_an_oncoming_file():
    # a solid file from y = -2.7 to 1.1 (walkers 0.6 m apart, 0.7 m clearance each) with a gap at y = 1.1 .. 1.9
    ys = [-2.0, -1.4, -0.8, -0.2, 0.4, 2.6, 3.2]
    sub = search().subgoal(np.zeros(2), GOAL, file_of_walkers(ys), None)
    assert not np.array_equal(sub, GOAL)
    assert sub[1] > 0.5 and np.hypot(*sub) <= 1.2 * 1.6 + 0.3  # towards the gap, at most lead_s away


def test_the_mpc_heads_for_the_searched_subgoal():
    ys = [-2.0, -1.4, -0.8, -0.2, 0.4, 2.6, 3.2]
    planner = MPCPlanner(replace(CROWD_MPC, spacetime=SpaceTimeConfig()))
    result = planner.plan(np.array([0.0, 0.0, 0.0, 0.0, 0.0]), GOAL, file_of_walkers(ys), None)
    assert result.subgoal is not None and result.subgoal[1] > 0.5


def test_config_is_validated():
    with pytest.raises(ValueError, match="cell_m"):
        SpaceTimeConfig(cell_m=0.0)
    with pytest.raises(ValueError, match="clearance_m"):
        SpaceTimeConfig(clearance_m=-0.1)
