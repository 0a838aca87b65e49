"""CrowdNav++'s livelier ORCA humans (`envs.crowds.orca`: random radii and speeds, goal changes, new humans on
arrival) and the robot's sensor range (`ObservationConfig.sensor_gap_m`), as suite crowdnav-plusplus v2 uses them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.config import ObservationConfig
from envs.crowds.crowd import rows_of
from envs.crowds.orca import RADIUS_RANGE_M, V_PREF_RANGE_MPS, OrcaCrowd, OrcaCrowdConfig
from envs.evaluation.suite import load_suite
from envs.policies import decide, make_policy
from planner import RobotConfig

HOLONOMIC = RobotConfig(model="holonomic", radius_m=0.3, max_speed_mps=1.0, max_accel_mps2=1000.0)
LIVELY = OrcaCrowdConfig(safety_space_m=0.15, spawn_gap_m=0.25, robot_route="random", route_min_m=8.0,
                         route_half_width_m=6.0, start_noise="positive", randomize_attributes=True,
                         goal_change_period_s=5.0, goal_change_chance=0.5, respawn_on_arrival=True)


def plusplus(**kw) -> CrowdNavConfig:
    base = dict(scenario="circle_crossing", crowd_model="orca", n_pedestrians=20, robot_visible=False,
                scenario_options=(("radius_m", 6 * np.sqrt(2)),), dt_s=0.05, warmup_s=0.0, time_limit_s=50.0,
                robot=HOLONOMIC, orca=LIVELY)
    return CrowdNavConfig(**{**base, **kw})


def walk(crowd: OrcaCrowd, steps: int) -> list:
    return [crowd.step() for _ in range(steps)]


def test_random_attributes_lie_in_crowdnav_plusplus_ranges_and_nobody_walks_faster_than_their_own_v_pref():
    crowd = OrcaCrowd(plusplus())
    crowd.reset(3)
    r, v = crowd.radius.copy(), crowd.v_pref.copy()
    assert np.all((r >= RADIUS_RANGE_M[0]) & (r <= RADIUS_RANGE_M[1])) and np.ptp(r) > 0.05
    assert np.all((v >= V_PREF_RANGE_MPS[0]) & (v <= V_PREF_RANGE_MPS[1])) and np.ptp(v) > 0.3
    for state in walk(crowd, 80):  # 4 s: before the first goal change and (at these distances) any arrival
        assert np.all(np.linalg.norm(state.vel, axis=1) <= crowd.v_pref + 1e-6)
        np.testing.assert_array_equal(state.radius, r)


def test_starts_are_on_the_circle_shifted_by_0_to_2_m_and_goals_opposite_clear_of_the_route_and_each_other():
    crowd = OrcaCrowd(plusplus())
    for seed in range(10):
        s = crowd.reset(seed)
        np.testing.assert_allclose(s.goal, -s.pos)
        rim = 6 * np.sqrt(2)
        for p in s.pos:  # p - (0..2, 0..2) lies on the circle for some shift
            shift = np.random.default_rng(0).uniform(0, 2, (20000, 2))
            assert np.min(np.abs(np.linalg.norm(p - shift, axis=1) - rim)) < 0.05
        start, goal = crowd.route
        assert np.all(np.abs([*start, *goal]) <= 6.0) and np.linalg.norm(goal - start) >= 8.0
        pts = np.vstack([start, goal, s.pos])
        rad = np.concatenate([[0.3, 0.3], s.radius])
        for i in range(2, len(pts)):
            d = np.linalg.norm(pts[:i] - pts[i], axis=1)
            assert np.all(d >= rad[:i] + rad[i] + 0.25 - 1e-9)


def test_goals_change_only_every_5_s_and_each_with_chance_one_half():
    crowd = OrcaCrowd(plusplus(orca=replace(LIVELY, respawn_on_arrival=False)))
    changed = []
    for seed in range(6):
        crowd.reset(seed)
        goals = crowd.goal.copy()
        for tick in range(1, 401):  # 20 s at 0.05 s
            crowd.step()
            moved = np.any(crowd.goal != goals, axis=1)
            if tick % 100:
                assert not moved.any(), f"a goal changed at {tick * 0.05:.2f} s"
            else:
                changed.append(moved.mean())
            goals = crowd.goal.copy()
    assert 0.35 < np.mean(changed) < 0.65  # 24 draws of 20 humans


def test_a_human_who_arrives_is_replaced_by_a_new_one_with_a_new_id():
    crowd = OrcaCrowd(plusplus(orca=replace(LIVELY, goal_change_period_s=0.0)))
    crowd.reset(1)
    seen, ids = set(crowd.ped_id.tolist()), crowd.ped_id.copy()
    new = 0
    for _ in range(1000):  # 50 s: every human has crossed the circle
        before_goal, before_id = crowd.goal.copy(), crowd.ped_id.copy()
        s = crowd.step()
        for i in np.flatnonzero(s.ped_id != before_id):
            assert s.ped_id[i] not in seen  # ids are never reused
            np.testing.assert_allclose(s.goal[i], -s.pos[i])  # a new crossing
            assert np.linalg.norm(before_goal[i] - s.pos[i]) > 1.0  # not where the old one arrived
            seen.add(int(s.ped_id[i]))
            new += 1
        ids = s.ped_id
    assert new >= 15 and len(set(ids.tolist())) == 20


def test_the_crowd_is_the_same_whatever_the_invisible_robot_does():
    env = CrowdNavEnv(plusplus())
    tracks = []
    for policy in ("orca", "social-force"):
        pol = make_policy(policy, env)
        env.reset(seed=11)
        pol.reset(11)
        states = []
        for _ in range(300):  # 15 s: goal changes and arrivals included
            _, _, term, trunc, _ = env.step_decision(decide(pol, env))
            states.append((env._state.ped_id.copy(), env._state.pos.copy()))
            if term or trunc:
                break
        tracks.append(states)
    n = min(len(t) for t in tracks)
    assert n > 100
    for (ia, pa), (ib, pb) in zip(tracks[0][:n], tracks[1][:n], strict=True):
        np.testing.assert_array_equal(ia, ib)
        np.testing.assert_array_equal(pa, pb)


def test_the_oracle_future_is_what_happens_across_goal_changes_and_arrivals_and_asking_changes_nothing():
    crowd = OrcaCrowd(plusplus())
    crowd.reset(4)
    walk(crowd, 93)  # the look-ahead spans the goal change at 5 s
    twin = OrcaCrowd(plusplus())
    twin.reset(4)
    walk(twin, 93)
    ids = crowd.ped_id.copy()
    times = 0.4 * np.arange(1, 13)
    future = crowd.future(ids, times)
    happened = [rows_of(s, ids) for s in walk(crowd, 96)][7::8]
    np.testing.assert_array_equal(future, np.array(happened))
    for a, b in zip(walk(crowd, 200), walk(twin, 296)[96:], strict=True):  # asking did not move the crowd's dice
        np.testing.assert_array_equal(a.pos, b.pos)


def test_the_sensor_hides_everyone_beyond_5_m_of_surface_gap_from_every_policy_input():
    env = CrowdNavEnv(plusplus(observation=ObservationConfig(sensor_gap_m=5.0)))
    env.reset(seed=2)
    for _ in range(60):
        env.step_control(np.zeros(2))
    every = env.pedestrians()
    gap = np.linalg.norm(every.pos - env.robot_state[:2], axis=1) - every.radius - 0.3
    assert (gap > 5.0).any() and (gap <= 5.0).any()
    view = env.view(future=True)
    np.testing.assert_array_equal(np.sort(view.pedestrians.ped_id), np.sort(every.ped_id[gap <= 5.0]))
    assert view.history.shape[1] == view.future.shape[1] == len(view.pedestrians.pos)
    np.testing.assert_allclose(view.history[-1], view.pedestrians.pos)
    obs = env._observe()
    assert int(obs["pedestrian_mask"].sum()) == int((gap <= 5.0).sum())


@pytest.mark.parametrize("bad", [dict(start_noise="uniform"), dict(goal_change_chance=1.5),
                                 dict(goal_change_period_s=-1.0), dict(route_half_width_m=float("nan")),
                                 dict(respawn_on_arrival="yes")])
def test_bad_lively_settings_raise_naming_the_field(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        OrcaCrowdConfig(**bad)


@pytest.mark.parametrize("gap", [0.0, -1.0, float("nan")])
def test_a_sensor_gap_that_is_not_positive_is_refused(gap: float) -> None:
    with pytest.raises(ValueError, match="sensor_gap_m"):
        ObservationConfig(sensor_gap_m=gap)


def test_suite_plusplus_v2_holds_crowdnav_plusplus_settings():
    cell = load_suite("crowdnav-plusplus").cells[0]
    cfg = cell.env_config(cell.seeds[0])
    assert cfg.orca == LIVELY and cfg.observation.sensor_gap_m == 5.0
    assert (cfg.n_pedestrians, cfg.time_limit_s, cfg.robot, len(cell.seeds)) == (20, 50.0, HOLONOMIC, 500)


def test_a_suite_cell_names_the_sensor_through_observation_fields_and_bad_ones_are_refused():
    from envs.evaluation.suite import parse_suite

    cell = {"name": "x", "scenario": "circle_crossing", "crowd_model": "orca", "n_pedestrians": 5,
            "robot_visible": False, "episodes": 1, "seed0": 0}

    def suite(observation: dict, base: dict = cell):
        return parse_suite({"name": "s", "version": 1, "defaults": {"dt_s": 0.05},
                            "cells": [{**base, "observation": observation}]})

    assert suite({"sensor_gap_m": 5.0}).cells[0].env_config(0).observation.sensor_gap_m == 5.0
    with pytest.raises(ValueError, match=r"unknown: \['sensor_m'\]; valid: .*sensor_gap_m"):
        suite({"sensor_m": 5.0})
    with pytest.raises(ValueError, match="sensor_gap_m"):
        suite({"sensor_gap_m": -1})
    replay = {"name": "r", "replay": ["zara1/test/crowds_zara01.txt"], "frame_step_s": 0.4, "episodes": 1, "seed0": 0}
    with pytest.raises(ValueError, match="a replay cell takes no"):
        suite({"sensor_gap_m": 5.0}, replay)
