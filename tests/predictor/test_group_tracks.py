"""Group rules on a longer track (``track``: NaN before a pedestrian was first seen): each pair is measured over the
steps both were seen; the predictors pass the track to their rule only; ``window_tracks`` cuts it from a recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from predictor import load_predictor
from predictor.cli import main
from predictor.data import Recording
from predictor.group_rules import CoherentMotionRule, ProximityRule, get_rule
from predictor.windows import recording_windows, window_tracks


def walk(start: tuple[float, float], vel: tuple[float, float], t: int, step_s: float = 0.4) -> np.ndarray:
    return np.asarray(start, float) + np.arange(t)[:, None] * step_s * np.asarray(vel, float)


def test_a_pair_is_measured_over_the_steps_both_were_seen() -> None:
    rng = np.random.default_rng(0)
    track = np.cumsum(rng.normal(scale=0.2, size=(20, 3, 2)), axis=0)
    track[:12, 2] = np.nan  # the third person was first seen 8 steps ago
    rule = CoherentMotionRule(track_steps=20)
    cost = rule.cost(track)
    assert cost[0, 1] == pytest.approx(rule.cost(track[:, :2])[0, 1], rel=1e-12)  # both seen throughout
    assert cost[0, 2] == pytest.approx(rule.cost(track[12:, [0, 2]])[0, 1], rel=1e-12)
    assert cost[1, 2] == pytest.approx(rule.cost(track[12:, [1, 2]])[0, 1], rel=1e-12)
    finite = np.cumsum(rng.normal(scale=0.2, size=(8, 4, 2)), axis=0)  # no NaN: the plain means, as before
    dist = np.linalg.norm(finite[:, :, None] - finite[:, None], axis=-1)
    vel = np.diff(finite, axis=0) / 0.4
    rel = np.linalg.norm(vel[:, :, None] - vel[:, None], axis=-1)
    assert CoherentMotionRule().cost(finite).tobytes() == (dist.mean(axis=0) / 1.5 + rel.mean(axis=0) / 1.2).tobytes()
    assert CoherentMotionRule().cost(track).tobytes() == CoherentMotionRule().cost(track[-8:]).tobytes()  # reads 8


def test_proximity_counts_only_the_steps_both_were_seen() -> None:
    t = 20
    a, b = walk((0.0, 0.0), (1.0, 0.0), t), walk((0.0, 5.0), (1.0, 0.0), t)
    b[-8:, 1] = 1.0  # came within 1 m of a for the last 8 steps
    late = walk((0.0, -0.8), (1.0, 0.0), t)
    late[:-6] = np.nan  # seen for the last 6 steps, 0.8 m from a all that time
    track = np.stack([a, b, late], axis=1)
    assert ProximityRule(radius_m=1.25, steps="max", track_steps=20)(track).tolist() == [0, 1, 0]  # b was far before
    assert ProximityRule(radius_m=1.25, steps="max")(track).tolist() == [0, 0, 0]  # the newest 8 rows only
    assert ProximityRule(radius_m=1.25, steps="last", track_steps=20)(track).tolist() == [0, 0, 0]


def test_a_longer_track_splits_strangers_who_are_walking_close_only_now() -> None:
    """Two people who walked 3 m apart for 16 s and have converged in the last 3.2 s, side by side at the same
    speed: the window's 8 steps alone call them a group, their track does not; a pair abreast all along stays one."""
    t = 48
    a = walk((0.0, 0.0), (1.2, 0.0), t)
    b = walk((0.0, 3.0), (1.2, 0.0), t)
    b[-8:, 1] = 0.7  # converged: abreast with a, 0.7 m apart, for the window's 8 steps
    c, d = walk((0.0, 10.0), (1.0, 0.0), t), walk((0.0, 10.6), (1.0, 0.0), t)
    track = np.stack([a, b, c, d], axis=1)
    assert get_rule("coherent-motion")(track).tolist() == [0, 0, 1, 1]  # reads the newest 8 rows
    assert get_rule("coherent-motion-track")(track).tolist() == [0, 1, 2, 2]


def test_bad_tracks_are_errors() -> None:
    rule = get_rule("coherent-motion-track")
    base = np.cumsum(np.ones((10, 2, 2)), axis=0)
    gap = base.copy()
    gap[4, 0] = np.nan  # seen, unseen, seen again
    late = base.copy()
    late[:, 1] = np.nan
    late[-1, 1] = 0.0  # seen only now: no velocity
    half = base.copy()
    half[:3, 0, 0] = np.nan  # one coordinate missing
    for bad in (gap, late, half):
        with pytest.raises(ValueError, match="NaN other than a pedestrian's leading rows"):
            rule(bad)
    inf = base.copy()
    inf[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="inf"):
        rule(inf)
    for steps in (1, 2.5, True):
        with pytest.raises(ValueError, match="track_steps must be an integer >= 2"):
            CoherentMotionRule(track_steps=steps)


def test_predictors_give_the_track_to_their_rule_and_only_to_it() -> None:
    t = 48
    a, b = walk((0.0, 0.0), (1.2, 0.0), t), walk((0.0, 3.0), (1.2, 0.0), t)
    b[-8:, 1] = 0.7
    track = np.stack([a, b], axis=1)
    history = track[-8:].copy()
    for name in ("constant-velocity+coherent-motion-track", "gpgraph-stgcnn-synthetic+coherent-motion-track"):
        p = load_predictor(name)
        assert p.reads_track and p.track_steps == 48
        assert p.predict(history, n_samples=4, rng=0).group_id.tolist() == [0, 0]  # no track: the 8 steps
        assert p.predict(history, n_samples=4, rng=0, track=track).group_id.tolist() == [0, 1]
        only_window = np.full_like(track, np.nan)
        only_window[-8:] = history  # a track that adds nothing: the same prediction, bit for bit
        same = p.predict(history, n_samples=4, rng=0, track=only_window)
        assert same.samples.tobytes() == p.predict(history, n_samples=4, rng=0).samples.tobytes()
        with pytest.raises(ValueError, match="last row must equal"):
            p.predict(history, n_samples=4, rng=0, track=track[:-1])
        with pytest.raises(ValueError, match="track must have shape"):
            p.predict(history, n_samples=4, rng=0, track=track[-5:])
    for name in ("gpgraph-stgcnn-synthetic", "constant-velocity", "gpgraph-stgcnn-synthetic+coherent-motion"):
        p = load_predictor(name)
        assert not p.reads_track and p.track_steps == 8
        with pytest.raises(ValueError, match="reads no track"):  # not silently ignored
            p.predict(history, n_samples=4, rng=0, track=track)


def test_window_tracks_extend_each_window_back_over_the_run_up_to_it() -> None:
    # person 1 walks throughout; person 2 from frame 5, away for frame 12, back from 13; frames 10 units apart
    rows = [(10 * f, 1, 0.4 * f, 0.0) for f in range(40)]
    rows += [(10 * f, 2, 0.4 * f, 1.0) for f in range(5, 40) if f != 12]
    rec = Recording(path=Path("rec.txt"), rows=np.array(rows, float), groups=())
    windows = recording_windows(rec)
    tracks = window_tracks(rec.rows, windows, 30)
    for w, tr in zip(windows, tracks, strict=True):
        assert tr.shape == (30, w.n_peds, 2) and np.array_equal(tr[-8:], w.obs)
        end = int(w.start_frame) // 10 + 8  # one past the last observed frame
        first_row = 30 - end  # frame 0 sits at this row of the track
        k = list(w.ped_ids).index(1)
        assert np.isnan(tr[: max(first_row, 0), k]).all() and not np.isnan(tr[max(first_row, 0):, k]).any()
        if 2 in w.ped_ids:  # seen from frame 13 without a break up to the window
            k2 = list(w.ped_ids).index(2)
            seen_from = 30 - (end - 13)
            assert np.isnan(tr[:seen_from, k2]).all() and not np.isnan(tr[seen_from:, k2]).any()
    with pytest.raises(ValueError, match="steps must be >= 8"):
        window_tracks(rec.rows, windows, 7)


def test_groups_command_reads_tracks_for_rules_that_want_them(tmp_path: Path, capsys) -> None:
    test = tmp_path / "data" / "scene" / "test"
    test.mkdir(parents=True)
    # 1 and 2 walked apart for 30 frames, then abreast; 3 and 4 walk together throughout (annotated group)
    rows = []
    for f in range(60):
        rows += [(10 * f, 1, 0.48 * f, 0.0), (10 * f, 2, 0.48 * f, 3.0 if f < 30 else 0.7),
                 (10 * f, 3, 0.4 * f, 10.0), (10 * f, 4, 0.4 * f, 10.6)]
    (test / "rec.txt").write_text("\n".join(f"{r[0]}\t{r[1]}\t{r[2]:.3f}\t{r[3]:.3f}" for r in rows) + "\n")
    groups = tmp_path / "groups"
    groups.mkdir()
    (groups / "rec.groups.txt").write_text("3 4\n")
    out = tmp_path / "g.json"
    args = ["groups", "--data", str(tmp_path / "data"), "--groups", str(groups), "--json", str(out), "--predictor",
            "constant-velocity+coherent-motion", "--predictor", "constant-velocity+coherent-motion-track"]
    assert main(args) == 0
    res = json.loads(out.read_text())["results"]
    short, long = res["constant-velocity+coherent-motion"]["all"], res["constant-velocity+coherent-motion-track"]["all"]
    assert long["pw_precision"] > short["pw_precision"] and long["pw_recall"] == short["pw_recall"] == 1.0
    capsys.readouterr()
    for command in ("evaluate", "predict"):  # they have 8 steps a pedestrian: a track rule would read less
        extra = ["--out", str(tmp_path / "p.npz"), "--history", str(tmp_path / "h.npy")] if command == "predict" else [
            "--data", str(tmp_path / "data" / "scene")]
        np.save(tmp_path / "h.npy", np.zeros((8, 2, 2)))
        assert main([command, "--checkpoint", "gpgraph-stgcnn-synthetic", "--group-rule", "coherent-motion-track",
                     *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "reads 48 positions per pedestrian" in err
    assert not (tmp_path / "p.npz").exists()


@pytest.mark.slow
def test_on_real_annotations_the_track_tells_groups_apart_better() -> None:
    """Validation on the UCY annotations (RESULTS.md, "sim-to-real"): on students003's 522 windows the rule on each
    person's last 48 positions (cut from the recording) beats the same rule on the 8 observed steps."""
    from predictor.ethucy import DEFAULT_DATA_DIR
    from predictor.group_validation import read_labelled, score_windows, summary

    groups = DEFAULT_DATA_DIR.absolute().parent / "eth_ucy_groups" / "students003.groups.txt"
    if not groups.is_file():
        pytest.skip(f"UCY group annotations not found at {groups}")
    rec = read_labelled(DEFAULT_DATA_DIR, groups, overlaps="merge", absent_ids="drop")
    tracks = {id(w): t for w, t in zip(rec.windows, window_tracks(rec.rows, rec.windows, 48), strict=True)}
    short = summary(score_windows(rec.windows, lambda w: get_rule("coherent-motion")(w.obs)))
    long = summary(score_windows(rec.windows, lambda w: get_rule("coherent-motion-track")(tracks[id(w)])))
    assert short["pw_f1"] == pytest.approx(0.821, abs=0.002) and long["pw_f1"] == pytest.approx(0.862, abs=0.002)
    assert long["gmitre_f1"] > short["gmitre_f1"]
