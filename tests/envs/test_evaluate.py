"""`envs.evaluation.evaluate` (aggregates, worker-count independence, report files) and the `crowdnav` CLI."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from envs.cli import main
from envs.config import CrowdNavConfig
from envs.evaluation.evaluate import evaluate
from envs.evaluation.report import compare
from envs.policies import ENV_MPC, PolicyConfig
from tests.cli_helpers import run_cli

REQUIRED_KEYS = {
    "policy", "predictor", "scenario", "seed", "episodes", "config", "episode_list",
    "success_rate", "collision_rate", "timeout_rate", "group_intrusion_rate", "group_intrusion_rate_success",
    "success_rate_ci95", "collision_rate_ci95", "time_to_goal_s", "time_to_goal_median_s", "path_length_m",
    "min_distance_m", "min_distance_overall_m", "discomfort_frequency", "solve_time_p50_ms", "solve_time_p95_ms",
    "fallback_rate",
}
EPISODE_KEYS = {"seed", "outcome", "time_s", "path_length_m", "min_distance_m", "group_intrusion",
                "discomfort_frequency", "fallbacks", "plans"}
SMALL = CrowdNavConfig(n_pedestrians=8, time_limit_s=6.0)


def _cli(args, capsys):
    """(exit code, stderr) of `crowdnav ARGS`."""
    return run_cli(main, args, capsys)


def test_compare_table_has_a_row_per_policy():
    a = evaluate("random", SMALL, episodes=1, seed=0, record=0, progress=False)
    b = evaluate("social-force", SMALL, episodes=1, seed=0, record=0, progress=False)
    table = compare([a, b])
    rows = [ln for ln in table.split("\n\n")[1].splitlines() if ln.startswith("| ")]
    assert len(rows) == 3 and rows[1].startswith("| random | none |") and rows[2].startswith("| social-force | none |")
    assert "plaza" in table and "| plaza | random vs social-force | 1 |" in table  # and the paired test


def _result(policy, outcomes):
    """An evaluation result of `policy` with one episode per outcome, seeds 0, 1, ... (what `compare` reads)."""
    from envs.evaluation.records import EpisodeRecord
    from envs.evaluation.stats import aggregate

    recs = [EpisodeRecord(policy=policy, seed=s, outcome=o, collision_with="pedestrian" if o == "collision" else None,
                          at_fault="robot" if o == "collision" else None, min_distance_m=0.5)
            for s, o in enumerate(outcomes)]
    return {"policy": policy, "predictor": None, "scenario": "plaza", "seed": 0, "config": {}, **aggregate(recs),
            "episode_list": [r.to_json() for r in recs]}


def test_comparison_has_the_exact_mcnemar_test_on_the_same_episodes():
    """a collides in none of 10 episodes, b in 7 (seeds 0-6), both time out in seeds 7-9: 7 discordant pairs, all
    on b's side, p = 2 / 2**7 = 0.0156 (significant); successes: none anywhere, p = 1, not tested."""
    from envs.evaluation.report import compare_json

    a = _result("mpc-a", ["success"] * 7 + ["timeout"] * 3)
    b = _result("mpc-b", ["collision"] * 7 + ["timeout"] * 3)
    (pair,) = compare_json([a, b])["paired"]
    assert (pair["policy_a"], pair["policy_b"], pair["pairs"]) == ("mpc-a", "mpc-b", 10)
    assert {k: pair["collision"][k] for k in ("a", "b", "a_only", "b_only", "tested", "significant")} == \
        {"a": 0, "b": 7, "a_only": 0, "b_only": 7, "tested": True, "significant": True}
    assert pair["collision"]["p_value"] == pytest.approx(2 / 2**7)
    assert pair["success"]["a_only"] == 7 and pair["success"]["p_value"] == pytest.approx(2 / 2**7)
    assert pair["group_intrusion"]["tested"] is False
    table = compare([a, b])
    assert "| plaza | mpc-a vs mpc-b | 10 | 0/7 (0, 7) | 0.0156 * | 0/7 (0, 7) | 0.0156 * | 7/0 (7, 0) | 0.0156 * |" \
        in table
    # the pairs are the same seeds: b's episodes in another order pair the same way; b on other seeds, no pairs
    shuffled = {**b, "episode_list": b["episode_list"][::-1]}
    assert compare_json([a, shuffled])["paired"] == compare_json([a, b])["paired"]
    other = _result("mpc-c", ["collision"] * 7)
    other["episode_list"] = [{**e, "seed": e["seed"] + 100} for e in other["episode_list"]]
    assert compare_json([a, other])["paired"][0]["pairs"] == 0


# ------------------------------------------------------------------------------------------ evaluate()
def test_evaluate_invalid_arguments():
    with pytest.raises(ValueError, match="valid names"):
        evaluate("nope", SMALL, 1)
    with pytest.raises(ValueError, match="episodes"):
        evaluate("random", SMALL, 0)


def test_worker_count_does_not_change_results_and_files_are_written(tmp_path):
    cv = PolicyConfig("mpc-cv", mpc=replace(ENV_MPC, time_budget_s=30.0))  # no load-dependent solver cut-off
    one = evaluate(cv, SMALL, episodes=3, seed=5, workers=1, record=0, out_dir=None, progress=False)
    two = evaluate(cv, SMALL, episodes=3, seed=5, workers=2, record=1, out_dir=tmp_path, progress=False)
    def timeless(episodes):
        return [{k: v for k, v in e.items() if k != "wall_time_s"} for e in episodes]

    assert timeless(one["episode_list"]) == timeless(two["episode_list"])  # recording and drawing change nothing
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
def test_cli_unknown_policy_exits_2_listing_names(capsys, tmp_path):
    code, err = _cli(["evaluate", "--policy", "mpc-cv", "teleport", "--episodes", "1", "--out", str(tmp_path / "o")],
                     capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "o").exists()
    assert "teleport" in err and "mpc-gpgraph" in err and "social-force" in err and "Traceback" not in err


def test_cli_unknown_scenario_exits_2(capsys):
    code, err = _cli(["evaluate", "--policy", "random", "--scenario", "moon"], capsys)
    assert code == 2 and "moon" in err and "plaza" in err and "replay" in err
    code, err = _cli(["evaluate", "--policy", "random", "--scenario", "replay"], capsys)
    assert code == 2 and "--replay-file" in err


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


TINY = ["--episodes", "1", "--workers", "1", "--record", "0", "--no-progress", "--pedestrians", "4",
        "--time-limit", "2"]


@pytest.mark.parametrize(("args", "needle"), [
    (["--policy", "random", "--predictor", "gpgraph-stgcnn-hotel"], "--predictor is ignored by random"),
    (["--policy", "social-force", "--mpc", "safety_margin_m=0.5"], "--mpc is ignored by social-force"),
    (["--policy", "social-force", "--samples", "5"], "--samples is ignored by social-force"),
    (["--policy", "mpc-cv", "--samples", "5"], "--samples is ignored by mpc-cv"),
    (["--policy", "mpc-cv", "mpc-none", "--threads", "2"], "--threads is ignored by mpc-cv, mpc-none"),
    (["--policy", "random", "social-force", "--replan-every", "3"], "--replan-every is ignored by random, social"),
    (["--policy", "mpc-cv", "--samples", "20"], "--samples is ignored"),  # given, even at its default value
    (["--policy", "mpc-cv", "--wall-rays", "8"], "--wall-rays is ignored by mpc-cv"),
    (["--policy", "random", "--backend", "ray", "--address", "auto", "--workers", "3"], "--workers is ignored"),
    (["--policy", "mpc-cv", "--mpc", "safety_margin=0.5"], "field 'safety_margin'; did you mean 'safety_margin_m'?"),
    (["--policy", "mpc-cv", "--mpc", "safety_margin_m=wide"], "not a float"),
    (["--policy", "mpc-cv", "--mpc", "safety_margin_m=-1"], "safety_margin_m"),
    (["--policy", "mpc-cv", "--mpc", "route=shortest"], "route is one of none, default"),
    (["--policy", "mpc-cv", "--mpc", "wall_margin_m=-0.1"], "wall_margin_m"),
    (["--policy", "mpc-cv", "--mpc", "safety_margin_m=none"], "not a float"),  # not optional
    (["--policy", "mpc-cv", "mpc-cv"], "named twice"),
    (["--policy", "mpc-gpgraph", "--samples", "0"], "--samples must be >= 1, got 0"),
    (["--policy", "random", "--address", "auto"], "--address needs --backend ray"),
    (["--policy", "random", "--invisible", "--scenario", "replay", "--replay-file", "x.txt"], "do not apply"),
    (["--policy", "random", "--frame-step", "0.6"], "need --scenario replay"),
    (["--policy", "nosuchmodule:make"], "cannot import"),
    (["--policy", "sb3:missing.zip"], "no such file"),
])
def test_cli_misuse_is_one_line_and_exit_2(args, needle, capsys, tmp_path):
    out = tmp_path / "never"
    code, err = _cli(["evaluate", *args, *TINY, "--out", str(out)], capsys)
    assert code == 2, err
    assert needle in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()


def test_cli_output_under_a_file_fails_before_any_episode(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, err = _cli(["evaluate", "--policy", "random", *TINY, "--out", str(blocker / "sub")], capsys)
    assert code == 2 and "file" in err and len(err.strip().splitlines()) == 1
    code, err = _cli(["evaluate", "--policy", "random", *TINY, "--out", str(tmp_path / "o"), "--json",
                      str(tmp_path)], capsys)
    assert code == 2 and "folder" in err and not (tmp_path / "o" / "random.json").exists()


def test_policy_flags_reach_the_results_json(tmp_path):
    code = main(["evaluate", "--policy", "mpc-cv", "--mpc", "safety_margin_m=0.45", "--replan-every", "2",
                 *TINY, "--out", str(tmp_path)])
    assert code == 0
    saved = json.loads((tmp_path / "mpc-cv.json").read_text())
    assert saved["policy_config"]["mpc"]["safety_margin_m"] == 0.45
    assert saved["policy_config"]["mpc"]["shield_horizon_s"] == 1.6  # the env's MPC, not the planner default
    assert saved["policy_config"]["replan_every_steps"] == 2


def test_optional_mpc_fields_take_none_and_the_route_takes_none_or_default():
    from envs.cli import build_parser
    from envs.cli_options import policy_configs
    from planner import RouteConfig

    args = build_parser().parse_args(["evaluate", "--policy", "mpc-cv", "--mpc", "wall_margin_m=none",
                                      "--mpc", "route=none"])
    (cv,) = policy_configs(args)
    assert cv.mpc.wall_margin_m is None and cv.mpc.route is None
    assert cv.mpc.wall_clearance_m == cv.mpc.robot.radius_m + cv.mpc.safety_margin_m  # the margin before 2026-11-25
    args = build_parser().parse_args(["evaluate", "--policy", "mpc-cv", "--mpc", "wall_margin_m=0.1",
                                      "--mpc", "route=default"])
    (cv,) = policy_configs(args)
    assert cv.mpc.wall_margin_m == 0.1 and cv.mpc.route == RouteConfig()
    with pytest.raises(ValueError, match="route is one of none, default"):
        policy_configs(build_parser().parse_args(["evaluate", "--policy", "mpc-cv", "--mpc", "route=left"]))
    with pytest.raises(ValueError, match="did you mean"):  # removed 2026-11-28 (docs/decisions/planner-settings.md)
        policy_configs(build_parser().parse_args(["evaluate", "--policy", "mpc-cv", "--mpc", "lane=default"]))


def _parsed_mpc(*items: str):
    """The MPCConfig `crowdnav evaluate --policy mpc-cv --mpc ITEM ...` runs."""
    from envs.cli import build_parser
    from envs.cli_options import policy_configs

    return policy_configs(build_parser().parse_args(
        ["evaluate", "--policy", "mpc-cv", *(a for item in items for a in ("--mpc", item))]))[0].mpc


def test_a_nested_config_field_is_set_by_its_dotted_name():
    from planner import ForesightConfig

    parse = _parsed_mpc
    mpc = parse("foresight.horizon_s=6", "foresight.lead_s=1.2")
    assert mpc.foresight == ForesightConfig(horizon_s=6.0, lead_s=1.2)  # the second item kept the first
    assert parse("foresight=default").foresight == ForesightConfig() and parse().foresight is None
    with pytest.raises(ValueError, match="horizon_s"):  # the nested config's own check
        parse("foresight.horizon_s=-1")
    with pytest.raises(ValueError, match="did you mean"):
        parse("foresight.horizon=6")
    with pytest.raises(ValueError, match="did you mean"):
        parse("foresigt.horizon_s=6")
    with pytest.raises(ValueError, match="is not a float"):
        parse("foresight.horizon_s=far")
    assert parse("foresight.retry_without_margin=0").foresight.retry_without_margin is False  # as FIELD=VALUE reads
    with pytest.raises(ValueError, match="is not a bool"):
        parse("foresight.retry_without_margin=maybe")
    with pytest.raises(ValueError, match="cannot set"):
        parse("guidance.heading_offsets_deg=10")


def test_the_cost_weights_are_set_one_field_at_a_time_on_the_envs_own():
    from envs.policies import ENV_MPC

    parse = _parsed_mpc
    assert parse().weights == ENV_MPC.weights
    mpc = parse("weights.social=0.2", "weights.goal=2")
    assert mpc.weights == replace(ENV_MPC.weights, social=0.2, goal=2.0)  # the others stay the env's
    with pytest.raises(ValueError, match="must be >= 0"):  # CostWeights' own check
        parse("weights.social=-1")
    with pytest.raises(ValueError, match="did you mean"):
        parse("weights.socal=0")
    with pytest.raises(ValueError, match="one field at a time"):  # no whole-config form
        parse("weights=default")


def test_every_registry_policy_states_the_flags_it_reads():
    from envs.cli_options import FLAG_FIELDS, POLICY_FLAGS
    from envs.policies import POLICIES, PREDICTOR_POLICIES

    assert set(POLICY_FLAGS) == set(POLICIES)  # a new policy must say which flags it reads
    assert all(set(flags) <= set(FLAG_FIELDS) for flags in POLICY_FLAGS.values())
    assert {n for n, flags in POLICY_FLAGS.items() if "--predictor" in flags} == set(PREDICTOR_POLICIES)


def test_a_flag_applies_to_the_policies_that_read_it_and_the_others_keep_their_defaults():
    from envs.cli import build_parser
    from envs.cli_options import policy_configs

    args = build_parser().parse_args(["evaluate", "--policy", "mpc-gpgraph", "mpc-cv", "social-force",
                                      "--samples", "5", "--replan-every", "3", "--mpc", "safety_margin_m=0.45"])
    gp, cv, sf = policy_configs(args)
    assert (gp.n_samples, gp.replan_every_steps, gp.mpc.safety_margin_m) == (5, 3, 0.45)
    assert (cv.n_samples, cv.replan_every_steps, cv.mpc.safety_margin_m) == (20, 3, 0.45)
    assert sf == PolicyConfig("social-force")  # what its results JSON records: the settings it ran with
    plain = build_parser().parse_args(["evaluate", "--policy", "mpc-cv"])
    assert policy_configs(plain) == [PolicyConfig("mpc-cv")]  # no flag given: the defaults (and their fingerprints)


def test_no_recording_unless_asked(tmp_path):
    """A plaza recording is ~11 MB per episode: `crowdnav evaluate` and `evaluate()` record none by default."""
    import inspect

    from envs.cli import build_parser

    assert build_parser().parse_args(["evaluate", "--policy", "random"]).record == 0
    assert inspect.signature(evaluate).parameters["record"].default == 0
    code = main(["evaluate", "--policy", "random", "--episodes", "2", "--workers", "1", "--no-progress",
                 "--pedestrians", "4", "--time-limit", "2", "--out", str(tmp_path)])
    assert code == 0 and (tmp_path / "random.json").is_file()
    assert not list(tmp_path.rglob("*.rrd"))
    assert json.loads((tmp_path / "random.json").read_text())["run"]["files"] == ["random.json", "random.md",
                                                                                   "random.png"]


def test_demo_still_writes_its_one_recording(tmp_path, monkeypatch, capsys):
    """`crowdnav demo`'s documented output includes demo.rrd (one episode), whatever evaluate's default. The
    demo's episodes are swapped for one small random one here; the recording request is the demo's own."""
    pytest.importorskip("rerun")
    import envs.evaluation.evaluate as evaluate_module

    real, asked = evaluate_module.evaluate, []

    def small(policy, config, episodes, seed, workers, record, out, **kw):
        asked.append(record)
        return real("random", SMALL, 1, seed, 1, record, out, **kw)

    monkeypatch.setattr(evaluate_module, "evaluate", small)
    assert main(["demo", "--out", str(tmp_path), "--episodes", "1", "--workers", "1", "--no-progress"]) == 0
    assert asked == [1] and [p.name for p in tmp_path.glob("*.rrd")] == ["demo.rrd"]
    assert (tmp_path / "demo.rrd").stat().st_size > 1000


def _replay_args(*extra):
    from envs.cli import build_parser

    return build_parser().parse_args(["evaluate", "--scenario", "replay", *extra])


def test_replay_of_a_known_test_recording_picks_the_scenes_leave_one_out_predictor():
    """As crowdnav-v1's real cells do: mpc-gpgraph on biwi_hotel.txt predicts with the hotel leave-one-out model;
    an explicit --predictor wins (`{scene}` filled in); an unknown file keeps the default, and the line says so."""
    from envs.cli_options import policy_configs, replay_predictors
    from envs.config import DEFAULT_PREDICTOR

    def run(*extra):
        args = _replay_args(*extra)
        return replay_predictors(args, policy_configs(args))

    configs, note = run("--replay-file", "d/hotel/test/biwi_hotel.txt", "--policy", "mpc-gpgraph", "mpc-cv")
    assert [p.predictor_used() for p in configs] == ["gpgraph-stgcnn-hotel+coherent-motion", None]
    assert "scene hotel" in note and "mpc-gpgraph predicts with gpgraph-stgcnn-hotel+coherent-motion" in note
    assert "--predictor NAME overrides" in note
    configs, note = run("--replay-file", "biwi_hotel.txt", "--policy", "mpc-gpgraph", "--predictor", "stgcnn-eth")
    assert configs[0].predictor == "stgcnn-eth" and "overrides" not in note
    configs, _ = run("--replay-file", "crowds_zara02.txt", "--policy", "mpc-gpgraph", "--predictor",
                     "gpgraph-sgcn-{scene}")
    assert configs[0].predictor == "gpgraph-sgcn-zara2"
    configs, note = run("--replay-file", "my_walk.txt", "--policy", "mpc-gpgraph")
    assert configs[0].predictor_used() == DEFAULT_PREDICTOR and "no known ETH/UCY test recording" in note
    assert run("--replay-file", "biwi_hotel.txt", "--policy", "mpc-cv") == ([PolicyConfig("mpc-cv")], None)


@pytest.mark.slow
def test_cli_replay_reports_name_the_predictor(tmp_path, capsys):
    from predictor.ethucy import DEFAULT_DATA_DIR

    hotel = DEFAULT_DATA_DIR / "hotel/test/biwi_hotel.txt"
    if not hotel.is_file():
        pytest.skip("../shared/datasets is not here")
    args = ["evaluate", "--policy", "mpc-gpgraph", "mpc-cv", "--scenario", "replay", "--replay-file", str(hotel),
            "--episodes", "1", "--time-limit", "2", "--workers", "1", "--no-progress", "--out", str(tmp_path)]
    assert main(args) == 0
    assert "mpc-gpgraph predicts with gpgraph-stgcnn-hotel+coherent-motion" in capsys.readouterr().out
    result = json.loads((tmp_path / "mpc-gpgraph.json").read_text())
    assert result["predictor"] == "gpgraph-stgcnn-hotel+coherent-motion"
    assert "| predictor | gpgraph-stgcnn-hotel+coherent-motion |" in (tmp_path / "mpc-gpgraph.md").read_text()
    assert "| predictor | none |" in (tmp_path / "mpc-cv.md").read_text()
    both = json.loads((tmp_path / "comparison.json").read_text())
    assert both["predictors"] == {"mpc-gpgraph": "gpgraph-stgcnn-hotel+coherent-motion", "mpc-cv": None}
    assert "| mpc-gpgraph | gpgraph-stgcnn-hotel+coherent-motion |" in (tmp_path / "comparison.md").read_text()
