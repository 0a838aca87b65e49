"""The foresight search (planner/foresight.py): it leaves the MPC alone where the straight run is free, finds a way
that keeps clear of everyone where it is not (waiting or going round), keeps out of walls, and extends a short
prediction at constant velocity."""

from __future__ import annotations

import numpy as np
import pytest

from planner import ForesightConfig, MPCConfig, MPCPlanner, PedPrediction
from planner.foresight import ForesightSearch, person_tracks

RADIUS = 0.3


def _walkers(start: np.ndarray, velocity: np.ndarray, steps: int = 25, step_s: float = 0.4) -> PedPrediction:
    """People at start (N, 2) m walking at velocity (N, 2) m/s, one exact sample of `steps` steps."""
    t = step_s * np.arange(1, steps + 1)
    pos = start[None] + t[:, None, None] * velocity[None]
    n = len(start)
    return PedPrediction(pos[None], np.full(n, RADIUS), np.arange(n), np.ones(n, bool), current=start, step_s=step_s)


def _search(**kw: float) -> ForesightSearch:
    return ForesightSearch(ForesightConfig(**kw), speed_mps=1.2, robot_radius_m=RADIUS, wall_clearance_m=0.35)


def _clear_of(path: np.ndarray, pred: PedPrediction, step_s: float, contact: float) -> float:
    """The smallest distance less `contact` between the path (one point per step_s) and the walkers then."""
    tracks, _ = person_tracks(pred, step_s, len(path) - 1)
    return float((np.linalg.norm(tracks - path[:, None], axis=-1) - contact).min())


def test_free_straight_run_returns_the_target_itself() -> None:
    far = _walkers(np.array([[0.0, -8.0]]), np.array([[0.0, -1.0]]))  # walking away behind the robot
    s = _search()
    target = np.array([10.0, 0.0])
    assert np.array_equal(s.subgoal(np.zeros(2), target, far, None), target)
    assert s.last_path is None
    assert np.array_equal(s.subgoal(np.zeros(2), target, None, None), target)


def test_a_passing_file_is_waited_for_or_gone_round_and_the_way_keeps_clear() -> None:
    # a file of 8 walkers 0.8 m apart crossing the robot's line 3 m ahead from right to left at 1 m/s
    start = np.stack([np.full(8, 3.0), -2.0 - 0.8 * np.arange(8)], axis=1)
    pred = _walkers(start, np.tile([0.0, 1.0], (8, 1)))
    s = _search()
    target = np.array([6.0, 0.0])
    sub = s.subgoal(np.zeros(2), target, pred, None)
    assert s.last_path is not None and not np.array_equal(sub, target)
    path = s.last_path
    assert np.allclose(path[0], 0.0)
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert steps.max() <= 1.2 * 0.85 * 0.4 + 0.15 * np.sqrt(2) + 1e-9  # the searched robot's speed, within a cell
    # the way keeps the contact distance plus the margin (less a cell's half diagonal) at every step
    assert _clear_of(path, pred, 0.4, 2 * RADIUS) >= 0.3 - 0.15 / np.sqrt(2) - 1e-9
    # the straight run at full speed would have met the file
    straight = np.minimum(1.2 * 0.4 * np.arange(len(path)), 6.0)[:, None] * np.array([1.0, 0.0])
    assert _clear_of(straight, pred, 0.4, 2 * RADIUS) < 0
    assert np.linalg.norm(path[-1] - target) < 1.5  # behind the file, most of the way there in the 10 s view


def test_the_way_keeps_out_of_walls() -> None:
    # a wall across the straight line with a gap at y in [1.5, 3]; a walker blocks the straight run too
    walls = np.array([[4.0, -5.0, 4.0, 1.5], [4.0, 3.0, 4.0, 8.0]])
    pred = _walkers(np.array([[2.0, 0.0]]), np.array([[0.0, 0.0]]))
    s = _search()
    s.subgoal(np.zeros(2), np.array([8.0, 0.0]), pred, walls)
    assert s.last_path is not None
    from planner.scene import point_segment_distances
    assert point_segment_distances(s.last_path, walls).min() >= 0.35 - 1e-9


def test_tracks_interpolate_then_hold_the_last_velocity() -> None:
    pred = _walkers(np.array([[0.0, 0.0], [5.0, 1.0]]), np.array([[1.0, 0.0], [0.0, -0.5]]), steps=5)
    tracks, spread = person_tracks(pred, 0.2, 40)  # 8 s from a 2 s prediction
    expected = np.array([[0.0, 0.0], [5.0, 1.0]])[None] + 0.2 * np.arange(41)[:, None, None] * np.array(
        [[1.0, 0.0], [0.0, -0.5]])[None]
    assert np.allclose(tracks, expected)
    assert np.allclose(spread, 0.0)


def test_the_planner_heads_for_the_searched_point() -> None:
    start = np.stack([np.full(8, 3.0), -2.0 - 0.8 * np.arange(8)], axis=1)
    pred = _walkers(start, np.tile([0.0, 1.0], (8, 1)))
    cfg = MPCConfig(solver="ipopt", foresight=ForesightConfig())
    planner = MPCPlanner(cfg)
    result = planner.plan(np.zeros(5), np.array([10.0, 0.0]), pred)
    alone = _search().subgoal(np.zeros(2), np.array([10.0, 0.0]), pred, None)
    assert np.allclose(result.subgoal, alone)
    assert planner.foresight.nearest_m == pytest.approx(10.0)
    planner.reset()  # a new episode: the nearest approach is forgotten
    assert planner.foresight.nearest_m == np.inf


def _oncoming_line() -> PedPrediction:
    """A line of walkers 0.5 m apart across y in [-7, 7], 2.5 m ahead of the robot, walking at it at 0.6 m/s: no way
    through or round within the view, so the search backs away before it."""
    y = np.arange(-7.0, 7.01, 0.5)
    return _walkers(np.stack([np.full(len(y), 2.5), y], axis=1), np.tile([-0.6, 0.0], (len(y), 1)))


def test_a_retreat_past_the_nearest_approach_is_replaced_and_the_nearest_approach_is_per_episode() -> None:
    target, line = np.array([10.0, 0.0]), _oncoming_line()
    free = _search(retreat_m=float("inf"))
    backing = free.subgoal(np.zeros(2), target, line, None)
    assert backing[0] < -1.0  # unbounded, the search backs away from the line
    held = _search(retreat_m=0.5)
    assert np.array_equal(held.subgoal(np.zeros(2), target, line, None), np.zeros(2))
    assert held.last_path is not None  # the search ran; its subgoal was not taken
    # the bound is the nearest approach so far: from 3 m farther back, a retreat of 2 m is past it ...
    behind = np.array([-3.0, 0.0])
    assert np.array_equal(held.subgoal(behind, target, _oncoming_line(), None), behind)
    # ... and after reset (a new episode) it is measured from there again: backing away 2 m is within 2.5 m
    held2 = _search(retreat_m=2.5)
    held2.nearest_m = 1.0
    assert np.array_equal(held2.subgoal(behind, target, line, None), behind)
    held2.reset()
    assert held2.subgoal(behind, target, line, None)[0] < behind[0]


def test_the_retreat_is_measured_from_the_episode_goal_not_the_waypoint() -> None:
    line = _oncoming_line()
    s = _search(retreat_m=0.5)
    waypoint, goal = np.array([10.0, 0.0]), np.array([-20.0, 0.0])  # the goal lies behind: backing away is progress
    assert s.subgoal(np.zeros(2), waypoint, line, None, goal=goal)[0] < -1.0


@pytest.mark.parametrize("field,value", [("horizon_s", 0.0), ("step_s", -1.0), ("speed_fraction", 1.5),
                                         ("clearance_m", -0.1), ("cell_m", float("nan")), ("horizon_s", 0.2),
                                         ("retreat_m", -1.0), ("retreat_m", float("nan"))])
def test_config_rejects_bad_values(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        ForesightConfig(**{field: value})


def test_disc_cells_match_a_brute_force_check_on_and_off_the_grid() -> None:
    from planner.foresight import disc_cells

    rng = np.random.default_rng(3)
    origin, h, shape = np.array([-2.0, 1.0]), 0.15, (30, 20)
    centres = rng.uniform([-6.0, -3.0], [6.0, 8.0], size=(4, 9, 2))  # (T, S, 2), some far off the grid
    clear = rng.uniform(0.3, 1.0, size=(4, 9))
    got = disc_cells(origin, h, shape, centres, clear)
    xy = origin + h * np.stack(np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij"), axis=-1)
    d = np.linalg.norm(xy[None, None] - centres[:, :, None, None], axis=-1)  # (T, S, G0, G1)
    assert np.array_equal(got, np.any(d < clear[:, :, None, None], axis=1))
    assert got.any() and not got.all()
