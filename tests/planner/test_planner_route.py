"""The global route (planner/route.py) and the wall margin: a goal behind a wall is reached through its door."""

from __future__ import annotations

import numpy as np
import pytest
from planner_helpers import drive, make_config

from planner import MPCConfig, MPCPlanner, RouteConfig, Router, grid_route, point_segment_distances
from planner.route import in_sight

# A room 8 x 8 m with a 1 m door in its east wall at y in [3.5, 4.5], opening into a 2 m corridor (crowdsim's
# bottleneck scenario, written out here: the planner does not import crowdsim).
DOOR_WALLS = np.array([
    [0.0, 0.0, 8.0, 0.0], [0.0, 8.0, 8.0, 8.0], [0.0, 0.0, 0.0, 8.0],
    [8.0, 0.0, 8.0, 3.5], [8.0, 4.5, 8.0, 8.0],
    [8.0, 3.5, 10.0, 3.5], [8.0, 4.5, 10.0, 4.5],
])
IN_ROOM, OUTSIDE = np.array([5.6, 1.5]), np.array([11.0, 1.0])  # straight on: the wall, 2 m from the door
CLEAR_M = 0.35


def test_the_route_goes_through_the_door_and_keeps_the_clearance():
    path = grid_route(IN_ROOM, OUTSIDE, DOOR_WALLS, RouteConfig(), CLEAR_M)
    assert path is not None
    np.testing.assert_array_equal(path[0], IN_ROOM)
    np.testing.assert_array_equal(path[-1], OUTSIDE)
    inner = path[1:-1]
    assert point_segment_distances(inner, DOOR_WALLS).min() >= CLEAR_M
    in_door = inner[(inner[:, 0] > 8.0) & (inner[:, 0] < 10.0)]
    assert len(in_door) > 0 and np.all(np.abs(in_door[:, 1] - 4.0) < 0.15)  # the middle of the 1 m corridor
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert steps.max() <= np.hypot(0.1, 0.1) + 0.1  # a connected chain of cells (ends join their cells)


def test_no_route_when_the_door_is_too_narrow_for_the_robot():
    assert grid_route(IN_ROOM, OUTSIDE, DOOR_WALLS, RouteConfig(), clearance_m=0.55) is None
    router = Router(RouteConfig(), clearance_m=0.55)
    np.testing.assert_array_equal(router.subgoal(IN_ROOM, OUTSIDE, DOOR_WALLS), OUTSIDE)  # falls back to the goal


def test_a_failed_search_is_repeated_only_once_the_robot_has_moved(monkeypatch):
    import planner.route as route

    calls = []
    real = route.grid_route
    monkeypatch.setattr(route, "grid_route", lambda *a, **k: calls.append(1) or real(*a, **k))
    router = Router(RouteConfig(replan_distance_m=1.0), clearance_m=0.55)
    for dx in (0.0, 0.2, 0.5, 0.9):  # within 1 m of where no route was found: the goal, no new search
        np.testing.assert_array_equal(router.subgoal(IN_ROOM + np.array([dx, 0.0]), OUTSIDE, DOOR_WALLS), OUTSIDE)
    assert len(calls) == 1
    router.subgoal(IN_ROOM + np.array([0.0, 1.5]), OUTSIDE, DOOR_WALLS)  # moved on: search again
    assert len(calls) == 2
    router.subgoal(IN_ROOM + np.array([0.0, 1.5]), np.array([11.0, 2.0]), DOOR_WALLS)  # a new goal: search again
    assert len(calls) == 3


def test_a_goal_in_sight_is_the_subgoal_itself():
    router = Router(RouteConfig(), CLEAR_M)
    goal = np.array([2.0, 6.0])
    assert router.subgoal(IN_ROOM, goal, DOOR_WALLS) is not None
    np.testing.assert_array_equal(router.subgoal(IN_ROOM, goal, DOOR_WALLS), goal)
    np.testing.assert_array_equal(router.subgoal(IN_ROOM, OUTSIDE, None), OUTSIDE)


def test_the_subgoal_behind_a_wall_is_in_sight_and_on_the_way():
    router = Router(RouteConfig(lookahead_m=2.0), CLEAR_M)
    sub = router.subgoal(IN_ROOM, OUTSIDE, DOOR_WALLS)
    assert not in_sight(IN_ROOM, OUTSIDE[None], DOOR_WALLS, CLEAR_M, 0.05)[0]
    assert np.linalg.norm(sub - IN_ROOM) == pytest.approx(2.0, abs=0.15)
    door = np.array([8.0, 4.0])
    assert np.linalg.norm(sub - door) < np.linalg.norm(IN_ROOM - door) - 1.5  # it leads towards the door


def test_route_config_and_wall_margin_are_validated():
    with pytest.raises(ValueError, match="cell_m"):
        RouteConfig(cell_m=0.0)
    with pytest.raises(ValueError, match="clearance_weight"):
        RouteConfig(clearance_weight=-1.0)
    with pytest.raises(ValueError, match="wall_margin_m"):
        MPCConfig(wall_margin_m=-0.1)
    with pytest.raises(ValueError, match="max_cells"):
        grid_route(IN_ROOM, OUTSIDE, DOOR_WALLS, RouteConfig(cell_m=0.01, max_cells=1000), CLEAR_M)
    assert MPCConfig(safety_margin_m=0.3).wall_clearance_m == pytest.approx(0.6)  # None: the pedestrians' margin
    assert MPCConfig(safety_margin_m=0.3, wall_margin_m=0.05).wall_clearance_m == pytest.approx(0.35)


def _through_the_door(**kwargs):
    planner = MPCPlanner(make_config(safety_margin_m=0.3, **kwargs))
    start = np.array([*IN_ROOM, 0.0, 0.0, 0.0])
    return drive(planner, start, OUTSIDE, lambda step, state: None, steps=50, obstacles=DOOR_WALLS)


@pytest.mark.slow
def test_with_a_route_and_a_wall_margin_the_mpc_goes_through_the_door():
    states, results = _through_the_door(wall_margin_m=0.05, route=RouteConfig())
    reached = np.linalg.norm(states[:, :2] - OUTSIDE, axis=1) < 0.3
    assert reached.any()
    assert point_segment_distances(states[:, :2], DOOR_WALLS).min() >= 0.3 - 1e-6  # never touched a wall
    assert any(not np.array_equal(r.subgoal, OUTSIDE) for r in results)  # the route steered it


@pytest.mark.slow
def test_without_them_the_mpc_does_not_find_the_door():
    """The failure the route fixes (every MPC timed out in crowdnav-v1 v5's door cells): heading straight for the
    goal, the MPC either stays in the room or, its wall constraints being soft, pushes through the wall."""
    for kwargs in ({}, {"wall_margin_m": 0.05}):
        states, _ = _through_the_door(**kwargs)
        through_door = (states[:, 0] > 8.0) & (np.abs(states[:, 1] - 4.0) < 0.5)
        assert not through_door.any(), kwargs


def test_the_cached_grid_gives_the_same_paths_as_a_fresh_search(monkeypatch):
    """A Router keeps the grid (GridCache): searches from many places, some outside the walls' box (a grown lattice),
    return exactly the paths a search without a cache returns, and the clearance field is computed once for them."""
    import planner.route as route

    fields = []
    real = route.wall_clearance
    monkeypatch.setattr(route, "wall_clearance", lambda p, w: (fields.append(np.shape(p)), real(p, w))[1])
    cache, cfg = route.GridCache(), RouteConfig()
    starts = [IN_ROOM, np.array([1.0, 7.0]), np.array([4.0, 4.0]), np.array([3.0, 8.6]), np.array([2.0, 9.0])]
    for start in starts:
        for goal in (OUTSIDE, np.array([9.5, 4.0])):
            cached = grid_route(start, goal, DOOR_WALLS, cfg, CLEAR_M, cache)
            fields_before = len(fields)
            fresh = grid_route(start, goal, DOOR_WALLS, cfg, CLEAR_M)
            assert len(fields) == fields_before + 1  # no cache: its own field
            np.testing.assert_array_equal(cached, fresh)
    grids = [s for s in fields if len(s) == 3]  # the (nx, ny, 2) fields, not the in-sight checks
    assert len(grids) == 1 + len(starts) * 2  # the cache's one field (grown once up front), plus each fresh search's


def test_a_cached_field_slice_equals_the_field_computed_at_its_own_size():
    import planner.route as route

    rng = np.random.default_rng(3)
    for _ in range(10):
        walls = rng.uniform(-8.0, 8.0, (int(rng.integers(1, 10)), 4))
        lo, cell = rng.uniform(-10.0, -9.0, 2), 0.1
        cache = route.GridCache()
        big = tuple(int(v) for v in rng.integers(60, 160, 2))
        cache.clearance(lo, big, walls, cell)
        small = tuple(int(v) - int(rng.integers(0, 50)) for v in big)
        np.testing.assert_array_equal(cache.clearance(lo, small, walls, cell),
                                      route.wall_clearance(route._centres(lo, small, cell), walls))
