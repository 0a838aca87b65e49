"""`envs.scoring.social_metrics` on hand-built episodes with values computed by hand, the env's per-step path, and
records (old files without these fields still load, aggregate and print "n/a")."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from envs.evaluation.records import EpisodeRecord, RecordStore, read_records
from envs.evaluation.report import markdown_table
from envs.evaluation.stats import aggregate
from envs.scoring.metrics import EpisodeMetrics, social_step
from envs.scoring.social_metrics import (
    finite_difference_velocity,
    group_contact,
    hall_zone_index,
    mean_jerk,
    nearest_person_distance,
    path_irregularity,
    shortest_path_m,
    spl,
    step_time_to_collision,
    surface_distances,
    time_to_collision,
    zone_times,
)

DT = 0.25
R = 0.3  # robot and person radius, m


def _side_by_side(gap_m: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Robot (steps, 2) walking along y = 0 at 1 m/s with one person (steps, 1, 2) beside it at centre distance
    gap_m, both at the steps' ends."""
    x = DT * np.arange(1, steps + 1)
    robot = np.stack([x, np.zeros(steps)], axis=1)
    return robot, (robot + np.array([0.0, gap_m]))[:, None, :]


# ------------------------------------------------------------------------------------------ Hall zones
def test_passing_at_one_metre_for_two_seconds_is_two_seconds_in_personal_space():
    robot, people = _side_by_side(1.0, 8)  # 8 steps of 0.25 s = 2 s; robot edge to person centre 0.7 m
    times = zone_times(robot, people, R, DT)
    assert times == {"intimate": 0.0, "personal": pytest.approx(2.0), "social": 0.0}
    # then 4 steps (1 s) at 2 m: social space; the bands are exclusive, as HuNavSim counts them
    far_robot, far_people = _side_by_side(2.0, 4)
    times = zone_times(np.vstack([robot, far_robot]), np.vstack([people, far_people]), R, DT)
    assert times == {"intimate": 0.0, "personal": pytest.approx(2.0), "social": pytest.approx(1.0)}
    assert times["personal"] / (12 * DT) == pytest.approx(2 / 3)  # the fraction of episode time


def test_zone_edges_are_measured_from_the_robot_edge_to_the_person_centre():
    # edge-to-centre distances exactly at the edges fall in the outer band (intimate is "closer than 0.45 m")
    assert hall_zone_index(np.array([-0.1, 0.44, 0.45, 1.19, 1.2, 3.59, 3.6, np.inf])).tolist() == \
        [0, 0, 1, 1, 2, 2, 3, 3]
    robot = np.zeros((1, 2))
    people = np.array([[[0.7, 0.0], [0.0, 3.0]]])  # centre distances 0.7 and 3.0 m
    assert nearest_person_distance(robot, people, R) == pytest.approx([0.4])  # 0.7 - 0.3: intimate
    absent = np.array([[False, True]])
    assert nearest_person_distance(robot, people, R, absent) == pytest.approx([2.7])
    assert nearest_person_distance(robot, people, R, np.zeros((1, 2), bool)) == [np.inf]  # nobody: beyond


# ------------------------------------------------------------------------------------------ time to collision
def test_heading_straight_at_a_standing_person_from_three_metres_is_2_4_seconds():
    # the gap closes at 1 m/s until the discs touch: (3 - 0.3 - 0.3) / 1
    assert time_to_collision(np.array([3.0, 0.0]), np.array([-1.0, 0.0]), 2 * R) == pytest.approx(2.4)
    # head-on, both at 1 m/s: the gap closes at 2 m/s
    assert time_to_collision(np.array([3.0, 0.0]), np.array([-2.0, 0.0]), 2 * R) == pytest.approx(1.2)


def test_time_to_collision_is_zero_in_contact_and_inf_off_course():
    p = np.array([[0.5, 0.0], [3.0, 0.0], [3.0, 1.0], [3.0, 0.6], [3.0, 0.0]])
    v = np.array([[1.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]])
    ttc = time_to_collision(p, v, 2 * R)
    # overlapping: 0; moving apart: inf; passing 1 m wide of a 0.6 m contact distance: inf;
    # grazing (offset exactly 0.6 m): touches at x = 0 after 3 s; no relative motion: inf
    assert ttc.tolist() == [0.0, math.inf, math.inf, pytest.approx(3.0), math.inf]


def test_episode_minimum_time_to_collision_uses_each_steps_start_and_velocity():
    robot = np.array([[-3.0, 0.0], [-2.75, 0.0], [-2.5, 0.0]])  # 1 m/s at 0.25 s steps toward the origin
    people = np.zeros((3, 1, 2))  # one person standing at the origin
    ttc = step_time_to_collision(robot[:-1], finite_difference_velocity(robot, DT), people[:-1],
                                 finite_difference_velocity(people, DT), np.array([R]), R)
    assert ttc == pytest.approx([2.4, 2.15])  # min over the episode: 2.15 s
    away = robot[::-1]
    ttc = step_time_to_collision(away[:-1], finite_difference_velocity(away, DT), people[:-1],
                                 np.zeros((2, 1, 2)), np.array([R]), R)
    assert ttc.tolist() == [math.inf, math.inf]


# ------------------------------------------------------------------------------------------ groups
def test_group_collision_needs_contact_with_a_member_of_a_group_of_two_or_more():
    robot = np.zeros((1, 2))
    people = np.array([[[0.5, 0.0], [0.5, 0.5], [-0.5, 0.0]]])  # A, B (group 0), C alone (group 1)
    groups = np.array([[0, 0, 1]])
    touch_c = surface_distances(robot, people + np.array([[5.0, 0.0], [5.0, 0.0], [0.0, 0.0]]), np.full(3, R), R)
    assert touch_c[0, 2] < 0 and (touch_c[0, :2] > 0).all()
    assert group_contact(touch_c, groups).tolist() == [False]  # touching the singleton is no group collision
    touch_a = surface_distances(robot, people + np.array([[0.0, 0.0], [5.0, 0.0], [-5.0, 0.0]]), np.full(3, R), R)
    assert group_contact(touch_a, groups).tolist() == [True]
    alone = np.array([[True, False, True]])  # B is not there: A is on their own at this step
    assert group_contact(touch_a, groups, alone).tolist() == [False]
    assert group_contact(touch_a, np.array([[-1, -1, 1]])).tolist() == [False]  # negative ids: no group


# ------------------------------------------------------------------------------------------ path
def test_straight_constant_speed_path_has_zero_irregularity_and_zero_jerk():
    path = np.stack([np.linspace(0.0, 5.0, 21), np.linspace(0.0, 2.0, 21)], axis=1)
    assert path_irregularity(path, np.array([10.0, 4.0])) == pytest.approx(0.0, abs=1e-7)
    assert mean_jerk(path, DT) == pytest.approx(0.0, abs=1e-9)
    accelerating = np.stack([0.5 * (DT * np.arange(12)) ** 2, np.zeros(12)], axis=1)
    assert mean_jerk(accelerating, DT) == pytest.approx(0.0, abs=1e-9)  # constant acceleration: no jerk


def test_jerk_of_a_cubic_and_of_a_single_kick():
    t = 0.5 * np.arange(6)
    cubic = np.stack([t**3, np.zeros(6)], axis=1)  # x = t^3: jerk 6 m/s^3 everywhere
    assert mean_jerk(cubic, 0.5) == pytest.approx(6.0)
    kick = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])  # third difference 1 m over 0.5 s steps
    assert mean_jerk(kick, 0.5) == pytest.approx(8.0)
    assert mean_jerk(kick[:3], 0.5) is None  # fewer than 4 positions


def test_path_irregularity_is_the_mean_angle_to_the_goal_over_moving_steps():
    goal = np.array([10.0, 0.0])
    # first a step sideways (pi/2 off the goal line), a pause (no direction: left out), then straight at the goal
    path = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 1.0], [1.0, 0.9]])
    assert path_irregularity(path, goal) == pytest.approx(math.pi / 4)
    assert path_irregularity(np.array([[0.0, 0.0], [-1.0, 0.0]]), goal) == pytest.approx(math.pi)  # away
    assert path_irregularity(np.zeros((3, 2)), goal) is None  # never moved


def test_spl_of_a_success_along_one_and_a_half_times_the_straight_line_is_two_thirds():
    start, goal = np.array([0.0, 0.0]), np.array([3.3, 0.0])
    assert shortest_path_m(start, goal, 0.3) == pytest.approx(3.0)  # to the goal region's edge
    assert spl(True, start, goal, 4.5, 0.3) == pytest.approx(2 / 3)
    assert spl(True, start, goal, 3.0, 0.3) == pytest.approx(1.0)
    assert spl(False, start, goal, 3.0, 0.3) == 0.0  # a failure
    assert spl(True, start, start, 0.0, 0.3) == 1.0  # started inside the goal region


@pytest.mark.parametrize("call", [
    lambda: zone_times(np.array([[np.nan, 0.0]]), np.zeros((1, 1, 2)), R, DT),
    lambda: zone_times(np.zeros((2, 2)), np.zeros((3, 1, 2)), R, DT),
    lambda: zone_times(np.zeros((1, 2)), np.zeros((1, 1, 2)), R, 0.0),
    lambda: nearest_person_distance(np.zeros((1, 2)), np.zeros((1, 1, 2)), R, np.ones((1, 1))),
    lambda: time_to_collision(np.zeros(2), np.array([np.nan, 0.0]), 0.6),
    lambda: time_to_collision(np.zeros(3), np.zeros(3), 0.6),
    lambda: path_irregularity(np.zeros((3, 3)), np.zeros(2)),
    lambda: mean_jerk(np.zeros((5, 2)), -0.1),
    lambda: spl(True, np.zeros(2), np.array([np.inf, 0.0]), 1.0, 0.3),
    lambda: group_contact(np.zeros((1, 2)), np.zeros((1, 3), int)),
    lambda: group_contact(np.zeros((1, 2)), np.zeros((1, 2))),
])
def test_bad_input_raises_value_error(call):
    with pytest.raises(ValueError):
        call()


def test_absent_rows_may_be_nan():
    people = np.array([[[1.0, 0.0], [np.nan, np.nan]]])
    present = np.array([[True, False]])
    assert nearest_person_distance(np.zeros((1, 2)), people, R, present) == pytest.approx([0.7])
    ttc = step_time_to_collision(np.zeros((1, 2)), np.array([[1.0, 0.0]]), people, np.zeros((1, 2, 2)),
                                 np.array([R, np.nan]), R, present)
    assert ttc == pytest.approx([0.4])


# ------------------------------------------------------------------------------------------ the env's path
def test_episode_metrics_accumulate_the_same_values_step_by_step():
    """`EpisodeMetrics.observe` with `social_step` on a hand-built run: the robot walks at 1 m/s along y = 0 from
    (-3, 0) for 4 steps of 0.25 s toward the goal (1.3, 0); a group of two stands 1 m off the path at x = 0."""
    m = EpisodeMetrics(start=(-3.0, 0.0), goal=(1.3, 0.0), goal_tolerance_m=0.3, dt_s=DT)
    people = np.array([[0.0, 1.0], [0.5, 1.2]])
    radius, groups = np.full(2, R), np.array([0, 0])
    pos = np.array([-3.0, 0.0])
    for _ in range(4):
        nxt = pos + np.array([DT, 0.0])
        centre = np.linalg.norm(people - nxt, axis=1)
        m.update(DT, DT, float((centre - 2 * R).min()), 0.2, False)
        m.observe(nxt, social_step(pos, nxt, DT, R, centre, centre - 2 * R, groups, people, np.zeros((2, 2)), radius))
        pos = nxt
    d = m.as_dict()
    # the robot ends at x = -2: nearest person centre sqrt(4 + 1) - 0.3 = 1.94 m away, social zone all along
    assert (d["time_intimate_s"], d["time_personal_s"], d["time_social_s"]) == (0.0, 0.0, pytest.approx(1.0))
    assert d["social_fraction"] == pytest.approx(1.0)
    assert d["path_irregularity_rad"] == pytest.approx(0.0) and d["jerk_mps3"] == pytest.approx(0.0)
    assert d["min_ttc_s"] == math.inf  # passing 1 m from a 0.6 m contact distance: never on a collision course
    assert d["group_collision"] is False and d["spl"] == 0.0  # not (yet) a success
    m.success = True
    assert m.as_dict()["spl"] == pytest.approx(1.0)  # 1 m travelled, less than the 4 m to the goal region
    assert EpisodeMetrics(labelled=False).as_dict()["group_collision"] is None


def test_env_episode_record_carries_the_metrics(tmp_path):
    from envs.config import CrowdNavConfig
    from envs.evaluation.episode import episode_record, run_episode

    result = run_episode(CrowdNavConfig(n_pedestrians=6, time_limit_s=4.0), "random", seed=3)
    rec = episode_record(result, "random", 3)
    m = result.metrics
    assert rec.path_irregularity_rad == pytest.approx(path_irregularity(result.robot_xy, result.goal))
    assert rec.jerk_mps3 == pytest.approx(mean_jerk(result.robot_xy, m["time_s"] / m["steps"]))
    assert rec.spl == (0.0 if rec.outcome != "success" else rec.spl)
    zones = rec.time_intimate_s + rec.time_personal_s + rec.time_social_s
    assert 0.0 <= zones <= rec.time_s + 1e-9 and rec.group_collision is not None
    assert rec.collision_course == (rec.min_ttc_s is not None)
    store = RecordStore(tmp_path / "records.jsonl")
    store.append(rec)
    assert store.read() == [rec]


# ------------------------------------------------------------------------------------------ records
OLD = {"policy": "p", "seed": 0, "outcome": "success", "cell": "c", "steps": 10, "time_s": 1.0, "time_to_goal_s": 1.0,
       "path_length_m": 1.0, "min_distance_m": 0.5, "discomfort_frequency": 0.0, "group_intrusion": False,
       "intrusion_fraction": 0.0, "plans": 10, "fallbacks": 0, "ret": 1.0, "wall_time_s": 0.1, "error": None,
       "fingerprint": "f", "solve_times_ms": []}


def test_old_records_without_the_fields_load_and_show_n_a(tmp_path):
    path = tmp_path / "records.jsonl"
    path.write_text(json.dumps(OLD) + "\n")
    [old] = read_records(path)
    assert old.spl is None and old.group_collision is None and old.min_ttc is None
    summary = aggregate([old])
    assert summary["spl"] is None and summary["group_collision_rate"] is None and summary["min_ttc_s"] is None
    table = markdown_table({**summary, "policy": "p", "config": {}})
    assert "| SPL | n/a |" in table and "| group collision rate [95% CI] | n/a |" in table
    # mixed with a new record, only the new one counts
    new = EpisodeRecord(**{**OLD, "seed": 1, "spl": 0.5, "group_collision": True, "min_ttc_s": None,
                           "collision_course": False, "time_intimate_s": 0.25, "intimate_fraction": 0.25})
    summary = aggregate([old, new])
    assert summary["spl"] == 0.5 and summary["group_collision_rate"] == 1.0
    assert summary["group_collision_measured"] == 1 and summary["collision_course_rate"] == 0.0
    assert summary["min_ttc_s"] is None and new.min_ttc == math.inf
    assert summary["time_intimate_s"] == 0.25 and summary["time_personal_s"] is None


def test_old_and_new_runs_compare(tmp_path, capsys, load_script):
    cmp = load_script("compare_runs")
    old = RecordStore(tmp_path / "a.jsonl")
    new = RecordStore(tmp_path / "b.jsonl")
    for seed in range(3):
        old.append(EpisodeRecord.from_json({**OLD, "seed": seed}))
        new.append(EpisodeRecord(**{**OLD, "seed": seed, "spl": 0.9, "solve_times_ms": ()}))
    assert cmp.main([str(old.path), str(new.path), "--policy", "p"]) == 0
    out = capsys.readouterr().out
    assert "pooled                         SPL: A n/a | B 0.900" in out


def test_a_leaderboard_of_old_and_new_records_prints_n_a_for_the_old_policy():
    from envs.evaluation.leaderboard import leaderboard, leaderboard_markdown
    from envs.evaluation.suite import parse_suite
    from envs.policies import PolicyConfig

    suite = parse_suite({"name": "s", "version": 1, "cells": [
        {"name": "c", "scenario": "corridor", "n_pedestrians": 4, "robot_visible": True, "episodes": 2, "seed0": 0}]})
    old = [EpisodeRecord.from_json({**OLD, "policy": "random", "seed": s}) for s in range(2)]
    new = [EpisodeRecord(**{**OLD, "policy": "social-force", "seed": s, "spl": 0.75, "group_collision": s == 0,
                            "collision_course": True, "min_ttc_s": 1.0 + s, "solve_times_ms": ()}) for s in range(2)]
    board = leaderboard(suite, list(suite.cells), [PolicyConfig("random"), PolicyConfig("social-force")], old + new)
    pooled = board["pooled"]["synthetic"]
    assert pooled["random"]["spl"] is None and pooled["social-force"]["spl"] == 0.75
    assert pooled["social-force"]["group_collision_rate"] == 0.5 and pooled["social-force"]["min_ttc_s"] == 1.5
    lines = leaderboard_markdown(board).splitlines()
    [old_row] = [ln for ln in lines if ln.startswith("| synthetic | random |") and "n/a" in ln]
    assert old_row.count("n/a") == 8  # every social column
    [spl_row] = [ln for ln in lines if ln.startswith("| c | n/a |")]
    assert spl_row == "| c | n/a | 0.750 |"
    json.dumps(board, allow_nan=False)  # strict JSON: no inf or NaN
