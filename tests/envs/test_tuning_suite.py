"""The tuning suite never meets a reported episode, and scripts/compare_runs.py pairs runs episode by episode."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from envs.evaluation.records import EpisodeRecord, RecordStore
from envs.evaluation.suite import load_suite


def _episodes(cell) -> set[tuple]:
    """What an episode of a cell is, independent of its name: the recording(s) or the simulated setting, x seed."""
    what = tuple(cell.spec["replay"]) if cell.is_real else \
        (cell.spec["scenario"], cell.spec["n_pedestrians"], cell.spec["robot_visible"])
    return {(what, seed) for seed in cell.seeds}


def test_tuning_suite_shares_no_recording_or_episode_with_the_reported_suite():
    tune, reported = load_suite("crowdnav-tune"), load_suite("crowdnav-v1")
    reported_files = {Path(f).name for c in reported.cells if c.is_real for f in c.spec["replay"]}
    tune_files = {Path(f).name for c in tune.cells if c.is_real for f in c.spec["replay"]}
    assert tune_files and not tune_files & reported_files
    # the files must not be cuts of a test recording either (zara03 and uni_examples are in no test split)
    assert not {f.split("_train")[0] for f in tune_files} & {f.split(".")[0] for f in reported_files}
    ours = set().union(*(_episodes(c) for c in tune.cells))
    theirs = set().union(*(_episodes(c) for c in reported.cells))
    assert not ours & theirs
    assert min(min(c.seeds) for c in tune.cells) > max(max(c.seeds) for c in reported.cells)


def test_tuning_suite_uses_the_reported_defaults_and_settings():
    """Its simulated cells are settings of the reported suite (version 2: the dense ones; version 3 adds a door and
    a sparse corridor) at other seeds."""
    tune, reported = load_suite("crowdnav-tune"), load_suite("crowdnav-v1")
    assert tune.cells[0].defaults == reported.cells[0].defaults

    def settings(suite):
        return {(c.spec["scenario"], c.spec["n_pedestrians"], c.spec["robot_visible"], str(c.spec.get("options")))
                for c in suite.cells if not c.is_real}
    assert settings(tune) <= settings(reported)
    assert {"bottleneck", "corridor", "plaza", "crossing", "circle_crossing"} <= {s[0] for s in settings(tune)}


def test_tuning_suite_holds_every_dense_two_way_setting_of_the_reported_suite():
    """Version 4: the dense corridor and crossing cells, robot visible and invisible (where the MPC policies fail
    most), are all tuned on, at 20 seeds each."""
    tune, reported = load_suite("crowdnav-tune"), load_suite("crowdnav-v1")
    assert tune.version >= 4

    def dense(suite):
        return {(c.spec["scenario"], c.spec["n_pedestrians"], c.spec["robot_visible"]): len(c.seeds)
                for c in suite.cells if not c.is_real and c.spec["scenario"] in ("corridor", "crossing")
                and c.name.split("-")[-2] == "high"}
    wanted = dense(reported)
    assert len(wanted) == 4 and set(wanted) <= set(dense(tune))
    assert all(dense(tune)[setting] == 20 for setting in wanted)


def test_check_suite_is_the_reported_cells_at_other_seeds():
    """crowdnav-v1-check: the same recordings, scenarios, rules, predictors and episode counts as crowdnav-v1's cells
    (real ones since version 1, synthetic ones since version 5), and not one of its episodes."""
    check, reported = load_suite("crowdnav-v1-check"), load_suite("crowdnav-v1")
    cells = {c.name: c for c in reported.cells}
    assert sorted(c.name for c in check.cells) == sorted(cells)
    for c in check.cells:
        ref = cells[c.name]
        assert c.spec | {"seed0": 0} == ref.spec | {"seed0": 0} and c.defaults == ref.defaults
        assert c.predictor == ref.predictor and len(c.seeds) == len(ref.seeds)
        assert not _episodes(c) & _episodes(ref)


def _record(cell: str, seed: int, outcome: str, kind: str | None = None) -> EpisodeRecord:
    return EpisodeRecord(policy="mpc-gpgraph", seed=seed, outcome=outcome, cell=cell,
                         collision_with="pedestrian" if outcome == "collision" else None, at_fault=kind)


def _write(path: Path, records: list[EpisodeRecord]) -> Path:
    store = RecordStore(path)
    for r in records:
        store.append(r)
    return path


def test_compare_runs_pairs_by_cell_and_seed(tmp_path, capsys, load_script):
    cmp = load_script("compare_runs")
    # run A collides in seeds 0-5 of cell x, run B only in seed 0; cell y only exists in A and is left out
    a = [_record("x", s, "collision" if s < 6 else "success", "robot" if s < 6 else None) for s in range(10)]
    a += [_record("y", 0, "collision", "spawn")]
    b = [_record("x", s, "collision" if s == 0 else "success", "pedestrian" if s == 0 else None) for s in range(10)]
    rows = dict(cmp.compare(a, b))
    assert set(rows) == {"x", "pooled"}
    pooled = rows["pooled"]
    assert pooled["pairs"] == 10
    assert (pooled["collision"]["a_only"], pooled["collision"]["b_only"]) == (5, 0)
    assert pooled["collision"]["p_value"] == pytest.approx(2 * 0.5 ** 5)
    assert pooled["avoidable_collision"]["a"] == 6 and pooled["avoidable_collision"]["b"] == 1
    pa, pb = _write(tmp_path / "a.jsonl", a), _write(tmp_path / "b.jsonl", b)
    assert cmp.main([str(pa), str(pb), "--policy", "mpc-gpgraph"]) == 0
    assert "pooled" in capsys.readouterr().out
    assert cmp.main([str(pa), str(pb), "--policy", "mpc-cv"]) == 2
    assert cmp.main([str(pa), str(tmp_path / "missing.jsonl"), "--policy", "mpc-gpgraph"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("compare_runs: error:") for line in err)


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))


def test_reported_real_cells_name_the_ucy_group_files_and_no_biwi_ones(tmp_path):
    """crowdnav-v1 version 6: zara1, zara2 and univ's students003 episodes carry the public UCY group annotations (the
    four students003 pedestrians listed twice merge their groups); eth, hotel and students001 have none."""
    for suite in (load_suite("crowdnav-v1"), load_suite("crowdnav-v1-check")):
        groups = {c.name: c.spec.get("groups", {}) for c in suite.cells if c.is_real}
        assert {n for n, g in groups.items() if g} == {"real-univ", "real-zara1", "real-zara2"}
        named = [Path(f) for g in groups.values() for f in [*g, *g.values()]]
        assert not any(p.parts[0] in ("eth", "hotel") or "biwi" in p.name for p in named)
        univ = suite.cell("real-univ")
        by_file = {univ.env_config(s, tmp_path).replay.path.name: univ.env_config(s, tmp_path).replay for s in (0, 1)}
        assert by_file["students003.txt"].groups_path.name == "students003.groups.txt"
        assert by_file["students003.txt"].group_overlaps == "merge"
        assert by_file["students001.txt"].groups_path is None


@pytest.mark.parametrize(("change", "needle"), [
    ({"groups": {"zara1/test/other.txt": "../g.txt"}}, "does not replay"),
    ({"group_overlaps": "drop"}, "group_overlaps must be error or merge"),
])
def test_a_cell_with_a_bad_group_entry_is_refused(change, needle):
    from envs.evaluation.suite import parse_suite

    cell = {"name": "r", "replay": ["zara1/test/crowds_zara01.txt"], "frame_step_s": 0.4, "episodes": 1, "seed0": 0}
    with pytest.raises(ValueError, match=needle):
        parse_suite({"name": "s", "version": 1, "cells": [cell | change]})


def test_a_missing_group_file_is_reported_before_any_episode(tmp_path):
    from envs.evaluation.suite import parse_suite

    (tmp_path / "z").mkdir()
    (tmp_path / "z" / "rec.txt").write_text("0\t1\t0.0\t0.0\n")
    cell = {"name": "r", "replay": ["z/rec.txt"], "frame_step_s": 0.4, "episodes": 1, "seed0": 0,
            "groups": {"z/rec.txt": "../nowhere/rec.groups.txt"}}
    suite = parse_suite({"name": "s", "version": 1, "cells": [cell]})
    with pytest.raises(ValueError, match=r"group file .* not found"):
        suite.check_data(list(suite.cells), tmp_path)


def test_trace_episode_replays_the_benchmark_episode_and_refuses_misuse(capsys, load_script):
    """scripts/trace_episode.py runs the very episode the benchmark runs (same outcome and time), prints one line per
    re-plan in its window, and refuses a seed outside the cell with one line on stderr and exit 2."""
    from envs.evaluation.episode import run_episode
    from envs.policies import PolicyConfig

    trace = load_script("trace_episode")
    cell = load_suite("crowdnav-tune").cell("tune-circle-high-invisible")
    seed = cell.seeds[0]
    assert trace.main(["crowdnav-tune", cell.name, str(seed), "--policy", "mpc-cv", "--from", "1", "--to", "2"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    m = run_episode(cell.env_config(seed), PolicyConfig("mpc-cv"), seed).metrics
    assert lines[-1].startswith(f"{m['outcome']} at {m['time_s']:.1f} s")
    replans = [ln for ln in lines[:-1] if ln.startswith("t=")]
    assert len(replans) == 11 and all("slack=" in ln and "shield=" in ln for ln in replans)  # 1.0 .. 2.0 s, 0.1 s
    assert trace.main(["crowdnav-tune", cell.name, str(seed), "--policy", "mpc-cv"]) == 0  # every re-plan printed
    lines = capsys.readouterr().out.strip().splitlines()
    replans = [ln for ln in lines if ln.startswith("t=")]
    shielded = sum("shield=yes" in ln for ln in replans) / len(replans)
    slack = sum(float(ln.split("slack=")[1].split()[0]) > 0.05 for ln in replans) / len(replans)
    assert f" | {len(replans)} plans: shield {shielded:.2f} (last 3 s: " in lines[-1]  # the summary counts them
    assert f"slack > 0.05 m {slack:.2f} (last 3 s: " in lines[-1]
    assert trace.main(["crowdnav-tune", cell.name, "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("trace_episode: seed 5 is not one of")
    assert trace.main(["crowdnav-tune", cell.name, str(seed), "--mpc", "horizon=3"]) == 2  # not an MPCConfig field
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("trace_episode: unknown --mpc field 'horizon'; did you mean 'horizon_steps'?")
