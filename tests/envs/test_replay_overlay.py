"""ReplayConfig.overlay: a denser crowd from K time-shifted copies of a recording (envs.crowds.replay_overlay)."""

from __future__ import annotations

import numpy as np
import pytest

from envs.crowds.replay import ReplayConfig, ReplayCrowd
from envs.crowds.replay_overlay import overlay_rows
from predictor.ethucy import DEFAULT_DATA_DIR, read_trajectories

ZARA03 = DEFAULT_DATA_DIR.absolute() / "eth/train/crowds_zara03_train.txt"


def _rows() -> np.ndarray:
    """Frames 0..90 (10 per step, 10 steps); ped 7 over 0..40, ped 12 over 60..90 (crosses no wrap at K=1)."""
    a = [(f, 7, 0.1 * f, 1.0) for f in range(0, 50, 10)]
    b = [(f, 12, 5.0, 0.05 * f) for f in range(60, 100, 10)]
    return np.array(a + b, dtype=float)


def test_copy_zero_is_the_recording_and_every_copy_keeps_its_tracks():
    rows = _rows()
    out = overlay_rows(rows, 3, 10.0)
    assert len(out) == 3 * len(rows)
    same = out[out[:, 1] < 100]  # copy 0: ids below B = 100
    assert np.array_equal(same[np.lexsort((same[:, 0], same[:, 1]))], rows[np.lexsort((rows[:, 0], rows[:, 1]))])
    assert out[:, 0].min() == 0 and out[:, 0].max() == 90  # the original frame grid and duration
    for j, shift in ((1, 3), (2, 6)):  # span 10 steps: copies shifted by 3 and 6 steps
        for pid, track in ((7, rows[rows[:, 1] == 7]), (12, rows[rows[:, 1] == 12])):
            mine = out[(out[:, 1] % 100 == pid) & (out[:, 1] // 200 == j)]  # this copy's pieces of the track
            assert sorted(map(tuple, mine[:, 2:])) == sorted(map(tuple, track[:, 2:]))  # same places
            # each place at its shifted frame, modulo the span (a wrap cuts the track: a new id on the far side)
            expect = {(x, y): (f + 10 * shift) % 100 for f, _, x, y in track}
            assert all(expect[(x, y)] == f for f, _, x, y in mine)
    # copy 1 shifts ped 12 (frames 60..90) to 90..120: frame 90 keeps id 212, 100..120 wrap to 0..20 as id 312
    out_ids = {int(i): sorted(out[out[:, 1] == i, 0].tolist()) for i in (212, 312)}
    assert out_ids == {212: [90.0], 312: [0.0, 10.0, 20.0]}


def test_density_rises_k_fold_on_a_real_recording():
    rows = read_trajectories(ZARA03)
    crowd1 = ReplayCrowd(ReplayConfig(path=ZARA03, start_mode="fixed"))
    crowd5 = ReplayCrowd(ReplayConfig(path=ZARA03, start_mode="fixed", overlay=5))
    assert crowd5.name == "crowds_zara03_train_x5" and crowd1.name == "crowds_zara03_train"
    assert crowd5.duration_s == crowd1.duration_s
    _, per_frame = np.unique(rows[:, 0], return_counts=True)
    out = overlay_rows(rows, 5, 10.0)
    _, per_frame5 = np.unique(out[:, 0], return_counts=True)
    assert per_frame5.sum() == 5 * per_frame.sum()
    assert 4.0 <= np.median(per_frame5) / np.median(per_frame) <= 6.0
    assert crowd5.capacity > 2 * crowd1.capacity  # peaks do not add exactly


def test_overlay_misuse_is_refused(tmp_path):
    with pytest.raises(ValueError, match="overlay must be an integer >= 1"):
        ReplayConfig(path=ZARA03, overlay=0)
    groups = tmp_path / "g.txt"
    groups.write_text("1 2\n")
    with pytest.raises(ValueError, match="cannot take a group file"):
        ReplayConfig(path=ZARA03, overlay=2, groups_path=groups)
    with pytest.raises(ValueError, match="cannot hold 20 shifted copies"):
        overlay_rows(_rows(), 20, 10.0)
    with pytest.raises(ValueError, match=r"\(R, 4\) rows"):
        overlay_rows(np.zeros((3, 3)), 2, 10.0)
