"""The any-robot bounds of a suite's episodes: resumable lines, the leaderboard's failure classes, the command."""

from __future__ import annotations

import json

import pytest

from envs.cli import main
from envs.evaluation.benchmark import run_benchmark
from envs.evaluation.bounds import BOUNDS, read_bounds, run_bounds
from envs.evaluation.suite import parse_suite
from envs.policies import PolicyConfig

SUITE = {"name": "tiny-bounds", "version": 1, "description": "test", "defaults": {"time_limit_s": 2.0},
         "cells": [{"name": "circle-short", "scenario": "circle_crossing", "n_pedestrians": 3, "robot_visible": False,
                    "episodes": 2, "seed0": 0},
                   {"name": "corridor-seen", "scenario": "corridor", "n_pedestrians": 3, "robot_visible": True,
                    "episodes": 1, "seed0": 0}]}


def test_bounds_resume_skip_seen_robots_and_class_failures_in_the_leaderboard(tmp_path):
    suite = parse_suite(SUITE)
    first = run_bounds(suite, suite.cells, tmp_path, progress=False)
    # 2 s cannot cover the 12 m across the circle at 1.2 m/s: no robot could succeed
    assert first["skipped"] == ["corridor-seen"]
    assert first["cells"]["circle-short"]["infeasible"] == 2 and first["cells"]["circle-short"]["success_ceiling"] == 0
    lines = read_bounds(tmp_path / BOUNDS).values()
    assert all(line["robot_witness"] is None and line["sensing_witness"] is None for line in lines)  # infeasible
    again = run_bounds(suite, suite.cells, tmp_path, progress=False)
    assert again["run"]["episodes_run"] == 0 and again["run"]["episodes_resumed"] == 2
    board = run_benchmark(suite, suite.cells, [PolicyConfig("random")], tmp_path, progress=False)
    classes = board["bounds"]["failures"]["synthetic"]["random"]
    assert classes["failures"] == 3 and classes["infeasible"] == 2 and classes["unbounded"] == 1
    assert classes["successes_on_infeasible"] == 0
    assert "What any robot could do" in (tmp_path / "leaderboard.md").read_text()


def test_bad_bounds_files_are_refused(tmp_path):
    suite = parse_suite(SUITE)
    cells = suite.select(["circle-short"])
    run_bounds(suite, cells, tmp_path, progress=False)
    lines = (tmp_path / BOUNDS).read_text().splitlines()
    other = json.loads(lines[0])
    other["fingerprint"] = "0" * 16
    (tmp_path / BOUNDS).write_text("\n".join([json.dumps(other), lines[1]]) + "\n")
    with pytest.raises(ValueError, match="other settings"):
        run_bounds(suite, cells, tmp_path, progress=False)
    with pytest.raises(ValueError, match="another version"):
        run_benchmark(suite, cells, [PolicyConfig("random")], tmp_path, progress=False)
    (tmp_path / BOUNDS).write_text('{"cell": "circle-short"}\n{"cell": "circle-short", "se')
    with pytest.raises(ValueError, match=r"bounds.jsonl:1: malformed"):
        read_bounds(tmp_path / BOUNDS)
    (tmp_path / BOUNDS).write_text(lines[0] + "\n" + lines[1][:20])  # a partial last line is a cut write
    assert len(read_bounds(tmp_path / BOUNDS)) == 1


def test_cli_bounds_misuse_is_one_line(tmp_path, capsys):
    for args, needle in ((["--suite", "nope"], "valid names"),
                         (["--suite", "smoke", "--cells", "real-mars"], "valid names"),
                         (["--suite", "smoke", "--cells-per-step", "1"], "--cells-per-step must"),
                         (["--suite", "smoke", "--cells", "circle-low-invisible", "--optimistic-dt", "0.25"],
                          "whole multiple"),  # a synthetic cell: the check must not depend on ../shared's data
                         (["--suite", "smoke", "--workers", "0"], "--workers"),
                         (["--suite", "smoke", "--data", str(tmp_path / "none")], "not found")):
        code = main(["bounds", *args, "--out", str(tmp_path / "o"), "--no-progress"])
        err = capsys.readouterr().err
        assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, (args, err)
    assert not (tmp_path / "o").exists()


def test_cli_bounds_prints_the_table_and_resumes(tmp_path, capsys):
    args = ["bounds", "--suite", "smoke", "--cells", "circle-low-invisible,corridor-low-visible", "--out",
            str(tmp_path), "--workers", "1", "--no-progress"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "| circle-low-invisible | 2 |" in out and "Not bounded" in out and "2 episodes computed" in out
    assert main(args) == 0
    assert "0 episodes computed, 2 already there" in capsys.readouterr().out


def test_a_feasible_episode_is_tried_with_the_benchmark_robot(tmp_path):
    spec = {**SUITE, "defaults": {"time_limit_s": 20.0}, "cells": SUITE["cells"][:1]}
    summary = run_bounds(parse_suite(spec), parse_suite(spec).cells, tmp_path, progress=False)
    lines = read_bounds(tmp_path / BOUNDS)
    assert {line["verdict"] for line in lines.values()} == {"feasible"}  # 3 people in a 12 m circle, 20 s
    assert {line["robot_witness"] for line in lines.values()} == {"success"}
    assert summary["cells"]["circle-short"]["robot_floor"] == 1.0
    # three people in view from the start: the sensing witness knows them all and wins too, at its first attempt
    assert {(line["sensing_witness"], line["sensing_attempt"]) for line in lines.values()} == {("success", 1)}
    assert summary["cells"]["circle-short"]["sensing_floor"] == 1.0
    assert "sensing robot wins" in (tmp_path / "bounds.md").read_text()


def test_an_episode_whose_worker_died_is_left_for_the_rerun(tmp_path, monkeypatch):
    import crowdsim.distributed as dist

    def flaky(fn, jobs, workers, ctx=None):
        yield 0, dist.WorkerDied("killed by signal 9 (SIGKILL)")
        for i, job in enumerate(jobs[1:], start=1):
            yield i, fn(job)

    monkeypatch.setattr(dist, "run_in_processes", flaky)
    suite = parse_suite(SUITE)
    cells = suite.select(["circle-short"])
    first = run_bounds(suite, cells, tmp_path, workers=2, progress=False)
    assert first["run"]["episodes_run"] == 1 and len(first["run"]["died"]) == 1
    assert len(read_bounds(tmp_path / BOUNDS)) == 1
    monkeypatch.setattr(dist, "run_in_processes", lambda fn, jobs, w, ctx=None: enumerate(map(fn, jobs)))
    again = run_bounds(suite, cells, tmp_path, workers=2, progress=False)
    assert again["run"]["episodes_run"] == 1 and len(read_bounds(tmp_path / BOUNDS)) == 2
