"""Reader and windowing rules: file format errors, group labels, and the reference window counts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predictor.data import DataFormatError, read_group_file, read_split, read_trajectory_file
from predictor.windows import (
    augment_rotations,
    has_labels,
    labels_for,
    load_windows,
    recording_windows,
    rotate_window,
)

# test / train / val windows and test pedestrians-in-windows, from ../shared/datasets/README.md
REFERENCE_COUNTS = {
    "eth": (70, 2785, 660, 181),
    "hotel": (301, 2594, 621, 1053),
    "univ": (947, 2076, 530, 24334),
    "zara1": (602, 2322, 605, 2253),
    "zara2": (921, 2112, 501, 5833),
}


def _write(path: Path, rows: list[tuple[float, int, float, float]], sep: str = "\t") -> Path:
    path.write_text("".join(sep.join(str(v) for v in r) + "\n" for r in rows))
    return path


def test_window_counts_match_reference(eth_ucy: Path) -> None:
    for scene, (n_test, n_train, n_val, n_peds) in REFERENCE_COUNTS.items():
        test = load_windows(eth_ucy / scene / "test")
        assert len(test) == n_test, scene
        assert sum(w.n_peds for w in test) == n_peds, scene
        assert len(load_windows(eth_ucy / scene / "train")) == n_train, scene
        assert len(load_windows(eth_ucy / scene / "val")) == n_val, scene


def test_malformed_row_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.txt"
    path.write_text("10\t1\t0.0\t0.0\n20\t1\t0.5\n")
    with pytest.raises(DataFormatError, match=r"bad\.txt:2"):
        read_trajectory_file(path)
    path.write_text("10 1 0.0 0.0\n\n20 1 abc 0.0\n")
    with pytest.raises(DataFormatError, match=r"bad\.txt:3.*non-numeric"):
        read_trajectory_file(path)


def test_whitespace_and_tabs_are_equivalent(tmp_path: Path) -> None:
    rows = [(10, 1, 1.5, 2.0), (10, 2, 3.0, 4.0)]
    a = read_trajectory_file(_write(tmp_path / "a.txt", rows, "\t"))
    b = read_trajectory_file(_write(tmp_path / "b.txt", rows, "   "))
    np.testing.assert_array_equal(a, b)
    assert a.shape == (2, 4)


def _synthetic_rows(n_frames: int, peds: dict[int, range]) -> list[tuple[float, int, float, float]]:
    rows = []
    for f in range(n_frames):
        for pid, frames in peds.items():
            if f in frames:
                rows.append((10 * f, pid, 0.1 * f + pid, 0.2 * pid))
    return rows


def test_window_rules_presence_and_min_peds(tmp_path: Path) -> None:
    # ped 1 and 2 present in frames 0..24; ped 3 only 0..19 -> appears only in the first window.
    rows = _synthetic_rows(25, {1: range(25), 2: range(25), 3: range(20)})
    _write(tmp_path / "s.txt", rows)
    recs = read_split(tmp_path)
    wins = recording_windows(recs[0])
    assert len(wins) == 25 - 20 + 1
    assert [w.n_peds for w in wins] == [3, 2, 2, 2, 2, 2]
    w0 = wins[0]
    assert w0.obs.shape == (8, 3, 2) and w0.pred.shape == (12, 3, 2)
    np.testing.assert_allclose(w0.pred[-1, 0], [0.1 * 19 + 1, 0.2])
    assert w0.group_id is None
    # a single pedestrian never makes a window
    _write(tmp_path / "s.txt", _synthetic_rows(25, {1: range(25)}))
    assert recording_windows(read_split(tmp_path)[0]) == []


def test_group_labels_travel_with_windows(tmp_path: Path) -> None:
    for split in ("train", "val", "test"):
        d = tmp_path / split
        d.mkdir()
        _write(d / "run0.txt", _synthetic_rows(21, {1: range(21), 2: range(21), 3: range(21), 4: range(21)}))
        (d / "run0.groups.txt").write_text("\n2 4\n\n")
    assert read_group_file(tmp_path / "test" / "run0.groups.txt") == ((2, 4),)
    wins = load_windows(tmp_path / "test")  # the group file must not be read as trajectories
    assert len(wins) == 2 and has_labels(wins)
    # ped order 1,2,3,4: ped 1 alone, 2 and 4 together, 3 alone
    np.testing.assert_array_equal(wins[0].group_id, [0, 1, 2, 1])


def test_labels_for_singletons_and_unknown_ids() -> None:
    gid = labels_for(np.array([7, 3, 5, 9]), ((3, 9), (5,)))
    np.testing.assert_array_equal(gid, [0, 1, 2, 1])


def test_group_file_rejects_duplicates(tmp_path: Path) -> None:
    p = tmp_path / "g.groups.txt"
    p.write_text("1 2\n2 3\n")
    with pytest.raises(DataFormatError, match="already listed"):
        read_group_file(p)


def test_rotation_preserves_distances() -> None:
    rng = np.random.default_rng(0)
    from predictor.windows import Window

    w = Window(rng.normal(size=(8, 3, 2)), rng.normal(size=(12, 3, 2)), np.arange(3), None)
    r = rotate_window(w, 0.7)
    d0 = np.linalg.norm(w.pred[:, 0] - w.pred[:, 1], axis=-1)
    d1 = np.linalg.norm(r.pred[:, 0] - r.pred[:, 1], axis=-1)
    np.testing.assert_allclose(d0, d1)
    assert not np.allclose(r.obs, w.obs)
    np.testing.assert_allclose(rotate_window(w, 2 * np.pi).obs, w.obs, atol=1e-12)
    out = augment_rotations([w, w], np.random.default_rng(1))
    assert not np.allclose(out[0].obs, out[1].obs)


def test_per_frame_labels_take_precedence_and_change_over_time(tmp_path: Path) -> None:
    # peds 1 and 2 walk together for frames 0..29; the labels file says they split at frame 15
    _write(tmp_path / "run.txt", _synthetic_rows(30, {1: range(30), 2: range(30), 3: range(30)}))
    (tmp_path / "run.groups.txt").write_text("1 2 3\n")  # majority partition: ignored when labels exist
    lines = [f"{10 * f}\t{p}\t{2 if (f >= 15 and p == 2) else (0 if p < 3 else 1)}\n"
             for f in range(30) for p in (1, 2, 3)]
    (tmp_path / "run.labels.tsv").write_text("".join(lines))
    wins = load_windows(tmp_path)
    assert len(wins) == 11
    by_last_obs = {int(w.start_frame) // 10 + 7: w.group_id.tolist() for w in wins}
    assert by_last_obs[14] == [0, 0, 1]  # together at the last observed frame
    assert by_last_obs[15] == [0, 1, 2]  # split from frame 15 on
    bad = tmp_path / "run.labels.tsv"
    bad.write_text("0 1\n")
    with pytest.raises(DataFormatError, match=r"run\.labels\.tsv:1.*'frame ped group'"):
        load_windows(tmp_path)
