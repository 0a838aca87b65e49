"""The lane layer (planner/lanes.py): in a bidirectional flow the subgoal moves to the side that is not oncoming,
never towards a wall, and changes nothing when nobody is ahead or the goal is near."""

from __future__ import annotations

import numpy as np
import pytest
from planner_helpers import STEP_S, make_config

from planner import MPCPlanner, PedPrediction
from planner.config import LaneConfig
from planner.lanes import LaneKeeper, walker_states
from planner.scene import point_segment_distances

CORRIDOR = np.array([[-5.0, 0.0, 25.0, 0.0], [-5.0, 4.0, 25.0, 4.0]])  # 4 m wide, along x
CLEARANCE_M = 0.35


def flow(positions, velocities, n_steps: int = 3) -> PedPrediction:
    """A one-sample constant-velocity prediction of walkers at positions (n, 2) m with velocities (n, 2) m/s."""
    pos, vel = np.asarray(positions, float), np.asarray(velocities, float)
    steps = STEP_S * np.arange(1, n_steps + 1)
    future = pos[None] + steps[:, None, None] * vel[None]
    n = len(pos)
    return PedPrediction(future[None], np.full(n, 0.3), np.arange(n), np.ones(n, bool), current=pos, step_s=STEP_S)


def oncoming_lane(y: float, x0: float = 3.0, count: int = 4) -> PedPrediction:
    """`count` walkers in a file at height y, ahead of a robot at x = 0 heading +x, walking towards it (-x)."""
    xs = x0 + 1.2 * np.arange(count)
    return flow(np.c_[xs, np.full(count, y)], np.tile([-1.2, 0.0], (count, 1)))


@pytest.mark.parametrize("lane_y, side", [(1.0, +1), (3.0, -1)])
def test_the_subgoal_moves_away_from_the_oncoming_lane(lane_y, side):
    keeper = LaneKeeper(LaneConfig(), CLEARANCE_M)
    robot, goal = np.array([0.0, 2.0]), np.array([15.0, 2.0])
    sub = keeper.subgoal(robot, goal, oncoming_lane(lane_y), CORRIDOR)
    assert np.sign(sub[1] - 2.0) == side  # oncoming below -> go up (left of +x), oncoming above -> go down
    assert abs(sub[1] - lane_y) > 0.8


def test_the_same_file_walking_the_robots_way_pulls_less_than_oncoming():
    robot, goal = np.array([0.0, 2.0]), np.array([15.0, 2.0])
    xs = 3.0 + 1.2 * np.arange(4)
    coming = flow(np.c_[xs, np.full(4, 1.4)], np.tile([-1.2, 0.0], (4, 1)))
    going = flow(np.c_[xs, np.full(4, 1.4)], np.tile([1.2, 0.0], (4, 1)))
    away_coming = LaneKeeper(LaneConfig(), CLEARANCE_M).subgoal(robot, goal, coming, CORRIDOR)[1] - 1.4
    away_going = LaneKeeper(LaneConfig(), CLEARANCE_M).subgoal(robot, goal, going, CORRIDOR)[1] - 1.4
    assert away_coming > away_going >= 0.0


def test_the_carrot_line_keeps_the_wall_clearance_plus_the_extra():
    cfg = LaneConfig()
    keeper = LaneKeeper(cfg, CLEARANCE_M)
    robot, goal = np.array([0.0, 1.2]), np.array([15.0, 1.2])
    sub = keeper.subgoal(robot, goal, oncoming_lane(1.5), CORRIDOR)  # oncoming just above: "down" is the wall
    line = robot + np.linspace(0.0, 1.0, 50)[:, None] * (sub - robot)
    assert point_segment_distances(line, CORRIDOR).min() >= CLEARANCE_M + cfg.wall_extra_m - 1e-9
    assert sub[1] > 2.5  # it passes on the open side instead


@pytest.mark.parametrize("case", ["nobody", "behind", "near goal"])
def test_no_offset_without_people_ahead_or_near_the_goal(case):
    keeper = LaneKeeper(LaneConfig(), CLEARANCE_M)
    robot, goal = np.array([0.0, 2.0]), np.array([15.0, 2.0])
    if case == "nobody":
        pred = None
    elif case == "behind":
        pred = flow([[-2.0, 2.0], [-3.0, 1.0]], [[1.2, 0.0], [1.2, 0.0]])
    else:
        goal, pred = np.array([3.0, 2.0]), oncoming_lane(2.0, x0=1.0)
    np.testing.assert_array_equal(keeper.subgoal(robot, goal, pred, CORRIDOR), goal)
    assert keeper.offset_m == 0.0


def test_the_offset_is_sticky_against_a_marginal_change():
    cfg = LaneConfig()
    keeper = LaneKeeper(cfg, CLEARANCE_M)
    robot, goal = np.array([0.0, 2.0]), np.array([15.0, 2.0])
    first = keeper.subgoal(robot, goal, oncoming_lane(2.1), CORRIDOR)[1]  # just above the line: go down
    assert first < 2.0
    again = keeper.subgoal(robot, goal, oncoming_lane(1.95), CORRIDOR)[1]  # now just below: stay down
    assert again < 2.0


def test_walker_states_are_positions_and_first_step_velocities():
    pred = flow([[1.0, 2.0], [3.0, -1.0]], [[0.5, 0.0], [0.0, -1.0]])
    pos, vel = walker_states(pred)
    np.testing.assert_allclose(pos, [[1.0, 2.0], [3.0, -1.0]])
    np.testing.assert_allclose(vel, [[0.5, 0.0], [0.0, -1.0]], atol=1e-12)


def test_the_mpc_heads_for_the_lane_subgoal_only_when_configured():
    pred = oncoming_lane(1.0)
    state, goal = np.array([0.0, 2.0, 0.0, 0.0, 0.0]), np.array([15.0, 2.0])
    plain = MPCPlanner(make_config()).plan(state, goal, pred, CORRIDOR)
    laned = MPCPlanner(make_config(lane=LaneConfig())).plan(state, goal, pred, CORRIDOR)
    np.testing.assert_array_equal(plain.subgoal, goal)
    assert laned.subgoal[1] > 2.2  # away from the oncoming file at y = 1


@pytest.mark.parametrize("field", ["carrot_m", "kernel_m", "offset_step_m"])
def test_bad_lane_settings_are_refused(field):
    with pytest.raises(ValueError, match=field):
        LaneConfig(**{field: 0.0})
    with pytest.raises(ValueError, match="switch_weight"):
        LaneConfig(switch_weight=float("nan"))
