"""Group rules (predictor.group_rules), the GP-Graph override by a rule, and `gpgraph groups` on annotated people."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from predictor import load_predictor
from predictor.cli import main
from predictor.ethucy import DEFAULT_DATA_DIR
from predictor.group_rules import GROUP_RULES, CoherentMotionRule, ProximityRule, apply_rule, get_rule, split_group_rule
from predictor.group_validation import read_labelled

UCY_GROUPS = DEFAULT_DATA_DIR.absolute().parent / "eth_ucy_groups"  # beside the ETH/UCY data in ../shared


def walk(start: tuple[float, float], vel: tuple[float, float], t: int = 8, step_s: float = 0.4) -> np.ndarray:
    """(T, 2) positions of a straight walk, m."""
    return np.asarray(start) + np.arange(t)[:, None] * step_s * np.asarray(vel)


def scene(*tracks: np.ndarray) -> np.ndarray:
    return np.stack(tracks, axis=1)  # (T, N, 2)


def test_coherent_motion_groups_walkers_together_not_passers_by() -> None:
    obs = scene(walk((0, 0), (1.2, 0)), walk((0, 0.7), (1.2, 0)),  # a pair abreast, 0.7 m apart
                walk((0.5, 1.4), (-1.2, 0)),  # a stranger passing the pair close, the other way
                walk((10, 10), (0, 0)), walk((10.6, 10), (0, 0)))  # a pair standing and talking
    assert get_rule("coherent-motion")(obs).tolist() == [0, 0, 1, 2, 2]


def test_average_linkage_does_not_chain_through_one_neighbour() -> None:
    # a line of people 1.2 m apart, all standing: each adjacent pair costs 0.8, the ends are 3.6 m apart
    obs = scene(*(walk((x, 0.0), (0, 0)) for x in (0.0, 1.2, 2.4, 3.6)))
    chained = CoherentMotionRule(linkage="single")(obs)
    average = CoherentMotionRule()(obs)
    assert len(set(chained.tolist())) == 1  # single linkage: one group through the neighbours
    assert average.tolist() == [0, 0, 1, 1]  # average linkage: the two pairs' mean cost is 1.6, above 1
    assert CoherentMotionRule().cost(obs)[0, 3] == pytest.approx(3.6 / 1.5)


@pytest.mark.parametrize("name", list(GROUP_RULES))
def test_rules_ignore_the_frame_and_follow_the_people(name: str) -> None:
    rng = np.random.default_rng(3)
    obs = np.cumsum(rng.normal(scale=0.3, size=(8, 9, 2)), axis=0) + rng.uniform(0, 4, size=(1, 9, 2))
    rule = get_rule(name)
    labels = rule(obs)
    assert labels[0] == 0 and set(labels.tolist()) == set(range(labels.max() + 1))  # 0..G-1 by first member
    angle = 0.9
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moved = obs @ rot.T + np.array([30.0, -7.0])
    same = labels[:, None] == labels[None]
    moved_labels = rule(moved)
    assert np.array_equal(moved_labels[:, None] == moved_labels[None], same)
    perm = rng.permutation(9)
    permuted = rule(obs[:, perm])
    assert np.array_equal(permuted[:, None] == permuted[None], same[np.ix_(perm, perm)])


def test_bad_rule_input_and_names_are_errors() -> None:
    with pytest.raises(ValueError, match="valid names: coherent-motion"):
        get_rule("coherent")
    with pytest.raises(ValueError, match="NaN"):
        get_rule("coherent-motion")(np.full((8, 2, 2), np.nan))
    with pytest.raises(ValueError, match="shape"):
        get_rule("proximity-max")(np.zeros((8, 2)))
    with pytest.raises(ValueError, match="distance_m"):
        CoherentMotionRule(distance_m=0.0)
    with pytest.raises(ValueError, match="steps"):
        ProximityRule(steps="first")


def test_apply_rule_lays_out_a_padded_batch() -> None:
    a = scene(walk((0, 0), (1, 0)), walk((0, 0.5), (1, 0)), walk((5, 5), (0, 1)))
    obs = np.zeros((2, 8, 3, 2))
    obs[0] = a
    obs[1, :, :1] = a[:, 2:]
    mask = np.array([[True, True, True], [True, False, False]])
    labels = apply_rule(get_rule("coherent-motion"), obs, mask)
    assert labels.tolist() == [[0, 0, 1], [0, 1, 2]]  # padding: groups of its own after the real ones


def test_a_predictor_named_with_a_rule_groups_by_it() -> None:
    obs = scene(walk((0, 0), (1.2, 0)), walk((0, 0.7), (1.2, 0)), walk((0.5, 1.4), (-1.2, 0)))
    rule = get_rule("coherent-motion")
    cv = load_predictor("constant-velocity+coherent-motion").predict(obs, n_samples=4, rng=0)
    assert cv.group_id.tolist() == rule(obs).tolist() == [0, 0, 1]
    learned = load_predictor("gpgraph-stgcnn-synthetic")
    ruled = load_predictor("gpgraph-stgcnn-synthetic", group_rule="coherent-motion")
    same = load_predictor("gpgraph-stgcnn-synthetic+coherent-motion")
    out = ruled.predict(obs, n_samples=20, rng=1)
    assert out.group_id.tolist() == [0, 0, 1]
    assert np.array_equal(out.samples, same.predict(obs, n_samples=20, rng=1).samples)
    # group-level latents follow the rule's groups: the pair shares its sample offsets from the means
    dev = out.samples - out.mean[None]
    assert np.corrcoef(dev[:, 0, 0, 0], dev[:, 0, 1, 0])[0, 1] > 0.9
    assert ruled.model.group_rule == "coherent-motion" and learned.model.group_rule is None


def test_rule_names_in_predictor_specs_are_checked() -> None:
    assert split_group_rule("gpgraph-stgcnn-eth+proximity-max") == ("gpgraph-stgcnn-eth", "proximity-max")
    assert split_group_rule("gpgraph-stgcnn-eth") == ("gpgraph-stgcnn-eth", None)
    with pytest.raises(ValueError, match=r"unknown group rule 'proximity'; did you mean 'proximity-max'\? valid names"):
        load_predictor("gpgraph-stgcnn-eth+proximity")
    with pytest.raises(ValueError, match="give one"):
        load_predictor("constant-velocity+proximity-max", group_rule="coherent-motion")
    with pytest.raises(ValueError, match="unknown group rule"):
        load_predictor("gpgraph-stgcnn-eth", group_rule="nearest")


def _recording(folder: Path, n_frames: int = 30) -> Path:
    """DATA/scene/test/rec.txt: people 1 and 2 walk together, 3 alone; rec.groups.txt beside the data."""
    test = folder / "data" / "scene" / "test"
    test.mkdir(parents=True)
    rows = [f"{10 * f}\t{p}\t{x:.3f}\t{y:.3f}" for f in range(n_frames)
            for p, (x, y) in ((1, (0.48 * f, 0.0)), (2, (0.48 * f, 0.7)), (3, (20 - 0.48 * f, 3.0)))]
    (test / "rec.txt").write_text("\n".join(rows) + "\n")
    groups = folder / "groups"
    groups.mkdir()
    return groups


def test_groups_command_scores_annotations_and_refuses_bad_ones(tmp_path: Path, capsys) -> None:
    groups = _recording(tmp_path)
    (groups / "rec.groups.txt").write_text("1 2\n")
    out = tmp_path / "g.json"
    args = ["groups", "--data", str(tmp_path / "data"), "--groups", str(groups), "--json", str(out),
            "--predictor", "constant-velocity+coherent-motion", "--predictor", "constant-velocity"]
    assert main(args) == 0
    res = json.loads(out.read_text())["results"]
    assert res["constant-velocity+coherent-motion"]["rec"]["pw_f1"] == 1.0  # the rule finds the pair
    assert res["constant-velocity"]["all"]["pw_recall"] == 0.0  # everyone alone: no pair found
    assert res["constant-velocity"]["all"]["windows"] == 11  # 30 frames: windows starting at 0..10
    out.unlink()
    (groups / "rec.groups.txt").write_text("1 2 7\n")  # 7 is not in the recording
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pedestrians [7] are not in" in err and not out.exists()
    assert main([*args, "--absent-ids", "drop"]) == 0
    assert "left out" in capsys.readouterr().err
    assert json.loads(out.read_text())["notes"] == ["rec.groups.txt: pedestrians [7] are not in rec.txt: left out"]


def test_groups_command_refuses_a_recording_without_windows_and_unknown_names(tmp_path: Path, capsys) -> None:
    groups = _recording(tmp_path, n_frames=15)
    (groups / "rec.groups.txt").write_text("1 2\n")
    base = ["groups", "--data", str(tmp_path / "data"), "--groups", str(groups)]
    assert main([*base, "--predictor", "constant-velocity"]) == 2
    assert "no window of 20 consecutive frames" in capsys.readouterr().err
    (groups / "other.groups.txt").write_text("1 2\n")
    assert main([*base, "--predictor", "cv"]) == 2
    assert "no recording other.txt" in capsys.readouterr().err


@pytest.mark.slow
def test_the_shipped_rule_groups_real_people_better_than_the_crowdsim_assigner() -> None:
    """Validation on the UCY annotations (RESULTS.md, "sim-to-real"): the coherent-motion rule, chosen there,
    against the pairwise assigner trained on crowdsim, on every window of zara01 (602 windows)."""
    if not UCY_GROUPS.is_dir():
        pytest.skip(f"UCY group annotations not found at {UCY_GROUPS}")
    from predictor.group_validation import score_windows, summary

    torch.set_num_threads(1)
    rec = read_labelled(DEFAULT_DATA_DIR, UCY_GROUPS / "crowds_zara01.groups.txt")
    rule = summary(score_windows(rec.windows, lambda w: get_rule("coherent-motion")(w.obs)))
    learned = load_predictor("gpgraph-stgcnn-synthetic")
    model = summary(score_windows(rec.windows, lambda w: learned.predict(w.obs, n_samples=1, rng=0).group_id))
    assert rule["pw_f1"] == pytest.approx(0.832, abs=0.002) and rule["gmitre_f1"] == pytest.approx(0.916, abs=0.002)
    assert rule["pw_f1"] > model["pw_f1"] + 0.2 and rule["gmitre_f1"] > model["gmitre_f1"] + 0.2
