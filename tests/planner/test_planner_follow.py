"""The follow layer (planner/follow.py): the target is left alone unless someone is oncoming in the robot's lane;
then the subgoal is behind the walker going the robot's way whose lane is emptiest, at their predicted position, and
the last leader is kept between equal lanes."""

from __future__ import annotations

import numpy as np
import pytest

from planner import FollowConfig, MPCConfig, MPCPlanner, PedPrediction
from planner.follow import FollowLayer

RADIUS = 0.3
TARGET = np.array([12.0, 0.0])


def _walkers(start: list, velocity: list, steps: int = 12, step_s: float = 0.4) -> PedPrediction:
    """People at start (N, 2) m walking at velocity (N, 2) m/s, one exact sample of `steps` steps."""
    start, velocity = np.asarray(start, float), np.asarray(velocity, float)
    t = step_s * np.arange(1, steps + 1)
    pos = start[None] + t[:, None, None] * velocity[None]
    n = len(start)
    return PedPrediction(pos[None], np.full(n, RADIUS), np.arange(n), np.ones(n, bool), current=start, step_s=step_s)


def test_the_target_is_left_alone_without_anyone_oncoming_in_the_lane() -> None:
    layer = FollowLayer(FollowConfig())
    # a walker ahead going the robot's way, and an oncoming one outside the lane (2 m to the side)
    pred = _walkers([[2.0, 0.3], [4.0, 2.0]], [[1.0, 0.0], [-1.2, 0.0]])
    assert np.array_equal(layer.subgoal(np.zeros(2), TARGET, pred), TARGET)
    assert layer.leader is None
    assert np.array_equal(layer.subgoal(np.zeros(2), TARGET, None), TARGET)


def test_an_oncoming_walker_makes_the_robot_follow_the_leader_of_the_emptiest_lane() -> None:
    layer = FollowLayer(FollowConfig(at_s=4.0, gap_m=1.2))
    # oncoming at 3 m in the robot's lane; leader A in that lane (0.2 m off), leader B in a free lane 1.2 m to the left
    pred = _walkers([[3.0, 0.0], [1.5, 0.2], [2.5, 1.2]], [[-1.2, 0.0], [0.9, 0.0], [1.0, 0.0]])
    sub = layer.subgoal(np.zeros(2), TARGET, pred)
    assert np.allclose(layer.leader, [2.5, 1.2])
    # B's position 4 s ahead (2.5 + 4 x 1.0, 1.2), 1.2 m back along the way (+x)
    assert np.allclose(sub, [2.5 + 4.0 - 1.2, 1.2])


def test_past_the_prediction_the_leader_walks_on_at_its_last_velocity() -> None:
    layer = FollowLayer(FollowConfig(at_s=6.0, gap_m=1.0))
    pred = _walkers([[3.0, 0.0], [2.0, 1.0]], [[-1.2, 0.0], [0.8, 0.0]], steps=5)  # 2 s of prediction
    assert np.allclose(layer.subgoal(np.zeros(2), TARGET, pred), [2.0 + 6.0 * 0.8 - 1.0, 1.0])


def test_no_leader_or_a_leader_past_the_target_leaves_the_target() -> None:
    layer = FollowLayer(FollowConfig())
    oncoming = _walkers([[3.0, 0.0]], [[-1.2, 0.0]])
    assert np.array_equal(layer.subgoal(np.zeros(2), TARGET, oncoming), TARGET)
    slow = _walkers([[3.0, 0.0], [2.0, 1.0]], [[-1.2, 0.0], [0.3, 0.0]])  # the only walker the robot's way is slow
    assert np.array_equal(layer.subgoal(np.zeros(2), TARGET, slow), TARGET)
    near_target = np.array([4.0, 0.0])  # the leader's point 4 s ahead lies past a target 4 m away
    pred = _walkers([[3.0, 0.0], [2.0, 1.0]], [[-1.2, 0.0], [1.0, 0.0]])
    assert np.array_equal(layer.subgoal(np.zeros(2), near_target, pred), near_target)


def test_the_last_leader_is_kept_between_equal_lanes_and_forgotten_at_reset() -> None:
    layer = FollowLayer(FollowConfig())
    # two leaders in free lanes either side; the nearer (left, 2.0 m ahead) is chosen first
    first = _walkers([[3.0, 0.0], [2.0, 1.0], [2.6, -1.0]], [[-1.2, 0.0], [1.0, 0.0], [1.0, 0.0]])
    layer.subgoal(np.zeros(2), TARGET, first)
    assert np.allclose(layer.leader, [2.0, 1.0])
    # 0.1 s later the right one is nearer, but the left one is where it was expected: kept
    later = _walkers([[2.88, 0.0], [2.1, 1.0], [1.8, -1.0]], [[-1.2, 0.0], [1.0, 0.0], [1.0, 0.0]])
    layer.subgoal(np.zeros(2), TARGET, later)
    assert np.allclose(layer.leader, [2.1, 1.0])
    layer.reset()
    layer.subgoal(np.zeros(2), TARGET, later)
    assert np.allclose(layer.leader, [1.8, -1.0])


def test_the_planner_heads_for_the_layers_subgoal() -> None:
    planner = MPCPlanner(MPCConfig(follow=FollowConfig(), shield_horizon_s=0.0))
    pred = _walkers([[4.5, 0.0], [2.0, 1.2]], [[-1.2, 0.0], [1.0, 0.0]])
    result = planner.plan(np.zeros(5), TARGET, pred)
    assert np.allclose(result.subgoal, [2.0 + 4.0 - 1.2, 1.2])
    assert result.states[-1][1] > 0.5  # the plan moves over to the leader's lane


@pytest.mark.parametrize("field", ["look_m", "band_m", "at_s", "gap_m", "oncoming_mps"])
def test_bad_settings_are_refused(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        FollowConfig(**{field: float("nan")})
    with pytest.raises(ValueError, match=field):
        FollowConfig(**{field: -1.0})

