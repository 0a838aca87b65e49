"""Benchmark suites: fixed seeds, the same episodes for every policy, resumable records, merging, leaderboard."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from envs.cli import main
from envs.evaluation.benchmark import RECORDS, plan_benchmark, run_benchmark
from envs.evaluation.records import EpisodeRecord, RecordStore, merge_records, read_records
from envs.evaluation.suite import load_suite, parse_suite, suite_names
from envs.policies import ENV_MPC, PolicyConfig

TINY = {"name": "tiny", "version": 1, "description": "test", "defaults": {"time_limit_s": 2.0},
        "cells": [{"name": "corridor-a", "scenario": "corridor", "n_pedestrians": 4, "robot_visible": True,
                   "episodes": 3, "seed0": 7},
                  {"name": "circle-b", "scenario": "circle_crossing", "n_pedestrians": 3, "robot_visible": False,
                   "episodes": 2, "seed0": 0}]}
POLICIES = [PolicyConfig("random"), PolicyConfig("social-force")]


def _untimed(board):
    """The pooled summaries without the wall-clock solve times (which differ between any two runs)."""
    return {pool: {name: {k: v for k, v in res.items() if not k.startswith("solve_time")}
                   for name, res in by_policy.items()} for pool, by_policy in board["pooled"].items()}


def _strip(records):
    return sorted((r.key, replace(r, wall_time_s=0.0, solve_times_ms=())) for r in records)


def test_shipped_suites_parse_and_unknown_names_list_the_valid_ones():
    assert {"crowdnav-v1", "smoke"} <= set(suite_names())
    with pytest.raises(ValueError, match=r"valid names: .*crowdnav-v1"):
        load_suite("nope")
    with pytest.raises(ValueError, match=r"valid names: .*real-eth"):
        load_suite("crowdnav-v1").select(["real-mars"])


def test_v1_has_the_real_recordings_at_their_frame_rate_and_the_synthetic_grid():
    suite = load_suite("crowdnav-v1")
    real = {c.name: c for c in suite.cells if c.is_real}
    assert set(real) == {"real-eth", "real-hotel", "real-univ", "real-zara1", "real-zara2"}
    assert all(len(c.seeds) >= 50 for c in real.values())
    assert real["real-eth"].spec["frame_step_s"] == pytest.approx(0.6667, abs=1e-3)  # 6 frames at 2.5 fps... x 10/6
    assert all(c.spec["frame_step_s"] == 0.4 for n, c in real.items() if n != "real-eth")
    synth = [c for c in suite.cells if not c.is_real]
    keys = {(c.spec["scenario"], c.spec["robot_visible"]) for c in synth}
    assert {s for s, _ in keys} == {"plaza", "circle_crossing", "corridor", "crossing", "bottleneck"}
    for scenario in {s for s, _ in keys}:
        sizes = sorted({c.spec["n_pedestrians"] for c in synth if c.spec["scenario"] == scenario})
        assert len(sizes) == 2 and sizes[0] < sizes[1]  # a low and a high density
        assert {v for s, v in keys if s == scenario} == {True, False}


def test_malformed_suites_are_rejected():
    with pytest.raises(ValueError, match="missing key"):
        parse_suite({**TINY, "cells": [{"name": "x", "episodes": 1, "seed0": 0}]})
    with pytest.raises(ValueError, match="unknown key"):
        parse_suite({**TINY, "cells": [{**TINY["cells"][0], "pedestrians": 3}]})
    with pytest.raises(ValueError, match="unknown default"):
        parse_suite({**TINY, "defaults": {"time_limit": 3}})


def test_every_policy_meets_the_same_episodes(tmp_path):
    suite = parse_suite(TINY)
    plan = plan_benchmark(suite, suite.cells, POLICIES, tmp_path)
    by_policy = {}
    for t in plan.tasks:
        by_policy.setdefault(t.policy.name, []).append((t.cell, t.seed, t.env))
    assert by_policy["random"] == by_policy["social-force"]
    assert [s for c, s, _ in by_policy["random"] if c == "corridor-a"] == [7, 8, 9]


@pytest.mark.slow
def test_killed_run_resumes_without_redoing_episodes_and_matches_one_shot(tmp_path):
    suite = parse_suite(TINY)
    one = run_benchmark(suite, suite.cells, POLICIES, tmp_path / "one", progress=False)
    assert one["run"]["episodes_run"] == 10
    # a "killed" run: only the first cell finished, and a half-written line at the end of the file
    part = tmp_path / "part"
    run_benchmark(suite, suite.select(["corridor-a"]), POLICIES, part, progress=False)
    with open(part / RECORDS, "a") as f:
        f.write('{"policy": "random", "seed": 0, "outc')
    resumed = run_benchmark(suite, suite.cells, POLICIES, part, progress=False)
    assert resumed["run"]["episodes_run"] == 4 and resumed["run"]["episodes_resumed"] == 6
    assert _strip(read_records(part / RECORDS)) == _strip(read_records(tmp_path / "one" / RECORDS))
    assert _untimed(resumed) == _untimed(one)
    again = run_benchmark(suite, suite.cells, POLICIES, part, progress=False)
    assert again["run"]["episodes_run"] == 0


@pytest.mark.slow
def test_records_from_two_machines_merge_into_one_leaderboard(tmp_path):
    suite = parse_suite(TINY)
    run_benchmark(suite, suite.select(["corridor-a"]), POLICIES, tmp_path / "a", progress=False)
    run_benchmark(suite, suite.select(["circle-b"]), POLICIES, tmp_path / "b", progress=False)
    board = run_benchmark(suite, suite.cells, POLICIES, tmp_path / "c", progress=False,
                          merge=[tmp_path / "a" / RECORDS, tmp_path / "b" / RECORDS])
    assert board["run"]["episodes_run"] == 0  # everything came from the merged files
    assert board["pooled"]["synthetic"]["random"]["episodes"] == 5
    md = (tmp_path / "c" / "leaderboard.md").read_text()
    assert "| corridor-a |" in md and "| circle-b |" in md and "McNemar" in md
    assert (tmp_path / "c" / "leaderboard.png").read_bytes()[:4] == b"\x89PNG"
    saved = json.loads((tmp_path / "c" / "leaderboard.json").read_text())
    assert saved["policies"]["social-force"]["name"] == "social-force"
    assert {c["policy_a"] for c in saved["paired"]["synthetic"]} == {"random"}


def test_records_under_other_settings_refuse_to_merge(tmp_path):
    a = EpisodeRecord(policy="p", seed=1, outcome="success", cell="c", fingerprint="aaa")
    b = replace(a, fingerprint="bbb")
    with pytest.raises(ValueError, match="different settings"):
        merge_records([[a], [b]])
    store = RecordStore(tmp_path / RECORDS)
    store.append(replace(a, cell="corridor-a", policy="random", seed=7))
    suite = parse_suite(TINY)
    with pytest.raises(ValueError, match="other settings"):
        plan_benchmark(suite, suite.cells, POLICIES, tmp_path, recorded=store.read())


def test_records_made_with_other_weights_under_the_same_name_are_refused(tmp_path):
    """Retrained weights behind an unchanged predictor name or path change the fingerprint (envs.policies.identity)."""
    import shutil

    from envs.evaluation.benchmark import episode_fingerprint
    from envs.policies.identity import artifact_digest, artifact_files
    from predictor.checkpoint import PACKAGE_CHECKPOINTS

    weights = tmp_path / "model.safetensors"
    shutil.copy(PACKAGE_CHECKPOINTS / "gpgraph-stgcnn-univ.safetensors", weights)
    suite = parse_suite(TINY)
    pcfg = PolicyConfig("mpc-gpgraph", predictor=str(weights))
    assert artifact_files(pcfg) == [weights] and artifact_digest(PolicyConfig("mpc-cv")) is None
    assert artifact_files(PolicyConfig("mpc-gpgraph"))[0].name == "gpgraph-stgcnn-synthetic.safetensors"
    ruled = PolicyConfig("mpc-gpgraph", predictor=f"{weights}+coherent-motion")  # NAME+RULE: NAME's weights
    assert artifact_files(ruled) == [weights]
    cell = suite.cells[0]
    assert episode_fingerprint(suite, cell, ruled) != episode_fingerprint(suite, cell, pcfg)  # the rule counts
    old = EpisodeRecord(policy="mpc-gpgraph", seed=7, outcome="success", cell=cell.name,
                        fingerprint=episode_fingerprint(suite, cell, pcfg))
    plan = plan_benchmark(suite, [cell], [pcfg], tmp_path, recorded=[old])
    assert len(plan.done) == 1  # the same weights resume
    weights.write_bytes(weights.read_bytes()[:-8] + bytes(8))  # "retrained": other bytes, same path
    with pytest.raises(ValueError, match="other settings"):
        plan_benchmark(suite, [cell], [pcfg], tmp_path, recorded=[old])
    # policies that load no weights keep the fingerprint they had before digests existed
    from envs.evaluation.episode import fingerprint
    from envs.policies.identity import LATER_MPC_FIELDS, REMOVED_MPC_FIELDS
    plain = PolicyConfig("random")
    before = plain.to_json()
    for later in LATER_MPC_FIELDS:  # added to MPCConfig later, left out at their defaults
        before["mpc"].pop(later)
    before["mpc"].update(REMOVED_MPC_FIELDS)  # removed from MPCConfig later, put back at their defaults
    assert episode_fingerprint(suite, cell, plain) == fingerprint(suite.name, suite.version, cell.spec,
                                                                  cell.defaults, before)


def test_a_record_made_before_the_latest_planner_fields_still_resumes():
    """The fingerprint of a crowdnav-v1 v7 mpc-oracle episode recorded on 2026-11-28 before MPCConfig.n_starts
    existed (the foresight ladder's records, `--mpc time_budget_s=10`): any field added to MPCConfig later must be
    listed in LATER_MPC_FIELDS, or every earlier record would stop resuming and merging."""
    from dataclasses import replace as _replace

    from envs.evaluation.benchmark import episode_fingerprint
    from envs.evaluation.suite import load_suite
    from envs.policies.registry import ENV_MPC

    suite = load_suite("crowdnav-v1")
    cell = next(c for c in suite.cells if c.name == "plaza-low-invisible")
    pcfg = PolicyConfig("mpc-oracle", mpc=_replace(suite.mpc_config(ENV_MPC), time_budget_s=10.0))
    assert episode_fingerprint(suite, cell, pcfg) == "a6cc028e0ee80bc8"


def test_removing_the_layers_not_adopted_kept_every_fingerprint():
    """The fingerprints of these configs, computed at b01ea5a, before the layers tried and not adopted left MPCConfig
    (docs/decisions/planner-settings.md, "Removed layers"): REMOVED_MPC_FIELDS puts their default values back, so
    every record made while they existed still resumes and merges."""
    from dataclasses import fields
    from dataclasses import replace as _replace

    from envs.evaluation.benchmark import episode_fingerprint
    from envs.evaluation.suite import load_suite
    from envs.policies.identity import REMOVED_MPC_FIELDS
    from envs.policies.registry import ENV_MPC
    from planner import GuidanceConfig, MPCConfig

    assert not set(REMOVED_MPC_FIELDS) & {f.name for f in fields(MPCConfig)}
    suite = load_suite("crowdnav-v1")
    cell = next(c for c in suite.cells if c.name == "plaza-low-invisible")
    pinned = [
        (PolicyConfig("mpc-cv"), "85ab016336c7b17e"),
        (PolicyConfig("mpc-gpgraph"), "fbd7eb8330090683"),
        (PolicyConfig("random"), "02c2adb228459bf0"),
        (PolicyConfig("random+shield"), "575bc8487bd92fb3"),
        (PolicyConfig("mpc-oracle", mpc=suite.mpc_config(ENV_MPC)), "9cbb75a6e76294d3"),
        (PolicyConfig("mpc-cv", mpc=_replace(ENV_MPC, guidance=GuidanceConfig(), n_starts=2)), "a808e0e3e8f70e7a"),
    ]
    for pcfg, expected in pinned:
        assert episode_fingerprint(suite, cell, pcfg) == expected, pcfg.name


def test_record_store_skips_a_partial_line_and_appends_after_it(tmp_path):
    store = RecordStore(tmp_path / RECORDS)
    r = EpisodeRecord(policy="p", seed=1, outcome="collision", cell="c", at_fault="spawn",
                      solve_times_ms=(1.5, 2.25))
    store.append(r)
    with open(store.path, "a") as f:
        f.write('{"policy": "p", "se')
    assert store.read() == [r]
    store.append(replace(r, seed=2))
    assert [x.seed for x in store.read()] == [1, 2]
    with open(store.path, "a") as f:
        f.write("not json\n")
    with pytest.raises(ValueError, match=r"records.jsonl:3"):
        store.read()


# a record line as written before the at_fault rename (the field was called collision_kind)
OLD_LINE = ('{"policy":"mpc-cv","seed":3,"outcome":"collision","cell":"real-hotel","collision_with":"pedestrian",'
            '"collision_kind":"pedestrian","collision_time_s":4.2,"steps":42,"time_s":4.2,"time_to_goal_s":null,'
            '"path_length_m":3.1,"min_distance_m":-0.05,"discomfort_frequency":0.2,"group_intrusion":false,'
            '"intrusion_fraction":0.0,"spawn_contacts":0,"plans":42,"fallbacks":0,"ret":-1.5,"wall_time_s":2.0,'
            '"error":null,"fingerprint":"0123456789abcdef","solve_times_ms":[1.5,2.0]}')


def test_records_written_with_collision_kind_load_as_at_fault(tmp_path):
    from envs.evaluation.stats import aggregate

    path = tmp_path / RECORDS
    path.write_text(OLD_LINE + "\n")
    [r] = read_records(path)
    assert r.at_fault == "pedestrian" and r.collision_with == "pedestrian" and r.avoidable_collision
    assert (r.cell, r.policy, r.seed, r.fingerprint) == ("real-hotel", "mpc-cv", 3, "0123456789abcdef")
    assert aggregate([r])["collisions_at_fault_pedestrian"] == 1
    RecordStore(path).append(replace(r, seed=4))  # new lines use the new name
    last = json.loads(path.read_text().splitlines()[-1])
    assert last["at_fault"] == "pedestrian" and "collision_kind" not in last
    assert [x.at_fault for x in read_records(path)] == ["pedestrian", "pedestrian"]
    with pytest.raises(ValueError, match="both"):
        EpisodeRecord.from_json({**json.loads(OLD_LINE), "at_fault": "robot"})


def test_a_folder_written_before_the_rename_resumes_to_the_same_leaderboard(tmp_path):
    suite = parse_suite(TINY)
    cells = suite.select(["corridor-a"])
    new = run_benchmark(suite, cells, POLICIES, tmp_path, progress=False)
    path = tmp_path / RECORDS
    text = path.read_text()
    assert text.count('"at_fault"') == 6
    path.write_text(text.replace('"at_fault"', '"collision_kind"'))  # as the old code wrote it
    old = run_benchmark(suite, cells, POLICIES, tmp_path, progress=False)
    assert old["run"]["episodes_run"] == 0 and old["run"]["episodes_resumed"] == 6
    assert _untimed(old) == _untimed(new)


def test_cli_benchmark_misuse_is_one_line(tmp_path, capsys):
    for args, needle in ((["--suite", "nope"], "valid names"),
                         (["--suite", "smoke", "--cells", "real-mars"], "valid names"),
                         (["--suite", "smoke", "--policy", "teleport"], "valid names"),
                         (["--suite", "smoke", "--data", str(tmp_path / "none")], "not found"),
                         (["--suite", "smoke", "--policy", "mpc-cv+shield"], "already"),
                         (["--suite", "smoke", "--policy", "random+shield+route"], "in the order"),
                         (["--suite", "smoke", "--policy", "random+shield", "--mpc", "shield_horizon_s=0"],
                          "shield_horizon_s > 0"),
                         (["--suite", "smoke", "--policy", "random+route", "--mpc", "route=none"], "needs")):
        code = main(["benchmark", *args, "--out", str(tmp_path / "o"), "--no-progress"])
        err = capsys.readouterr().err
        assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, (args, err)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.xdist_group("crowdsim-parallel")  # one xdist worker for every test that starts Ray or a pool
def test_ray_backend_gives_the_same_records_as_the_process_pool(tmp_path):
    ray = pytest.importorskip("ray")
    suite = parse_suite(TINY)
    cells = suite.select(["corridor-a"])
    # no wall-clock budget: a solve cut short by machine load would fall back and change the episode
    pols = [PolicyConfig("mpc-cv", mpc=replace(ENV_MPC, time_budget_s=30.0)), PolicyConfig("random")]
    local = run_benchmark(suite, cells, pols, tmp_path / "local", workers=2, progress=False)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        remote = run_benchmark(suite, cells, pols, tmp_path / "ray", workers=2, backend="ray", progress=False)
    finally:
        ray.shutdown()
    assert remote["run"]["backend"] == "ray"
    assert _strip(read_records(tmp_path / "ray" / RECORDS)) == _strip(read_records(tmp_path / "local" / RECORDS))
    a, b = _untimed(remote), _untimed(local)
    differ = [(pool, pol, k, a[pool][pol][k], b[pool][pol][k]) for pool in b for pol in b[pool] for k in b[pool][pol]
              if a[pool][pol][k] != b[pool][pol][k]]
    assert not differ


def test_cli_benchmark_runs_a_suite_and_resumes(tmp_path, capsys):
    args = ["benchmark", "--suite", "smoke", "--cells", "corridor-low-visible", "--policy", "random",
            "--out", str(tmp_path), "--workers", "1", "--no-progress"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "Leaderboard: suite smoke v7" in out and "| corridor-low-visible |" in out
    assert "2 episodes run, 0 already recorded" in out
    assert len(read_records(tmp_path / RECORDS)) == 2
    assert main(args) == 0
    assert "0 episodes run, 2 already recorded" in capsys.readouterr().out
    assert main(["suites"]) == 0
    assert "crowdnav-v1 v7: " in capsys.readouterr().out


def test_real_cells_give_mpc_gpgraph_the_scenes_leave_one_out_predictor(tmp_path):
    """In crowdnav-v1 (version 2 on) a real cell runs mpc-gpgraph with the ETH/UCY checkpoint that never saw its
    scene, a synthetic cell with the default; an explicit predictor wins, and `{scene}` is filled per cell."""
    from envs.policies import make_policy
    from predictor.checkpoint import PACKAGE_CHECKPOINTS
    from predictor.group_rules import split_group_rule

    def available(spec):  # NAME+RULE: NAME's weights are packaged, the rule is registered
        return (PACKAGE_CHECKPOINTS / f"{split_group_rule(spec)[0]}.safetensors").is_file()

    suite = load_suite("crowdnav-v1")
    cells = suite.select(["real-hotel", "plaza-low-visible"])
    real = suite.cell("real-hotel")
    assert real.predictor == "gpgraph-stgcnn-hotel+coherent-motion" and available(real.predictor)
    assert all(available(c.predictor) for c in suite.cells if c.is_real)
    policies = [PolicyConfig("mpc-gpgraph"), PolicyConfig("mpc-cv")]
    plan = plan_benchmark(suite, cells, policies, tmp_path)
    by = {(t.cell, t.policy.name): t.policy for t in plan.tasks}
    assert by["real-hotel", "mpc-gpgraph"].predictor == "gpgraph-stgcnn-hotel+coherent-motion"
    assert by["plaza-low-visible", "mpc-gpgraph"].predictor is None  # the shipped synthetic default
    assert by["real-hotel", "mpc-cv"].predictor is None
    explicit = PolicyConfig("mpc-gpgraph", predictor="gpgraph-sgcn-{scene}")
    plan = plan_benchmark(suite, cells, [explicit], tmp_path)
    assert {t.cell: t.policy.predictor for t in plan.tasks} == {"real-hotel": "gpgraph-sgcn-hotel",
                                                               "plaza-low-visible": "gpgraph-sgcn-synthetic"}
    with pytest.raises(ValueError, match="per cell"):
        make_policy(explicit, plan.tasks[0].env)


def test_cli_data_default_is_the_suites_default_data_folder():
    from envs import cli
    from envs.evaluation import suite as suite_module

    args = cli.build_parser().parse_args(["benchmark", "--suite", "smoke", "--out", "x"])
    assert args.data is suite_module.DEFAULT_DATA


def test_an_episode_recorded_as_an_error_is_retried_on_resume_and_the_exit_says_so(tmp_path, capsys):
    suite = parse_suite(TINY)
    cells = suite.select(["circle-b"])
    out = tmp_path / "bench"
    first = run_benchmark(suite, cells, POLICIES, out, progress=False)
    assert first["run"]["errors"] == 0
    good = read_records(out / RECORDS)
    victim = next(r for r in good if r.policy == "social-force" and r.seed == 1)
    failed = replace(victim, outcome="error", error="RuntimeError: worker process died twice", steps=0)
    RecordStore(out / "failed.jsonl").append(failed)  # the same episode as an earlier run recorded it: an error
    others = [r for r in good if r.key != victim.key]
    (out / RECORDS).unlink()
    for r in [failed, *others]:
        RecordStore(out / RECORDS).append(r)
    assert [t.seed for t in plan_benchmark(suite, cells, POLICIES, out, recorded=read_records(out / RECORDS)).todo] \
        == [victim.seed]  # only the failed episode is run again
    again = run_benchmark(suite, cells, POLICIES, out, progress=False)
    assert again["run"]["episodes_run"] == 1 and again["run"]["errors"] == 0
    assert _untimed(again) == _untimed(first)  # its result replaced the error: the same leaderboard as before
    assert merge_records([[failed], [victim]]) == [victim] and merge_records([[victim], [failed]]) == [victim]


def test_an_mpc_field_added_later_stays_out_of_the_fingerprint_at_its_default():
    """Records made before `MPCConfig.guidance` existed still resume: at its default the field is not fingerprinted;
    set, it is. A field removed later (`lane`, which predates the v7 records) is fingerprinted at its old default;
    `spacetime`, added and removed since, is in none."""
    from envs.policies.identity import policy_identity
    from planner import GuidanceConfig

    plain = policy_identity(PolicyConfig("mpc-cv"))[0]["mpc"]
    assert "guidance" not in plain and "spacetime" not in plain and plain["lane"] is None
    guided = policy_identity(PolicyConfig("mpc-cv", mpc=replace(ENV_MPC, guidance=GuidanceConfig())))[0]["mpc"]
    assert guided["guidance"] is not None


def test_smoke_routes_fit_in_its_episodes():
    """Smoke v6's 8 s episodes ended before anyone could arrive (15 m and 12 m routes at 1.2 m/s): every route of
    every smoke episode must now be drivable at full speed within two thirds of the time limit."""
    from envs.env import CrowdNavEnv
    from envs.evaluation.suite import DEFAULT_DATA

    suite = load_suite("smoke")
    cells = [c for c in suite.cells if not c.is_real or all(f.is_file() for f in c.files(DEFAULT_DATA))]
    assert len(cells) >= 2
    for cell in cells:
        for seed in cell.seeds:
            env = CrowdNavEnv(cell.env_config(seed))
            env.reset(seed=seed)
            route_m = float(((env.goal - env.robot_state[:2]) ** 2).sum() ** 0.5)
            assert route_m / env.config.robot.max_speed_mps < 2 / 3 * env.config.time_limit_s, (cell.name, seed)


@pytest.mark.slow
def test_in_the_smoke_suite_mpc_cv_reaches_its_goal(tmp_path):
    """The smoke suite is a first look that can show a difference: mpc-cv arrives in at least one simulated
    episode (SPL above 0), where v6 gave success 0.00 and SPL 0.000 to every policy."""
    suite = load_suite("smoke")
    cells = [c for c in suite.cells if not c.is_real]
    board = run_benchmark(suite, cells, [PolicyConfig("mpc-cv")], tmp_path, workers=1, progress=False)
    res = board["pooled"]["synthetic"]["mpc-cv"]
    assert res["completed"] == 4 and res["success_rate"] > 0 and res["spl"] > 0


def test_a_known_test_recording_maps_to_its_suite_cell_and_every_leaderboard_names_its_predictors():
    """`recording_cell` is crowdnav-v1's own mapping (file -> real cell -> scene, leave-one-out predictor), and the
    leaderboard (json and md) names each policy's predictor per cell, the shipped default included."""
    from envs.config import DEFAULT_PREDICTOR
    from envs.evaluation.leaderboard import leaderboard, leaderboard_markdown
    from envs.evaluation.suite import recording_cell

    v1 = load_suite("crowdnav-v1")
    for cell in (c for c in v1.cells if c.is_real):
        for f in cell.spec["replay"]:
            assert recording_cell(f"/anywhere/{f}") == cell
    assert recording_cell("eth_ucy/univ/test/students003.txt").predictor == "gpgraph-stgcnn-univ+coherent-motion"
    assert recording_cell("eth_ucy/hotel/train/biwi_eth_train.txt") is None and recording_cell("notes.txt") is None
    smoke = load_suite("smoke")
    board = leaderboard(smoke, list(smoke.cells), [PolicyConfig("mpc-gpgraph"), PolicyConfig("mpc-cv")], [])
    assert board["cells"]["real-hotel"]["predictors"] == {"mpc-gpgraph": "gpgraph-stgcnn-hotel+coherent-motion"}
    assert board["cells"]["corridor-low-visible"]["predictors"] == {"mpc-gpgraph": DEFAULT_PREDICTOR}
    assert (f"Predictors: mpc-gpgraph: `{DEFAULT_PREDICTOR}` (corridor-low-visible, circle-low-invisible); "
            "`gpgraph-stgcnn-hotel+coherent-motion` (real-hotel).") in leaderboard_markdown(board)
    alone = leaderboard(smoke, list(smoke.cells), [PolicyConfig("mpc-cv")], [])
    assert "Predictors: none of these policies runs one." in leaderboard_markdown(alone)
