"""Exports, determinism, the CLI and the rerun recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from crowdsim.cli import main
from crowdsim.config import GroupConfig, SimConfig
from crowdsim.generate import RunSpec, generate
from predictor.ethucy import read_groups as read_groups_file  # the one ETH/UCY reader

EVENTFUL = SimConfig(scenario="plaza", n_pedestrians=30,
                     groups=GroupConfig(leave_rate_hz=0.05, merge_rate_hz=0.05))


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_same_seed_and_config_give_byte_identical_files(tmp_path):
    for k in ("a", "b"):
        generate(EVENTFUL, RunSpec(duration_s=20.0, seed=7), tmp_path / k, name="run")
    generate(EVENTFUL, RunSpec(duration_s=20.0, seed=8), tmp_path / "c", name="run")
    a, b, c = (_files(tmp_path / k) for k in "abc")
    assert set(a) == {"run.txt", "run.groups.txt", "run.labels.tsv", "run.json"}
    assert a == b
    assert a["run.txt"] != c["run.txt"]


def test_the_one_reader_reads_every_export_exactly(tmp_path):
    """crowdsim writes (it may not import predictor); predictor.ethucy, the project's one reader, reads what it
    wrote: the same rows, labels one per row, groups a partition of labelled pedestrians."""
    from predictor.ethucy import read_labels, read_trajectories

    paths = generate(EVENTFUL, RunSpec(duration_s=20.0, seed=3), tmp_path, name="run")
    rows = read_trajectories(paths["trajectories"])
    np.testing.assert_array_equal(rows, np.loadtxt(paths["trajectories"], delimiter="\t"))
    labels = read_labels(paths["labels"])
    np.testing.assert_array_equal(labels[:, :2], rows[:, :2])
    members = [p for g in read_groups_file(paths["groups"]) for p in g]
    assert set(members) <= set(rows[:, 1].astype(int))


def test_eth_ucy_format_and_labels(tmp_path):
    paths = generate(EVENTFUL, RunSpec(duration_s=40.0, seed=3), tmp_path, name="run")
    lines = paths["trajectories"].read_text().splitlines()
    assert all(len(line.split("\t")) == 4 for line in lines)
    rows = np.loadtxt(paths["trajectories"], delimiter="\t")
    frames = np.unique(rows[:, 0])
    np.testing.assert_array_equal(np.diff(frames), 10)  # +10 per 0.4 s step
    assert len(frames) == 101
    labels = np.loadtxt(paths["labels"], delimiter="\t")
    np.testing.assert_array_equal(labels[:, :2], rows[:, :2])  # one label per trajectory row
    meta = json.loads(paths["metadata"].read_text())
    assert meta["scenario"] == "plaza" and meta["seed"] == 3 and meta["steps"] == 100
    assert meta["config"]["groups"]["leave_rate_hz"] == 0.05
    assert meta["config"]["social"]["relaxation_time_s"] == 0.5
    # the group file is a partition: each pedestrian in the group of its majority label
    groups = read_groups_file(paths["groups"])
    flat = [p for g in groups for p in g]
    assert len(flat) == len(set(flat))
    by_label: dict[int, list[int]] = {}
    for ped in np.unique(labels[:, 1]).astype(int):
        values, counts = np.unique(labels[labels[:, 1] == ped, 2].astype(int), return_counts=True)
        by_label.setdefault(int(values[np.argmax(counts)]), []).append(int(ped))
    assert sorted(map(sorted, groups)) == sorted(sorted(m) for m in by_label.values() if len(m) >= 2)


def test_events_make_labels_change_over_time(tmp_path):
    paths = generate(EVENTFUL, RunSpec(duration_s=60.0, seed=1), tmp_path, name="run")
    labels = np.loadtxt(paths["labels"], delimiter="\t").astype(int)
    per_ped: dict[int, set[int]] = {}
    for _, ped, g in labels:
        per_ped.setdefault(ped, set()).add(g)
    assert sum(len(v) > 1 for v in per_ped.values()) >= 3  # some pedestrians left or merged


def test_read_groups_file_rejects_garbage(tmp_path):
    bad = tmp_path / "g.txt"
    bad.write_text("1 2\n\n3 x\n")
    with pytest.raises(ValueError, match=r"g\.txt:3"):
        read_groups_file(bad)


def test_cli_generate_and_dataset_layout(tmp_path, capsys):
    assert main(["generate", "--scenario", "corridor", "--pedestrians", "12", "--duration", "8",
                 "--seed", "2", "--out", str(tmp_path / "one")]) == 0
    assert (tmp_path / "one" / "corridor_n12_s2.txt").exists()
    assert main(["dataset", "--scenarios", "corridor,circle_crossing", "--seeds-per-scenario", "3",
                 "--pedestrians", "10", "--duration", "8", "--out", str(tmp_path / "ds")]) == 0
    for split in ("train", "val", "test"):
        assert len(list((tmp_path / "ds" / split).glob("*.groups.txt"))) == 2
    assert main(["generate", "--scenario", "mall", "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()


def test_rerun_recording_holds_every_frame_colour_coded_by_group(tmp_path):
    rerun_chunk = pytest.importorskip("rerun.chunk")
    paths = generate(SimConfig(scenario="plaza", n_pedestrians=20), RunSpec(duration_s=8.0, seed=0),
                     tmp_path, name="run", rrd=True)
    rows = np.loadtxt(paths["trajectories"], delimiter="\t")
    n_frames, n_points, first = 0, 0, None
    for chunk in rerun_chunk.RrdReader(paths["rrd"]).stream():
        if str(chunk.entity_path) != "/world/pedestrians":
            continue
        batch = chunk.to_record_batch()
        positions = batch.column(batch.schema.names.index("Points2D:positions")).to_pylist()
        classes = batch.column(batch.schema.names.index("Points2D:class_ids")).to_pylist()
        n_frames += chunk.num_rows
        n_points += sum(len(p) for p in positions)
        assert all(len(c) == len(p) for c, p in zip(classes, positions, strict=True))
        first = first if first is not None else np.array(positions[0])
    assert n_frames == 21 and n_points == len(rows)
    frame0 = rows[rows[:, 0] == 0][:, 2:4]
    np.testing.assert_allclose(np.sort(first[:, 0]), np.sort(frame0[:, 0]), atol=1e-3)
    np.testing.assert_allclose(np.sort(-first[:, 1]), np.sort(frame0[:, 1]), atol=1e-3)  # y-down view
