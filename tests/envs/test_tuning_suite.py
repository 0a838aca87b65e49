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


def test_tuning_suite_uses_the_reported_defaults_and_dense_cells():
    tune, reported = load_suite("crowdnav-tune"), load_suite("crowdnav-v1")
    assert tune.cells[0].defaults == reported.cells[0].defaults
    dense = {(c.spec["scenario"], c.spec["n_pedestrians"]) for c in reported.cells
             if not c.is_real and "high" in c.name}
    assert {(c.spec["scenario"], c.spec["n_pedestrians"]) for c in tune.cells if not c.is_real} <= dense


def test_check_suite_is_the_reported_real_cells_at_other_seeds():
    """crowdnav-v1-check: the same recordings, rules, predictors and episode counts as crowdnav-v1's real cells,
    and not one of its episodes."""
    check, reported = load_suite("crowdnav-v1-check"), load_suite("crowdnav-v1")
    real = {c.name: c for c in reported.cells if c.is_real}
    assert {c.name for c in check.cells} == set(real) and all(c.is_real for c in check.cells)
    for c in check.cells:
        ref = real[c.name]
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
