"""TrajNet++ ndjson files: the writer's scenes and tracks, the reader's refusals, and `--format trajnet`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import crowdsim.cli as cli
from crowdsim.export import FRAME_STRIDE
from crowdsim.trajnet import SCENE_LEN, TrajnetFormatError, read_trajnet, scene_windows, trajnet_text


def _table() -> np.ndarray:
    """(R, 5) frame, ped, x, y, label in (frame, ped) order: ped 1 on 25 consecutive steps, ped 2 on 20 (too short
    for a scene), ped 3 on 30 steps with one step missing after its 10th row."""
    rows = []
    for ped, steps, label in ((1, range(25), 0), (2, range(3, 23), 0), (3, [k for k in range(31) if k != 10], 1)):
        for k in steps:
            rows.append((k * FRAME_STRIDE, ped, 0.1234567 * k - ped, 2.0 * ped + 0.00005 * k, label))
    t = np.asarray(rows, dtype=np.float64)
    return t[np.lexsort((t[:, 1], t[:, 0]))]


def test_scenes_are_21_consecutive_steps_of_one_pedestrian_every_3_rows():
    # ped 1: windows at rows 0 and 3 (25 rows); ped 2: none; ped 3: the 20 rows after its gap hold no window of 21,
    # and the 10 before it none either
    assert scene_windows(_table(), FRAME_STRIDE).tolist() == [[1, 0, 200], [1, 30, 230]]
    # with the gap filled, ped 3 (31 steps) gets its windows at rows 0, 3, 6, 9
    full = np.vstack([_table(), [[100, 3, 0.0, 0.0, 1]]])
    assert scene_windows(full, FRAME_STRIDE)[2:, 1].tolist() == [0, 30, 60, 90]
    assert SCENE_LEN == 21


def test_written_lines_are_trajnet_scenes_then_tracks(tmp_path):
    text = trajnet_text(_table(), fps=2.5, frame_step=FRAME_STRIDE)
    objs = [json.loads(line) for line in text.splitlines()]
    assert [list(o) for o in objs[:2]] == [["scene"], ["scene"]] and all(list(o) == ["track"] for o in objs[2:])
    assert objs[0]["scene"] == {"id": 0, "p": 1, "s": 0, "e": 200, "fps": 2.5, "tag": 0}
    assert objs[1]["scene"]["id"] == 1
    tracks = [o["track"] for o in objs[2:]]
    assert len(tracks) == len(_table())
    assert set(tracks[0]) == {"f", "p", "x", "y", "group"}
    assert [(t["f"], t["p"]) for t in tracks] == sorted((t["f"], t["p"]) for t in tracks)
    assert all(isinstance(t["f"], int) and isinstance(t["p"], int) for t in tracks)
    assert tracks[-1]["x"] == round(0.1234567 * 30 - 3, 4)  # 4 decimals, as the ETH/UCY export
    assert "group" not in trajnet_text(_table(), 2.5, FRAME_STRIDE, labels=False)


def test_read_returns_the_written_rows_labels_and_scenes(tmp_path):
    path = tmp_path / "x.ndjson"
    path.write_text(trajnet_text(_table(), fps=2.5, frame_step=FRAME_STRIDE))
    got = read_trajnet(path)
    np.testing.assert_allclose(got.table(), _table(), atol=5e-5, rtol=0)
    assert got.labels.tolist() == _table()[:, 4].astype(int).tolist()
    assert got.scenes.tolist() == [[0, 1, 0, 200], [1, 1, 30, 230]] and got.fps == 2.5


TRACK = '{"track": {"f": 0, "p": 1, "x": 1.0, "y": 2.0}}'
BAD = {
    "not JSON": ('{"track": {"f": 0, "p": 1, "x": 1.0', 2, "not JSON"),
    "missing key": ('{"track": {"f": 10, "p": 1, "x": 1.0}}', 2, "missing key 'y'"),
    "NaN coordinate": ('{"track": {"f": 10, "p": 1, "x": NaN, "y": 2.0}}', 2, "x is not finite"),
    "string coordinate": ('{"track": {"f": 10, "p": 1, "x": "1.0", "y": 2.0}}', 2, "x is not a number"),
    "fractional ped": ('{"track": {"f": 10, "p": 1.5, "x": 1.0, "y": 2.0}}', 2, "p 1.5 is not a whole number"),
    "duplicate (frame, ped)": ('{"track": {"f": 0, "p": 1, "x": 3.0, "y": 2.0}}', 2,
                               "pedestrian 1 appears twice in frame 0 (first at line 1)"),
    "neither scene nor track": ('{"person": {"f": 10}}', 2, "expected an object"),
    "a list": ("[1, 2, 3]", 2, "expected an object"),
    "group on some rows": ('{"track": {"f": 10, "p": 1, "x": 1.0, "y": 2.0, "group": 3}}', 2, "'group' is present"),
    "scene without end": ('{"scene": {"id": 0, "p": 1, "s": 0}}', 2, "missing key 'e'"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_line_is_an_error_naming_file_and_line(tmp_path, case):
    line, lineno, message = BAD[case]
    path = tmp_path / "bad.ndjson"
    path.write_text(f"{TRACK}\n{line}\n")
    with pytest.raises(TrajnetFormatError) as err:
        read_trajnet(path)
    assert str(err.value).startswith(f"{path}:{lineno}: ") and message in str(err.value)


def test_tracks_before_scenes_blank_lines_and_extra_keys_are_fine(tmp_path):
    path = tmp_path / "ok.ndjson"
    path.write_text(f'{TRACK}\n\n{{"scene": {{"id": 7, "p": 1, "s": 0, "e": 0, "fps": 2.5, "tag": [3, [1]]}}}}\n'
                    '{"track": {"f": 10, "p": 1, "x": 1.5, "y": 2.0, "prediction_number": 0}}\n')
    got = read_trajnet(path)
    assert got.rows.tolist() == [[0, 1, 1.0, 2.0], [10, 1, 1.5, 2.0]] and got.labels is None
    assert got.scenes.tolist() == [[7, 1, 0, 0]]


def test_a_file_without_track_rows_is_an_error(tmp_path):
    path = tmp_path / "empty.ndjson"
    path.write_text('{"scene": {"id": 0, "p": 1, "s": 0, "e": 200}}\n')
    with pytest.raises(TrajnetFormatError, match="no track rows"):
        read_trajnet(path)


SMALL = ["--scenario", "corridor", "--pedestrians", "4", "--duration", "2", "--warmup", "0"]


def test_generate_format_trajnet_writes_one_ndjson_and_the_metadata(tmp_path, capsys):
    assert cli.main(["generate", *SMALL, "--format", "trajnet", "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["corridor_n4_s0.json", "corridor_n4_s0.ndjson"]
    meta = json.loads((tmp_path / "corridor_n4_s0.json").read_text())
    got = read_trajnet(tmp_path / "corridor_n4_s0.ndjson")
    assert meta["format"] == "trajnet" and meta["rows"] == len(got.rows) and meta["scenes"] == len(got.scenes)
    assert got.labels is not None and len(got.labels) == len(got.rows)
    assert f"{meta['rows']} rows, {meta['pedestrians']} pedestrians, {meta['groups_of_two_or_more']} groups of 2+" \
        in capsys.readouterr().out


def test_dataset_format_trajnet_writes_ndjson_in_every_split(tmp_path):
    args = ["dataset", "--scenarios", "corridor", "--seeds-per-scenario", "3", "--pedestrians", "4",
            "--duration", "1", "--warmup", "0", "--format", "trajnet", "--out", str(tmp_path)]
    assert cli.main(args) == 0
    for split in ("train", "val", "test"):
        assert sorted(p.suffix for p in (tmp_path / split).iterdir()) == [".json", ".ndjson"]


def test_unknown_format_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["generate", *SMALL, "--format", "trajnet++", "--out", str(tmp_path / "out")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "--format" in err and "trajnet" in err
    assert not (tmp_path / "out").exists()


def test_an_unknown_format_in_the_api_lists_the_valid_ones(tmp_path):
    from crowdsim.config import SimConfig
    from crowdsim.generate import RunSpec, generate

    with pytest.raises(ValueError, match="unknown format 'csv'; valid: ethucy, trajnet"):
        generate(SimConfig(scenario="corridor", n_pedestrians=6), RunSpec(duration_s=1.0), tmp_path, fmt="csv")
    assert not any(tmp_path.iterdir())


def test_format_defaults_to_ethucy(tmp_path):
    assert cli.main(["generate", *SMALL, "--out", str(tmp_path)]) == 0
    assert sorted(Path(p).suffix for p in tmp_path.iterdir()) == [".json", ".tsv", ".txt", ".txt"]
