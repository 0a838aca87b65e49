"""Reachable-set bounds: what any robot could do in an episode whose crowd ignores the robot."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.evaluation.reachability import Course, ReachConfig, course_of, reach
from planner import RobotConfig

DT = 0.1


def _course(goal: tuple[float, float], seconds: float, walls: list | None = None,
            peds: list[tuple[np.ndarray, np.ndarray]] | None = None) -> Course:
    """A hand-built course from (0, 0): peds is a list of (positions (T + 1, 2), radius) tracks."""
    n = int(round(seconds / DT))
    pos = [np.array([p[k] for p, _ in (peds or [])]).reshape(-1, 2) for k in range(n + 1)]
    rad = [np.array([r for _, r in (peds or [])], float) for _ in range(n + 1)]
    ids = [np.arange(len(peds or [])) for _ in range(n + 1)]
    fresh = [np.zeros(len(peds or []), bool) for _ in range(n + 1)]
    w = np.asarray(walls, float).reshape(-1, 2, 2) if walls else np.zeros((0, 2, 2))
    return Course(np.zeros(2), np.asarray(goal, float), 0.3, 0.3, 1.2, DT, n, w, pos, rad, ids, fresh)


def test_open_ground_bounds_bracket_the_straight_run() -> None:
    r = reach(_course((10.0, 0.0), 20.0))
    straight = (10.0 - 0.3) / 1.2  # 8.08 s at full speed
    assert r.verdict == "feasible"
    assert r.earliest_arrival_s <= straight <= r.witness_arrival_s <= straight + 1.0


def test_a_goal_beyond_the_speed_limit_is_infeasible() -> None:
    # 29.7 m to go in 20 s needs 1.49 m/s: out of reach even for the optimistic set's slack
    assert reach(_course((30.0, 0.0), 20.0)).verdict == "infeasible"


def _box(gap_m: float) -> list:
    """A closed square room around the goal (4, 0), its left wall with a centred gap of gap_m."""
    x0, x1, y0, y1, g = 2.0, 6.0, -2.0, 2.0, gap_m / 2
    return [[(x0, y0), (x1, y0)], [(x1, y0), (x1, y1)], [(x1, y1), (x0, y1)],
            [(x0, y1), (x0, g)], [(x0, -g), (x0, y0)]]


@pytest.mark.parametrize(("gap", "verdict"), [(0.0, "infeasible"), (0.5, "infeasible"), (1.0, "feasible")])
def test_a_door_narrower_than_the_robot_cannot_be_passed(gap: float, verdict: str) -> None:
    assert reach(_course((4.0, 0.0), 20.0, walls=_box(gap))).verdict == verdict  # robot diameter 0.6 m


def test_a_person_standing_on_the_goal_delays_every_robot() -> None:
    n = int(20.0 / DT)
    track = np.tile([3.0, 0.0], (n + 1, 1))
    k0 = int(8.0 / DT)
    track[k0:, 1] = 1.5 * DT * np.arange(n + 1 - k0)  # walks away at 1.5 m/s from 8 s: clear 0.6 m later
    r = reach(_course((3.0, 0.0), 20.0, peds=[(track, 0.3)]))
    assert r.verdict == "feasible"
    assert 7.9 <= r.earliest_arrival_s <= r.witness_arrival_s <= 9.0
    stays = np.tile([3.0, 0.0], (n + 1, 1))
    assert reach(_course((3.0, 0.0), 20.0, peds=[(stays, 0.3)])).verdict == "infeasible"


@pytest.mark.slow
def test_optimistic_never_later_than_the_witness_on_random_crowds() -> None:
    rng = np.random.default_rng(3)
    n = int(15.0 / DT)
    for _ in range(3):
        peds = []
        for _ in range(12):
            p0, v = rng.uniform([1, -3], [9, 3]), rng.normal(0, 0.4, 2)
            peds.append((p0 + np.arange(n + 1)[:, None] * DT * v, 0.3))
        r = reach(_course((10.0, 0.0), 15.0, peds=peds))
        if r.witness_arrival_s is not None:
            assert r.earliest_arrival_s <= r.witness_arrival_s
        assert (r.verdict == "infeasible") == (r.earliest_arrival_s is None)


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match="cells_per_step"):
        ReachConfig(cells_per_step=1)
    with pytest.raises(ValueError, match="whole multiple"):
        reach(_course((3.0, 0.0), 5.0), ReachConfig(optimistic_dt_s=0.25))


def test_a_visible_robot_has_no_fixed_course() -> None:
    with pytest.raises(ValueError, match="ignores the robot"):
        course_of(CrowdNavConfig(scenario="corridor", n_pedestrians=10, robot_visible=True), 0)


@pytest.mark.slow
def test_the_witness_path_driven_in_the_env_succeeds_without_contact() -> None:
    """The conservative verdict is a claim about the env: its path, driven there by a holonomic robot, must reach the
    goal with no contact, and the crowd the env shows on the way must be the course's crowd."""
    robot = RobotConfig(model="holonomic", max_accel_mps2=1000.0)
    cfg = CrowdNavConfig(scenario="corridor", n_pedestrians=40, robot_visible=False, robot=robot, time_limit_s=30.0)
    seed = 2
    course = course_of(cfg, seed)
    r = reach(course, witness_path=True)
    assert r.verdict == "feasible" and r.path is not None
    env = CrowdNavEnv(cfg)
    env.reset(seed=seed)
    np.testing.assert_array_equal(env.robot_state[:2], r.path[0])
    done, info, k = False, {}, 0
    while not done:
        k += 1
        _, _, terminated, truncated, info = env.step_control((r.path[k] - env.robot_state[:2]) / DT)
        np.testing.assert_allclose(env.pedestrians().pos, course.ped_pos[k], atol=1e-12)
        done = terminated or truncated
    m = info["episode_metrics"]
    assert m["success"] and not m["collision"]
    assert k * DT == pytest.approx(r.witness_arrival_s)


@pytest.mark.slow
def test_the_benchmark_robot_wins_a_dense_corridor_by_tracking_a_roomy_witness() -> None:
    """The unicycle (acceleration and turn-rate limits) tracking a slower, roomier witness wins a 40-person corridor
    (a seed where the first roomy path is tracked home); the tracker refuses a path not from the episode's start."""
    from envs.evaluation.reachability import roomy_path
    from envs.evaluation.witness import track

    cfg = CrowdNavConfig(scenario="corridor", n_pedestrians=40, robot_visible=False, time_limit_s=30.0)
    path = roomy_path(course_of(cfg, 3))
    assert path is not None and cfg.robot.model == "unicycle"
    assert track(cfg, 3, path) == "success"
    with pytest.raises(ValueError, match="start"):
        track(cfg, 3, path + 1.0)


def test_the_default_check_period_follows_the_env_step() -> None:
    assert ReachConfig().resolved(0.1).optimistic_dt_s == pytest.approx(0.2)
    assert ReachConfig().resolved(0.25).optimistic_dt_s == pytest.approx(0.25)  # CrowdNav's step
    with pytest.raises(ValueError, match="whole multiple"):
        ReachConfig(optimistic_dt_s=0.3).resolved(0.25)


@pytest.mark.slow
def test_a_fine_env_step_is_strided_and_the_witness_still_holds_in_the_env() -> None:
    """CrowdNav++'s 0.05 s step: the conservative set steps 0.1 s at a time; its path, one point per env step, driven
    in the env by the holonomic robot of that setting, reaches the goal without contact."""
    from envs.evaluation.reachability import stride_of
    from envs.evaluation.suite import load_suite

    assert stride_of(0.05) == 2 and stride_of(0.1) == 1 and stride_of(0.25) == 1
    cell = load_suite("crowdnav-plusplus").cells[0]
    cfg = replace(cell.env_config(0), time_limit_s=25.0)
    course = course_of(cfg, 0)
    r = reach(course, witness_path=True)
    assert cfg.dt_s == 0.05 and r.verdict == "feasible" and len(r.path) == round(r.witness_arrival_s / 0.05) + 1
    assert np.max(np.hypot(*np.diff(r.path, axis=0).T)) <= cfg.robot.max_speed_mps * 0.05 + 1e-9
    env = CrowdNavEnv(cfg)
    env.reset(seed=0)
    done, info, k = False, {}, 0
    while not done:
        k += 1
        _, _, terminated, truncated, info = env.step_control((r.path[k] - env.robot_state[:2]) / cfg.dt_s)
        done = terminated or truncated
    assert info["episode_metrics"]["success"] and not info["episode_metrics"]["collision"]


def test_trace_back_walks_one_path_back_through_the_sets() -> None:
    """`trace_back` (planner/foresight.py, which the bounds use): from a cell of the last set, the nearest cell of
    each set before it within `pad` cells, in forward order."""
    from envs.evaluation.reachability import trace_back

    sets = [np.zeros((5, 5), bool) for _ in range(3)]
    sets[0][0, 0] = True
    sets[1][1, 0] = sets[1][1, 2] = True
    sets[2][2, 2] = sets[2][2, 0] = True
    assert trace_back(sets, (2, 2), 2) == [(0, 0), (1, 2), (2, 2)]
    assert trace_back(sets, (2, 0), 2) == [(0, 0), (1, 0), (2, 0)]  # the nearest cell of each set
    assert trace_back(sets[:1], (0, 0), 1) == [(0, 0)]
