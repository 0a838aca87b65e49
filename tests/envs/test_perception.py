"""The limited view (`ObservationConfig.fov_deg`, `occlusion`; `envs.perception`): who is hidden, from which policy
input, and that the metrics still count everybody and the defaults change nothing."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.config import ObservationConfig
from envs.crowds.replay import ReplayConfig
from envs.perception import in_field_of_view, perceived, sight_points, unoccluded
from planner import RobotConfig

ORIGIN = np.zeros(2)
NO_WALLS = np.zeros((0, 4))


# ------------------------------------------------------------------------------------------------ the geometry
def test_a_disc_counts_in_view_when_any_part_of_it_is_inside_the_field_of_view():
    pos = np.array([[3.0, 0.0], [-3.0, 0.0], [0.0, 3.0], [0.3, -3.0], [-0.1, 0.2]])
    radius = np.full(5, 0.25)
    # ahead, behind, exactly abeam (half of it in view), just behind abeam but its edge in view, covering the robot
    np.testing.assert_array_equal(in_field_of_view(ORIGIN, 0.0, 180.0, pos, radius), [1, 0, 1, 1, 1])
    np.testing.assert_array_equal(in_field_of_view(ORIGIN, 0.0, 360.0, pos, radius), [1, 1, 1, 1, 1])
    np.testing.assert_array_equal(in_field_of_view(ORIGIN, math.pi, 90.0, pos, radius), [0, 1, 0, 0, 1])
    # the edge of a disc 1 m off the axis of a 20-degree view: in view up to 10 deg + asin(r / d)
    d = np.hypot(5.0, 1.0)
    edge = math.degrees(math.atan2(1.0, 5.0) - math.asin(0.25 / d))
    assert edge < 10.0 < math.degrees(math.atan2(1.0, 5.0))
    assert in_field_of_view(ORIGIN, 0.0, 2 * edge + 0.01, np.array([[5.0, 1.0]]), np.array([0.25]))[0]
    assert not in_field_of_view(ORIGIN, 0.0, 2 * edge - 0.01, np.array([[5.0, 1.0]]), np.array([0.25]))[0]


def test_the_three_sight_lines_end_at_the_centre_and_the_tangent_points():
    pos, radius = np.array([[4.0, 3.0]]), np.array([0.5])
    ends = sight_points(ORIGIN, pos, radius)[0]
    np.testing.assert_allclose(ends[0], pos[0])
    for tangent in ends[1:]:
        assert np.linalg.norm(tangent - pos[0]) == pytest.approx(0.5)  # on the disc
        assert np.dot(tangent, tangent - pos[0]) == pytest.approx(0.0, abs=1e-12)  # the line grazes it


def test_a_wall_and_a_nearer_person_block_the_line_of_sight():
    wall = np.array([[2.0, -1.0, 2.0, 1.0]])
    pos, radius = np.array([[4.0, 0.0], [4.0, 3.0]]), np.array([0.25, 0.25])
    np.testing.assert_array_equal(unoccluded(ORIGIN, pos, radius, wall), [False, True])
    np.testing.assert_array_equal(unoccluded(ORIGIN, pos, radius, NO_WALLS), [True, True])
    # a person hides the one collinear behind them, not the other way round; stepping aside shows them again
    for y, seen in ((0.0, False), (0.2, False), (0.6, True)):
        pair = np.array([[2.0, 0.0], [4.0, y]])
        np.testing.assert_array_equal(unoccluded(ORIGIN, pair, radius, NO_WALLS), [True, seen])
    # one edge in sight is enough: the centre line blocked, a tangent line clear
    pair, radii = np.array([[2.0, 0.0], [4.0, 0.45]]), np.array([0.3, 0.3])
    assert 2.0 * 0.45 / np.hypot(4.0, 0.45) < 0.3  # the centre line passes through the nearer disc
    np.testing.assert_array_equal(unoccluded(ORIGIN, pair, radii, NO_WALLS), [True, True])


def test_perceived_needs_both_the_view_and_the_line_of_sight():
    pos, radius = np.array([[2.0, 0.0], [4.0, 0.0], [-3.0, 0.0]]), np.full(3, 0.25)
    np.testing.assert_array_equal(perceived(ORIGIN, 0.0, pos, radius, NO_WALLS), [1, 1, 1])
    np.testing.assert_array_equal(perceived(ORIGIN, 0.0, pos, radius, NO_WALLS, 180.0), [1, 1, 0])
    np.testing.assert_array_equal(perceived(ORIGIN, 0.0, pos, radius, NO_WALLS, occlusion=True), [1, 0, 1])
    np.testing.assert_array_equal(perceived(ORIGIN, 0.0, pos, radius, NO_WALLS, 180.0, True), [1, 0, 0])


# ------------------------------------------------------------------------------------------------- in the env
def _replay(tmp_path: Path, tracks: dict[int, list[tuple[int, float, float]]], walls=(), **obs) -> CrowdNavEnv:
    """An env replaying (frame, x, y) knots per pedestrian (0.4 s a frame, radius 0.25 m; the episode starts at frame
    8 after the 3.2 s warmup), the unicycle robot at (0, 0) heading for (10, 0) (+x)."""
    rows = sorted((10 * t, pid, x, y) for pid, knots in tracks.items() for t, x, y in knots)
    path = tmp_path / "tracks.txt"
    path.write_text("\n".join(f"{f}\t{p}\t{x}\t{y}" for f, p, x, y in rows) + "\n")
    replay = ReplayConfig(path=path, start_mode="fixed", walls=walls)
    env = CrowdNavEnv(CrowdNavConfig(scenario="replay", replay=replay, time_limit_s=10.0,
                                     observation=ObservationConfig(**obs)))
    env.crowd.robot_route = lambda rng: (np.array([0.0, 0.0]), np.array([10.0, 0.0]))
    env.reset(seed=0)
    return env


def _standing(x: float, y: float) -> list[tuple[int, float, float]]:
    return [(t, x, y) for t in range(40)]


def _inputs(env: CrowdNavEnv) -> tuple[set[int], int, int]:
    """Who the policy inputs hold now: the view's ids, the observation's rows, the history's pedestrians."""
    view = env.view(history=True, track=True)
    assert view.history.shape[1] == view.track.shape[1] == len(view.pedestrians.ped_id)
    return {int(i) for i in view.pedestrians.ped_id}, int(view.obs["pedestrian_mask"].sum()), view.history.shape[1]


def _still(env: CrowdNavEnv) -> dict:
    _, _, term, trunc, info = env.step_control(np.zeros(2))
    assert not (term or trunc)
    return info


def test_a_person_behind_a_wall_is_perceived_only_without_occlusion(tmp_path):
    tracks = {1: _standing(4.0, 0.0), 2: _standing(0.0, 4.0)}
    wall = [((2.0, -1.5), (2.0, 1.5))]
    hidden = _replay(tmp_path, tracks, wall, occlusion=True)
    seeing = _replay(tmp_path, tracks, wall)
    for _ in range(5):
        assert _inputs(hidden) == ({2}, 1, 1)
        assert _inputs(seeing) == ({1, 2}, 2, 2)
        assert hidden.history.times_seen(1) == 0 < seeing.history.times_seen(1)
        _still(hidden), _still(seeing)


def test_a_person_behind_the_robot_is_outside_a_180_degree_view_and_inside_360(tmp_path):
    tracks = {1: _standing(3.0, 0.0), 2: _standing(-3.0, 0.0)}
    assert _inputs(_replay(tmp_path, tracks, fov_deg=180.0))[0] == {1}
    assert _inputs(_replay(tmp_path, tracks, fov_deg=360.0))[0] == {1, 2}
    assert _inputs(_replay(tmp_path, tracks, fov_deg=90.0, occlusion=True))[0] == {1}


def test_a_person_hidden_behind_another_reappears_as_one_who_has_just_come_into_view(tmp_path):
    # 3 stands behind 1 (collinear, farther) until frame 14 (2.4 s into the episode), then walks +y at 1 m/s
    walker = [(t, 4.0, 0.0) for t in range(15)] + [(t, 4.0, 0.4 * (t - 14)) for t in range(15, 40)]
    tracks = {1: _standing(2.0, 0.0), 3: walker}
    env, seeing = _replay(tmp_path, tracks, occlusion=True), _replay(tmp_path, tracks)
    steps = 0
    while 3 not in _inputs(env)[0]:
        assert _inputs(env) == ({1}, 1, 1) and env.history.times_seen(3) == 0
        assert _inputs(seeing)[0] == {1, 3}
        _still(env), _still(seeing)
        steps += 1
    assert 24 <= steps <= 30  # out from behind 1 some 0.25 m after it set off
    for _ in range(6):  # 0.6 s after: its early velocity measured over its first 0.4 s in view
        _still(env), _still(seeing)
    rows = env.view().pedestrians.ped_id.tolist().index(3)
    window = env.view().history[:, rows]
    # back-filled as a newcomer: the whole window on its walking line at 1 m/s (0.4 m a row), although it stood
    # behind 1 before; the env that saw it all along has its standing past
    np.testing.assert_allclose(window[:, 0], 4.0, atol=1e-9)
    np.testing.assert_allclose(np.diff(window[:, 1]), 0.4, atol=0.02)
    assert env.history.times_seen(3) <= 2
    past = seeing.view().history[:, seeing.view().pedestrians.ped_id.tolist().index(3)]
    np.testing.assert_allclose(past[:3], [[4.0, 0.0]] * 3, atol=1e-9)
    track = env.view(track=True).track[:, rows]
    assert np.isnan(track[:-8]).all() and np.isfinite(track[-8:]).all()  # no recorded past before it came back


def test_a_person_nobody_sees_coming_is_absent_from_every_input_yet_the_collision_counts(tmp_path):
    # 1 walks up behind the robot at 1 m/s; the robot faces +x with a 90-degree view and waits
    tracks = {1: [(t, -6.0 + 0.4 * t, 0.0) for t in range(40)], 2: _standing(5.0, 2.0)}
    env = _replay(tmp_path, tracks, fov_deg=90.0, occlusion=True)
    for _ in range(100):
        assert _inputs(env) == ({2}, 1, 1) and env.history.times_seen(1) == 0
        assert 1 in env.pedestrians().ped_id  # in the scene all along
        _, _, term, _, info = env.step_control(np.zeros(2))
        if term:
            break
    m = info["episode_metrics"]
    assert m["collision"] and m["collision_with"] == "pedestrian" and m["at_fault"] == "pedestrian"


def test_the_metrics_and_rewards_count_everybody_whatever_the_view():
    """The same actions in the same crowd: the observations differ, the rewards and the metrics do not."""
    runs = []
    for obs in (ObservationConfig(), ObservationConfig(fov_deg=120.0, occlusion=True)):
        env = CrowdNavEnv(CrowdNavConfig(scenario="corridor", time_limit_s=8.0, observation=obs))
        o, _ = env.reset(seed=4)
        rng, masks, rewards, done = np.random.default_rng(4), [], [], False
        while not done:
            masks.append(int(o["pedestrian_mask"].sum()))
            o, r, term, trunc, info = env.step(rng.uniform(-0.2, 1.0, 2).astype(np.float32))
            rewards.append(r)
            done = term or trunc
        runs.append((masks, rewards, info["episode_metrics"]))
    (all_masks, *full), (some_masks, *limited) = runs
    assert sum(some_masks) < sum(all_masks)
    assert full == limited


def test_the_oracle_future_covers_whom_it_perceives_only(tmp_path):
    tracks = {1: _standing(2.0, 0.0), 3: _standing(4.0, 0.0), 4: _standing(0.0, 3.0)}
    view = _replay(tmp_path, tracks, occlusion=True).view(future=True)
    assert sorted(view.pedestrians.ped_id.tolist()) == [1, 4] and view.future.shape[1] == 2


def test_a_holonomic_sensor_faces_its_motion_and_keeps_its_heading_while_it_stands():
    env = CrowdNavEnv(CrowdNavConfig(scenario="circle_crossing", robot=RobotConfig(model="holonomic"),
                                     observation=ObservationConfig(fov_deg=90.0)))
    env.reset(seed=1)
    to_goal = env.goal - env.robot_state[:2]
    assert env.sensor_heading() == pytest.approx(math.atan2(to_goal[1], to_goal[0]))
    env.step_control(np.array([0.0, -0.5]))
    assert env.sensor_heading() == pytest.approx(-math.pi / 2)
    env.step_control(np.zeros(2))
    assert env.sensor_heading() == pytest.approx(-math.pi / 2)


def test_predicted_observations_cover_the_perceived_people_only():
    cfg = CrowdNavConfig(observation=ObservationConfig(predictions=True, group_source="predicted", fov_deg=120.0,
                                                       occlusion=True))
    env = CrowdNavEnv(cfg)
    obs, _ = env.reset(seed=2)
    n = int(obs["pedestrian_mask"].sum())
    assert 0 < n < len(env.pedestrians().pos)
    assert env._pred_samples.shape[2] == len(env._pred_ids) == len(env.view().pedestrians.pos)
    assert np.abs(obs["predictions"][:, :, :n]).sum() > 0 and not obs["predictions"][:, :, n:].any()


# ------------------------------------------------------------------------------------------- defaults, config
def test_by_default_nobody_is_hidden_and_the_perception_code_never_runs(monkeypatch):
    """Defaults (360 degrees, no occlusion): the mask is None as before, so the observations are the old ones (also
    checked once by hashing observations and views over episodes before and after the change)."""
    monkeypatch.setattr("envs.perception.perceived", lambda *a, **k: pytest.fail("perception ran under the defaults"))
    env = CrowdNavEnv(CrowdNavConfig(scenario="corridor"))
    assert not env.config.observation.limited_view
    env.reset(seed=0)
    for _ in range(12):
        assert env._sensor_mask(env.pedestrians()) is None
        v = env.view()
        np.testing.assert_array_equal(v.pedestrians.ped_id, env.pedestrians().ped_id)
        env.step(np.array([1.0, 0.0], np.float32))


def test_a_limited_view_that_hides_nobody_changes_no_observation():
    """The limited view's own bookkeeping (its history, forgetting) with a field of view that hides nobody gives
    the default env's observations and views."""
    envs = [CrowdNavEnv(CrowdNavConfig(scenario="corridor", observation=ObservationConfig(fov_deg=fov)))
            for fov in (360.0, 359.999)]
    outs = [env.reset(seed=5)[0] for env in envs]
    rng, done, steps = np.random.default_rng(5), False, 0
    while not done:
        a, b = outs
        assert all(np.array_equal(a[k], b[k]) for k in a)
        va, vb = (env.view(track=True) for env in envs)
        np.testing.assert_array_equal(va.history, vb.history)
        np.testing.assert_array_equal(va.track, vb.track)
        action = rng.uniform(-0.2, 1.0, 2).astype(np.float32)
        results = [env.step(action) for env in envs]
        outs, done, steps = [r[0] for r in results], results[0][2] or results[0][3], steps + 1
    assert steps > 20


@pytest.mark.parametrize("bad", [dict(fov_deg=0.0), dict(fov_deg=-10.0), dict(fov_deg=361.0),
                                 dict(fov_deg=float("nan")), dict(fov_deg=True), dict(fov_deg="90"),
                                 dict(occlusion="yes"), dict(occlusion=1)])
def test_bad_view_settings_are_refused_naming_the_field(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        ObservationConfig(**bad)


def test_a_suite_cell_turns_the_limited_view_on_through_its_observation_fields():
    from envs.evaluation.suite import parse_suite

    cell = {"name": "x", "scenario": "corridor", "n_pedestrians": 5, "robot_visible": True, "episodes": 1, "seed0": 0}

    def suite(observation: dict):
        return parse_suite({"name": "s", "version": 1, "cells": [{**cell, "observation": observation}]})

    obs = suite({"fov_deg": 120, "occlusion": True}).cells[0].env_config(0).observation
    assert (obs.fov_deg, obs.occlusion, obs.limited_view) == (120, True, True)
    with pytest.raises(ValueError, match="fov_deg"):
        suite({"fov_deg": 400})


def test_crowdnav_evaluate_takes_the_view_flags_and_records_them(tmp_path, capsys):
    import json

    from envs.cli import main

    out = tmp_path / "social-force.json"
    code = main(["evaluate", "--policy", "social-force", "--scenario", "corridor", "--episodes", "1", "--workers", "1",
                 "--pedestrians", "6", "--time-limit", "2", "--record", "0", "--fov-deg", "120", "--occlusion",
                 "--json", str(out), "--out", str(tmp_path / "dir"), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    config = json.loads(out.read_text())["config"]
    assert (config["fov_deg"], config["occlusion"]) == (120.0, True)
    assert "(unicycle), field of view 120 deg, occlusion, time limit 2 s" in capsys.readouterr().out
