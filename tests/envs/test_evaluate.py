"""`envs.evaluate` (aggregates, worker-count independence, report files) and the `crowdnav` CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from envs.cli import main
from envs.config import CrowdNavConfig
from envs.evaluate import aggregate, compare, evaluate, wilson_interval

REQUIRED_KEYS = {
    "policy", "scenario", "seed", "episodes", "config", "episode_list",
    "success_rate", "collision_rate", "timeout_rate", "group_intrusion_rate", "group_intrusion_rate_success",
    "success_rate_ci95", "collision_rate_ci95", "time_to_goal_s", "time_to_goal_median_s", "path_length_m",
    "min_distance_m", "min_distance_overall_m", "discomfort_frequency", "solve_time_p50_ms", "solve_time_p95_ms",
    "fallback_rate",
}
EPISODE_KEYS = {"seed", "outcome", "time_s", "path_length_m", "min_distance_m", "group_intrusion",
                "discomfort_frequency", "fallbacks", "plans"}
SMALL = CrowdNavConfig(n_pedestrians=8, time_limit_s=6.0)


def _rec(seed, outcome, ttg=None, path=10.0, mind=0.5, disc=0.0, intr=False, plans=10, fallbacks=0, times=()):
    return {"seed": seed, "outcome": outcome, "collision_with": "pedestrian" if outcome == "collision" else None,
            "steps": 100, "time_s": 10.0, "time_to_goal_s": ttg, "path_length_m": path, "min_distance_m": mind,
            "discomfort_frequency": disc, "group_intrusion": intr, "intrusion_fraction": 0.1 * intr,
            "plans": plans, "fallbacks": fallbacks, "solver_calls": len(times), "return": 1.0,
            "solve_times_ms": list(times)}


# ------------------------------------------------------------------------------------------- aggregates
def test_wilson_interval_known_values():
    lo, hi = wilson_interval(5, 10)
    assert lo == pytest.approx(0.2366, abs=1e-4) and hi == pytest.approx(0.7634, abs=1e-4)
    z2 = 1.959963984540054**2
    assert wilson_interval(0, 4) == pytest.approx([0.0, z2 / (4 + z2)])
    assert wilson_interval(4, 4) == pytest.approx([4 / (4 + z2), 1.0])
    assert wilson_interval(0, 0) is None


def test_aggregate_hand_made_records():
    records = [
        _rec(0, "success", ttg=10.0, path=12.0, mind=0.4, disc=0.1, intr=True, plans=10, fallbacks=1,
             times=range(1, 51)),
        _rec(1, "success", ttg=20.0, path=14.0, mind=0.2, disc=0.3, intr=False, plans=10, fallbacks=0,
             times=range(51, 101)),
        _rec(2, "success", ttg=60.0, path=22.0, mind=0.6, disc=0.2, intr=False, plans=10),
        _rec(3, "collision", path=5.0, mind=-0.1, disc=0.4, intr=True, plans=5, fallbacks=3),
        _rec(4, "timeout", path=99.0, mind=None, disc=0.0, intr=True, plans=5),  # nobody ever in the scene
    ]
    r = aggregate(records, "p", SMALL, seed=0)
    assert r["episodes"] == 5 and r["policy"] == "p" and r["scenario"] == "plaza" and r["seed"] == 0
    assert (r["success_rate"], r["collision_rate"], r["timeout_rate"]) == (0.6, 0.2, 0.2)
    assert r["group_intrusion_rate"] == pytest.approx(0.6)
    assert r["group_intrusion_rate_success"] == pytest.approx(1 / 3)
    assert r["success_rate_ci95"] == pytest.approx(wilson_interval(3, 5))
    assert r["collision_rate_ci95"] == pytest.approx(wilson_interval(1, 5))
    # over successes only
    assert r["time_to_goal_s"] == pytest.approx(30.0) and r["time_to_goal_median_s"] == pytest.approx(20.0)
    assert r["path_length_m"] == pytest.approx(16.0)
    # per-episode minima, the empty episode left out
    assert r["min_distance_m"] == pytest.approx((0.4 + 0.2 + 0.6 - 0.1) / 4)
    assert r["min_distance_overall_m"] == pytest.approx(-0.1)
    assert r["discomfort_frequency"] == pytest.approx(0.2)
    # every solver call of every episode: 1..100 ms
    assert r["solve_time_p50_ms"] == pytest.approx(50.5) and r["solve_time_p95_ms"] == pytest.approx(95.05)
    assert r["solver_calls"] == 100
    assert r["fallback_rate"] == pytest.approx(4 / 40)
    assert [e["seed"] for e in r["episode_list"]] == [0, 1, 2, 3, 4]
    assert "solve_times_ms" not in r["episode_list"][0]
    json.dumps(r, allow_nan=False)  # strict JSON
    assert r["config"]["n_pedestrians"] == 8 and r["config"]["time_limit_s"] == 6.0


def test_aggregate_without_successes_solver_or_plans():
    r = aggregate([_rec(0, "collision", plans=0), _rec(1, "timeout", plans=0)], "random", SMALL)
    assert r["success_rate"] == 0.0 and r["group_intrusion_rate_success"] is None
    assert r["time_to_goal_s"] is None and r["path_length_m"] is None and r["time_to_goal_median_s"] is None
    assert r["solve_time_p50_ms"] is None and r["solve_time_p95_ms"] is None
    assert r["fallback_rate"] is None
    with pytest.raises(ValueError, match="no episodes"):
        aggregate([], "p", SMALL)
    with pytest.raises(ValueError, match="outcome"):
        aggregate([_rec(0, "running")], "p", SMALL)


def test_compare_table_has_a_row_per_policy():
    a = aggregate([_rec(0, "success", ttg=5.0)], "alpha", SMALL, 0)
    b = aggregate([_rec(0, "collision")], "beta", SMALL, 0)
    table = compare([a, b])
    rows = [ln for ln in table.splitlines() if ln.startswith("| ")]
    assert len(rows) == 3 and rows[1].startswith("| alpha |") and rows[2].startswith("| beta |")
    assert "1.00 [" in rows[1] and "plaza" in table


# ------------------------------------------------------------------------------------------ evaluate()
def test_evaluate_invalid_arguments():
    with pytest.raises(ValueError, match="valid names"):
        evaluate("nope", SMALL, 1)
    with pytest.raises(ValueError, match="episodes"):
        evaluate("random", SMALL, 0)


def test_worker_count_does_not_change_results_and_files_are_written(tmp_path):
    one = evaluate("mpc-cv", SMALL, episodes=3, seed=5, workers=1, record=0, out_dir=None, progress=False)
    two = evaluate("mpc-cv", SMALL, episodes=3, seed=5, workers=2, record=1, out_dir=tmp_path, progress=False)
    assert one["episode_list"] == two["episode_list"]  # recording and drawing change nothing either
    assert [e["seed"] for e in two["episode_list"]] == [5, 6, 7]
    for key in ("success_rate", "collision_rate", "path_length_m", "min_distance_m", "fallback_rate", "plans"):
        assert one[key] == two[key]

    saved = json.loads((tmp_path / "mpc-cv.json").read_text())
    assert REQUIRED_KEYS <= set(saved)
    assert EPISODE_KEYS <= set(saved["episode_list"][0])
    assert saved["episodes"] == 3 and saved["policy"] == "mpc-cv" and saved["seed"] == 5
    assert saved["solve_time_p50_ms"] > 0 and saved["plans"] > 0
    assert (tmp_path / "mpc-cv.md").read_text().count("|") > 20
    assert (tmp_path / "mpc-cv.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rrd = tmp_path / "mpc-cv_seed5.rrd"
    assert rrd.stat().st_size > 1000
    assert not (tmp_path / "mpc-cv_seed6.rrd").exists()
    assert not list(tmp_path.glob(".*")), "temporary files left behind"


def test_recording_holds_the_episode(tmp_path):
    rr_chunk = pytest.importorskip("rerun.chunk")
    r = evaluate("social-force", SMALL, episodes=1, seed=2, workers=1, record=1, out_dir=tmp_path, draw=1,
                 progress=False)
    assert r["solve_time_p50_ms"] is None  # reactive: no solver
    steps = set()
    for chunk in rr_chunk.RrdReader(tmp_path / "social-force_seed2.rrd").stream():
        if str(chunk.entity_path) == "/world/robot":
            steps.update(chunk.to_record_batch().column("step").to_pylist())
    assert len(steps) == r["episode_list"][0]["steps"] + 1  # every frame, the last one included


# ------------------------------------------------------------------------------------------------ CLI
def test_cli_unknown_policy_exits_2_listing_names(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--policy", "mpc-cv", "teleport", "--episodes", "1"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "teleport" in err and "mpc-gpgraph" in err and "social-force" in err and "Traceback" not in err


def test_cli_unknown_scenario_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--policy", "random", "--scenario", "moon"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "moon" in err and "plaza" in err and "replay" in err
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--policy", "random", "--scenario", "replay"])
    assert exc.value.code == 2 and "--replay-file" in capsys.readouterr().err


def test_cli_lists(capsys):
    assert main(["policies"]) == 0
    assert "mpc-gpgraph" in capsys.readouterr().out.split()
    assert main(["scenarios"]) == 0
    assert {"plaza", "replay"} <= set(capsys.readouterr().out.split())


def test_cli_evaluate_writes_json(tmp_path, capsys):
    out = tmp_path / "res" / "random.json"
    code = main(["evaluate", "--policy", "random", "--scenario", "corridor", "--episodes", "2", "--seed", "3",
                 "--workers", "1", "--pedestrians", "6", "--time-limit", "4", "--invisible", "--record", "0",
                 "--json", str(out), "--out", str(tmp_path / "dir"), "--no-progress"])
    assert code == 0
    r = json.loads(out.read_text())
    assert REQUIRED_KEYS <= set(r)
    assert r["scenario"] == "corridor" and r["episodes"] == 2 and r["seed"] == 3
    assert r["config"]["n_pedestrians"] == 6 and r["config"]["robot_visible"] is False
    assert r["config"]["time_limit_s"] == 4.0
    assert r["solve_time_p50_ms"] is None and r["fallback_rate"] is None
    assert (tmp_path / "dir" / "random.md").exists() and (tmp_path / "dir" / "random.png").exists()
    assert "| success rate" in capsys.readouterr().out


def test_cli_evaluate_several_policies_writes_comparison(tmp_path, capsys):
    out = tmp_path / "all.json"
    code = main(["evaluate", "--policy", "random", "social-force", "--episodes", "1", "--workers", "1",
                 "--pedestrians", "4", "--time-limit", "3", "--record", "0", "--json", str(out),
                 "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    combined = json.loads(out.read_text())
    assert combined["policies"] == ["random", "social-force"]
    assert set(combined["results"]) == {"random", "social-force"}
    for name in ("comparison.md", "comparison.json", "comparison.png", "random.json", "social-force.json"):
        assert (tmp_path / name).stat().st_size > 0
    assert "| social-force |" in capsys.readouterr().out


def test_cli_replay_scenario(tmp_path):
    # two pedestrians walking across a 10 m square for 16 s (0.4 s annotation steps, 10 frame ids each)
    rows = []
    for k in range(41):
        rows.append(f"{10 * k}\t1\t{0.25 * k:.3f}\t2.0")
        rows.append(f"{10 * k}\t2\t{10 - 0.25 * k:.3f}\t8.0")
    traj = tmp_path / "rec.txt"
    traj.write_text("\n".join(rows) + "\n")
    groups = tmp_path / "groups.txt"
    groups.write_text("1 2\n")
    out = tmp_path / "replay.json"
    code = main(["evaluate", "--policy", "social-force", "--scenario", "replay", "--replay-file", str(traj),
                 "--groups-file", str(groups), "--episodes", "1", "--workers", "1", "--time-limit", "4",
                 "--record", "0", "--json", str(out), "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    r = json.loads(out.read_text())
    assert r["scenario"] == "replay" and r["config"]["replay_file"] == str(traj)
    assert r["config"]["n_pedestrians"] is None
    assert math.isfinite(r["episode_list"][0]["path_length_m"])
    assert np.isfinite(r["discomfort_frequency"])
