"""CrowdNav++'s intrusion ratio (ITR) and social distance during intrusions (SD) on hand-built episodes with values
computed by hand, the env's record against CrowdNav++'s own per-state procedure, and records and tables (old
records without the fields load and print "n/a")."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from envs.evaluation.records import EpisodeRecord, RecordStore, read_records
from envs.evaluation.report import compare, markdown_table
from envs.evaluation.stats import aggregate
from envs.scoring.metrics import EpisodeMetrics, SocialStep
from envs.scoring.social_metrics import ITR_OFFSETS_S, future_intrusions
from envs.view import Pedestrians

R = 0.3  # robot and person radius, m: contact (and intrusion) below a centre distance of 0.6 m


def _crossing(dt_s: float, present: np.ndarray | None = None):
    """The robot walks up the y axis at 1 m/s from (0, -2) for 4 s; one person walks along the x axis at 1 m/s from
    (-3, 0), recorded for 5 s (the crowd's continuation past the robot's last state). Robot (T + 1, 2), people
    (S, 1, 2) at the states 0, dt, ..."""
    t = dt_s * np.arange(round(4.0 / dt_s) + 1)
    s = dt_s * np.arange(round(5.0 / dt_s) + 1)
    robot = np.stack([np.zeros_like(t), t - 2.0], axis=1)
    people = np.stack([s - 3.0, np.zeros_like(s)], axis=1)[:, None, :]
    return robot, people, future_intrusions(robot, people, np.full(1, R), R, dt_s, present)


# ------------------------------------------------------------------------------------------ the definition
def test_a_robot_that_never_comes_near_anyone_has_itr_zero():
    robot, people, _ = _crossing(0.25)
    fi = future_intrusions(robot + np.array([5.0, 0.0]), people, np.full(1, R), R, 0.25)
    assert fi.count == 0 and fi.ratio == 0.0 and fi.social_distance_m is None and fi.states == 17
    assert np.isnan(fi.min_distance_m).all()


def test_crossing_the_future_path_of_a_person_without_touching_them_now():
    robot, people, fi = _crossing(0.25)  # CrowdNav++'s step: the 0.25 .. 1.25 s offsets are 1 .. 5 steps
    now = np.linalg.norm(people[: len(robot), 0] - robot, axis=1)
    assert now.min() == pytest.approx(math.sqrt(0.5))  # at t = 2.5 s; never within 0.6 m now
    # at time t the robot is at (0, t - 2), the person at t + o at (t + o - 3, 0): an intrusion where
    # (t + o - 3)^2 + (t - 2)^2 < 0.36 for some o in 0.25 .. 1.25 s: t = 1.5 (o = 1.25: 0.559 m), 1.75 (o = 1.25:
    # 0.25 m), 2.0 (o = 1: 0 m), 2.25 (o = 0.25: 0.25 m), 2.5 (o = 0.5: 0.5 m); not t = 1.25 or 2.75
    assert np.flatnonzero(fi.intruding).tolist() == [6, 7, 8, 9, 10]
    expected = [math.sqrt(0.3125), 0.25, 0.0, 0.25, 0.5]
    assert fi.min_distance_m[fi.intruding] == pytest.approx(expected)
    assert fi.states == 17 and fi.ratio == pytest.approx(5 / 17)  # 16 steps: 17 states, the terminal one unchecked
    assert fi.social_distance_m == pytest.approx(sum(expected) / 5)  # 0.3118 m


def test_the_offsets_are_seconds_whatever_the_step():
    _, _, coarse = _crossing(0.25)
    _, _, fine = _crossing(0.05)  # our env step: the offsets are 5, 10, ..., 25 steps
    assert ITR_OFFSETS_S == (0.25, 0.5, 0.75, 1.0, 1.25)
    assert fine.intruding[::5].tolist() == coarse.intruding.tolist()
    assert fine.min_distance_m[::5] == pytest.approx(coarse.min_distance_m, nan_ok=True)
    _, _, tenth = _crossing(0.1)  # 0.25 s is 2.5 steps: linear interpolation between two states (exact here)
    assert tenth.intruding[::5].tolist() == coarse.intruding[::2].tolist()
    assert tenth.min_distance_m[::5] == pytest.approx(coarse.min_distance_m[::2], nan_ok=True)
    _, _, hundredth = _crossing(0.01)  # 401 states: checked in several blocks
    assert hundredth.intruding[::25].tolist() == coarse.intruding.tolist()
    # the fraction of time is nearly the same at every step: intrusions from about t = 1.45 s to 2.6 s of 4 s
    assert fine.ratio == pytest.approx(coarse.ratio, abs=0.03) and tenth.ratio == pytest.approx(fine.ratio, abs=0.03)


def test_only_people_present_now_and_then_count():
    robot, people, _ = _crossing(0.25)
    present = np.ones((len(people), 1), bool)
    present[:8] = False  # appears at t = 2 s: the states before do not see that future
    fi = future_intrusions(robot, np.where(present[..., None], people, np.nan), np.full(1, R), R, 0.25, present)
    assert np.flatnonzero(fi.intruding).tolist() == [8, 9, 10]
    present = np.ones((len(people), 1), bool)
    present[11:] = False  # gone after t = 2.5 s: t = 1.5 s and 2.5 s needed it at 2.75 s or later
    fi = future_intrusions(robot, people, np.full(1, R), R, 0.25, present)
    assert np.flatnonzero(fi.intruding).tolist() == [7, 8, 9]
    fi = future_intrusions(robot, people[:17], np.full(1, R), R, 0.25)  # no continuation past the last state
    assert np.flatnonzero(fi.intruding).tolist() == [6, 7, 8, 9, 10]  # (this crossing ends before it matters)


def test_the_terminal_state_counts_in_the_ratio_but_is_never_checked():
    people = np.array([[[0.0, 0.0]], [[0.0, 0.0]], [[0.0, 0.0]]])  # a person standing at the origin
    at_end = future_intrusions(np.array([[-1.0, 0.0], [-0.25, 0.0]]), people[:2], np.full(1, R), R, 0.25)
    assert at_end.ratio == 0.0  # the one checked state is 1 m away from where the person will be
    at_start = future_intrusions(np.array([[-0.25, 0.0], [-1.0, 0.0]]), people, np.full(1, R), R, 0.25)
    assert at_start.ratio == 0.5 and at_start.social_distance_m == pytest.approx(0.25)


def test_bad_input_raises_value_error():
    robot, people, _ = _crossing(0.25)
    with pytest.raises(ValueError):
        future_intrusions(robot, people[:5], np.full(1, R), R, 0.25)  # fewer people states than robot states
    with pytest.raises(ValueError):
        future_intrusions(robot, people, np.full(1, R), R, 0.0)
    with pytest.raises(ValueError):
        future_intrusions(robot, people, np.full(1, R), R, 0.25, offsets_s=(0.0,))


# ------------------------------------------------------------------------------------------ the env
def test_episode_metrics_track_people_by_id_and_continue_past_the_end():
    robot, people, expected = _crossing(0.25)
    m = EpisodeMetrics(start=tuple(robot[0]), goal=(0.0, 2.0), dt_s=0.25, robot_radius_m=R)
    other = np.array([9.0, 9.0])  # a bystander in another row, arriving later: ids, not rows, identify people
    for k in range(len(robot)):
        ids, pos = (np.array([7]), people[k]) if k < 3 else (np.array([4, 7]), np.vstack([other, people[k]]))
        if k:
            m.observe(robot[k], SocialStep(math.inf, math.inf, False))
        m.observe_people(Pedestrians(pos, np.zeros_like(pos), np.full(len(ids), R), ids, ids))
    assert m.intrusions().states == 17 and m.as_dict()["itr_states"] == 5  # (the crossing is over before the end)

    def future(ids: np.ndarray, times_s: np.ndarray) -> np.ndarray:
        assert ids.tolist() == [4, 7] and times_s == pytest.approx(0.25 * np.arange(1, 5))
        return np.stack([np.stack([other, people[16 + round(t / 0.25)][0]]) for t in times_s])

    last = m.people.states[-1]
    m.continue_people(Pedestrians(last[1], np.zeros_like(last[1]), last[2], last[0], last[0]), future)
    d = m.as_dict()
    assert d["itr"] == pytest.approx(expected.ratio) and d["itr_states"] == 5
    assert d["itr_sd_m"] == pytest.approx(expected.social_distance_m)
    assert EpisodeMetrics(dt_s=0.25).as_dict()["itr"] is None  # people never observed: not measured


def test_env_records_match_crowdnav_plusplus_per_state_rollout():
    """CrowdNav++ rolls the humans out from every state (`calc_human_future_traj(method='truth')`); the crowd's
    `future` does the same here (exact with an invisible robot). The record, computed at the end from the recorded
    trajectories, must agree state for state."""
    from envs.env import CrowdNavEnv
    from envs.evaluation.episode import episode_record
    from envs.evaluation.suite import load_suite
    from envs.policies import decide, make_policy

    cfg = load_suite("crowdnav-plusplus").cells[0].env_config(2)
    env = CrowdNavEnv(cfg)
    policy = make_policy("social-force", env)
    env.reset(seed=2)
    policy.reset(2)
    hits, steps, done = [], 0, False
    while not done:
        p = env.pedestrians()
        d = np.linalg.norm(env.crowd.future(p.ped_id, np.array(ITR_OFFSETS_S)) - env.robot_state[:2], axis=-1)
        hit = ~np.isnan(d) & (d < p.radius + cfg.robot.radius_m)
        if hit.any():
            hits.append(d[hit].min())
        _, _, terminated, truncated, info = env.step_decision(decide(policy, env))
        steps, done = steps + 1, terminated or truncated
    m = info["episode_metrics"]
    assert hits, "the episode should hold intrusions"
    assert m["itr_states"] == len(hits) and m["itr"] == pytest.approx(len(hits) / (steps + 1))
    assert m["itr_sd_m"] == pytest.approx(np.mean(hits))

    class Result:
        metrics, ret, wall_time_s, solve_times_ms = {**m, "plans": 0, "fallbacks": 0}, 0.0, 0.0, []

    rec = episode_record(Result(), "social-force", 2)
    assert (rec.itr, rec.itr_states, rec.itr_sd_m) == (m["itr"], len(hits), m["itr_sd_m"])


# ------------------------------------------------------------------------------------------ records and tables
OLD = {"policy": "p", "seed": 0, "outcome": "success", "cell": "c", "steps": 10, "time_s": 1.0, "time_to_goal_s": 1.0,
       "path_length_m": 1.0, "min_distance_m": 0.5, "discomfort_frequency": 0.0, "group_intrusion": False,
       "intrusion_fraction": 0.0, "plans": 10, "fallbacks": 0, "ret": 1.0, "wall_time_s": 0.1, "error": None,
       "fingerprint": "f", "solve_times_ms": []}


def test_records_round_trip_and_aggregate_as_crowdnav_plusplus(tmp_path):
    new = {**OLD, "solve_times_ms": ()}
    recs = [EpisodeRecord(**{**new, "seed": 0, "itr": 0.1, "itr_states": 2, "itr_sd_m": 0.2}),
            EpisodeRecord(**{**new, "seed": 1, "outcome": "collision", "itr": 0.3, "itr_states": 6, "itr_sd_m": 0.4}),
            EpisodeRecord(**{**new, "seed": 2, "itr": 0.0, "itr_states": 0, "itr_sd_m": None})]
    store = RecordStore(tmp_path / "records.jsonl")
    for r in recs:
        store.append(r)
    assert store.read() == recs
    s = aggregate(recs)
    # ITR: the mean of the per-episode ratios over every outcome; SD: pooled over the intruding states
    assert s["itr"] == pytest.approx(0.4 / 3) and s["itr_measured"] == 3 and s["itr_states"] == 8
    assert s["itr_sd_m"] == pytest.approx((2 * 0.2 + 6 * 0.4) / 8)
    table = markdown_table({**s, "policy": "p", "config": {}})
    assert "| ITR, intrusion ratio (CrowdNav++) | 13.33% |" in table
    assert "| SD, social distance in intrusions (m) | 0.35 |" in table
    assert "13.33% | 0.35 |" in compare([{**s, "policy": "p", "config": {}}])


def test_old_records_without_the_fields_load_and_show_n_a(tmp_path):
    path = tmp_path / "records.jsonl"
    path.write_text(json.dumps(OLD) + "\n")
    [old] = read_records(path)
    assert (old.itr, old.itr_states, old.itr_sd_m) == (None, None, None)
    s = aggregate([old])
    assert s["itr"] is None and s["itr_sd_m"] is None and s["itr_measured"] == 0
    table = markdown_table({**s, "policy": "p", "config": {}})
    assert "| ITR, intrusion ratio (CrowdNav++) | n/a |" in table
    assert "| SD, social distance in intrusions (m) | n/a |" in table
    never = aggregate([EpisodeRecord(**{**OLD, "itr": 0.0, "itr_states": 0})])  # measured, no intrusion
    assert markdown_table({**never, "policy": "p", "config": {}}).count("| 0.00% |") == 1
    assert "| SD, social distance in intrusions (m) | – |" in markdown_table({**never, "policy": "p", "config": {}})


def test_the_leaderboard_shows_itr_and_sd():
    from envs.evaluation.leaderboard import leaderboard, leaderboard_markdown
    from envs.evaluation.suite import parse_suite
    from envs.policies import PolicyConfig

    suite = parse_suite({"name": "s", "version": 1, "cells": [
        {"name": "c", "scenario": "corridor", "n_pedestrians": 4, "robot_visible": True, "episodes": 2, "seed0": 0}]})
    old = [EpisodeRecord.from_json({**OLD, "policy": "random", "seed": s}) for s in range(2)]
    new = [EpisodeRecord(**{**OLD, "policy": "social-force", "seed": s, "itr": 0.042 * s, "itr_states": 3 * s,
                            "itr_sd_m": 0.5 if s else None, "solve_times_ms": ()}) for s in range(2)]
    board = leaderboard(suite, list(suite.cells), [PolicyConfig("random"), PolicyConfig("social-force")], old + new)
    pooled = board["pooled"]["synthetic"]
    assert pooled["social-force"]["itr"] == pytest.approx(0.021) and pooled["social-force"]["itr_sd_m"] == 0.5
    lines = leaderboard_markdown(board).splitlines()
    [header] = [ln for ln in lines if ln.startswith("| pool | policy | time in intimate")]
    assert header.endswith("| ITR, intrusion ratio (CrowdNav++) | SD, social distance in intrusions (m) |")
    [row] = [ln for ln in lines if ln.startswith("| synthetic | social-force |") and "%" in ln]
    assert row.endswith("| 2.10% | 0.50 |")
    [old_row] = [ln for ln in lines if ln.startswith("| synthetic | random |") and "n/a" in ln]
    assert old_row.endswith("| n/a | n/a |")
    json.dumps(board, allow_nan=False)
