"""TrajNet++ files across the packages: ETH/UCY -> TrajNet++ -> ETH/UCY returns the rows, crowdsim's and the
predictor's readers agree, and the predictor's windows and the replayed crowd are the same from either format."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import predictor.cli as gpgraph_cli
from crowdsim.config import SimConfig
from crowdsim.export import FRAME_STRIDE, trajectories_text
from crowdsim.generate import RunSpec, generate
from crowdsim.trajnet import read_trajnet, trajnet_text
from envs.crowds.replay import ReplayConfig, ReplayCrowd
from predictor.data import DataFormatError, list_trajectory_files, read_recording
from predictor.ethucy import DEFAULT_DATA_DIR, read_trajectories
from predictor.trajnet import read_trajnet_rows
from predictor.windows import load_windows

STUDENTS003 = DEFAULT_DATA_DIR / "univ" / "test" / "students003.txt"


@pytest.fixture
def eth_ucy_head(tmp_path) -> Path:
    """The first 200 lines of students003 (the test file of univ), copied into tmp_path."""
    if not STUDENTS003.is_file():
        pytest.skip(f"ETH/UCY data not found at {STUDENTS003} (needs the sibling ../shared folder, or ETH_UCY_DIR)")
    path = tmp_path / "students003.txt"
    path.write_text("".join(STUDENTS003.read_text().splitlines(keepends=True)[:200]))
    return path


def _sorted(rows: np.ndarray) -> np.ndarray:
    return rows[np.lexsort((rows[:, 1], rows[:, 0]))]


def test_ethucy_to_trajnet_to_ethucy_returns_the_same_rows(eth_ucy_head, tmp_path):
    rows = _sorted(read_trajectories(eth_ucy_head))
    table = np.column_stack([rows, np.full(len(rows), -1.0)])
    ndjson = tmp_path / "students003.ndjson"
    ndjson.write_text(trajnet_text(table, fps=2.5, frame_step=FRAME_STRIDE, labels=False))
    back = read_trajnet(ndjson)
    assert back.labels is None and len(back.rows) == 200
    # the same (frame, ped, x, y) rows, byte for byte at the export's 4 decimals
    assert trajectories_text(back.table()) == trajectories_text(table)
    np.testing.assert_allclose(back.table()[:, :4], rows, atol=5e-5, rtol=0)


def test_crowdsim_and_predictor_readers_agree(eth_ucy_head, tmp_path):
    rows = _sorted(read_trajectories(eth_ucy_head))
    labels = (rows[:, 1] % 3).astype(float)  # some per-row labels, to compare the group fields too
    path = tmp_path / "labelled.ndjson"
    path.write_text(trajnet_text(np.column_stack([rows, labels]), fps=2.5, frame_step=FRAME_STRIDE))
    ours, theirs = read_trajnet(path), read_trajnet_rows(path)
    np.testing.assert_array_equal(ours.rows, theirs[0])
    np.testing.assert_array_equal(np.column_stack([ours.rows[:, :2], ours.labels]), theirs[1])


@pytest.fixture(scope="module")
def both_formats(tmp_path_factory) -> tuple[Path, Path]:
    """One small crowdsim run written as ETH/UCY files and as a TrajNet++ file, into two folders."""
    root = tmp_path_factory.mktemp("run")
    config, spec = SimConfig(scenario="corridor", n_pedestrians=6), RunSpec(duration_s=10.0, warmup_s=2.0, seed=3)
    for fmt in ("ethucy", "trajnet"):
        generate(config, spec, root / fmt, fmt=fmt)
    return root / "ethucy", root / "trajnet"


def test_predictor_windows_are_the_same_from_either_format(both_formats):
    ethucy, trajnet = both_formats
    assert [p.suffix for p in list_trajectory_files(trajnet)] == [".ndjson"]
    a, b = load_windows(ethucy), load_windows(trajnet)
    assert len(a) == len(b) > 0 and a[0].group_id is not None
    for wa, wb in zip(a, b, strict=True):
        np.testing.assert_allclose(wb.obs, wa.obs, atol=1e-12)
        np.testing.assert_allclose(wb.pred, wa.pred, atol=1e-12)
        np.testing.assert_array_equal(wb.ped_ids, wa.ped_ids)
        np.testing.assert_array_equal(wb.group_id, wa.group_id)  # labels from the group field = the labels file


def test_replay_reads_either_format_alike(both_formats):
    ethucy, trajnet = both_formats
    crowds = [ReplayCrowd(ReplayConfig(path=folder / f"corridor_n6_s3{suffix}", start_mode="fixed"))
              for folder, suffix in ((ethucy, ".txt"), (trajnet, ".ndjson"))]
    assert crowds[0].ped_ids.tolist() == crowds[1].ped_ids.tolist()
    assert crowds[0].duration_s == crowds[1].duration_s > 0
    for t in (0.0, 1.3, 4.0):
        for got, want in zip(crowds[1].positions_at(t), crowds[0].positions_at(t), strict=True):
            np.testing.assert_allclose(got, want, atol=1e-12)


def test_a_recording_in_both_formats_in_one_folder_is_refused(both_formats, tmp_path):
    ethucy, trajnet = both_formats
    for src in (*ethucy.iterdir(), next(trajnet.glob("*.ndjson"))):
        (tmp_path / src.name).write_bytes(src.read_bytes())
    with pytest.raises(DataFormatError, match=re.escape("both .txt and .ndjson")):
        list_trajectory_files(tmp_path)


def test_predictor_reader_names_file_and_line(tmp_path):
    path = tmp_path / "bad.ndjson"
    path.write_text('{"track": {"f": 0, "p": 1, "x": 1.0, "y": 2.0}}\n{"track": {"f": 0, "p": 1, "x": 1.0, '
                    '"y": NaN}}\n')
    with pytest.raises(DataFormatError, match="^" + re.escape(f"{path}:2: y is not a finite number")):
        read_recording(path)


def test_gpgraph_train_on_a_malformed_ndjson_is_one_line_exit_2_nothing_written(both_formats, tmp_path, capsys):
    _, trajnet = both_formats
    data = tmp_path / "data"
    for split in ("train", "val"):
        (data / split).mkdir(parents=True)
        for src in trajnet.iterdir():
            (data / split / src.name).write_bytes(src.read_bytes())
    bad = next((data / "val").glob("*.ndjson"))
    lines = bad.read_text().splitlines()
    track = next(i for i, line in enumerate(lines) if "track" in line)
    lines[track] = json.dumps({"track": {"f": 0, "p": 1, "x": 1.0}})
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "run"
    code = gpgraph_cli.main(["train", "--data", str(data), "--out", str(out), "--epochs", "1"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"{bad}:{track + 1}: missing key 'y'" in err
    assert not out.exists()
