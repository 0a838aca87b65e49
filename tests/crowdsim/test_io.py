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
    written = np.loadtxt(tmp_path / "one" / "corridor_n12_s2.txt", ndmin=2)
    groups = (tmp_path / "one" / "corridor_n12_s2.groups.txt").read_text().split("\n")
    summary = capsys.readouterr().out.strip().splitlines()[-1]  # what the summary line reports is what was written
    assert summary.startswith(f"{len(written)} rows, {len(np.unique(written[:, 1]))} pedestrians, "
                              f"{sum(bool(g.strip()) for g in groups)} groups of 2+ -> ")
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


def test_vectorised_text_is_byte_identical_to_python_formatting():
    """The export texts are built with numpy; they must equal the plain f-string formatting byte for byte,
    including Python's half-to-even rounding of exact ties (multiples of 1/32), "-0.0000" for negative values
    that round to zero, multi-digit-group ids, and the fallback for non-finite values."""
    from crowdsim.export import (
        _fixed4_chars,
        labels_text,
        labels_text_reference,
        trajectories_text,
        trajectories_text_reference,
    )

    rng = np.random.default_rng(0)
    xs = np.concatenate([
        rng.uniform(-100.0, 100.0, 3000), np.round(rng.uniform(-50.0, 50.0, 3000), 5),
        np.arange(-256, 257) / 32.0,  # exact ties at the 4th decimal: 0.03125 -> 0.0312, 0.09375 -> 0.0938
        np.arange(-300, 300) / 20000.0,  # near-ties that are not exact in binary
        [0.0, -0.0, 1e-9, -1e-9, -0.00004999, 0.00005, -0.00005, 9999.99995, 123456.78905, -500000.0],
    ])
    n = len(xs)
    table = np.column_stack([np.arange(n) * 10 // 7 * 10, rng.integers(1, 10**9, n), xs, xs[::-1],
                             rng.integers(-1, 10**5, n)]).astype(float)
    assert _fixed4_chars(xs) is not None  # the vectorised path, not the fallback
    assert trajectories_text(table) == trajectories_text_reference(table)
    assert labels_text(table) == labels_text_reference(table)
    small = table[:50].copy()
    small[:, 1] = np.arange(50)  # ids that fit one 4-digit look-up, with a zero
    assert trajectories_text(small) == trajectories_text_reference(small)
    small[2, 2] = 123456789.12345  # beyond the exact fast path
    small[3, 2] = np.nan
    small[4, 3] = -np.inf
    assert trajectories_text(small) == trajectories_text_reference(small)  # falls back: "nan", "-inf"
    assert trajectories_text(table[:0]) == labels_text(table[:0]) == ""


def test_trajectory_log_orders_rows_and_majority_labels_break_ties_by_smallest():
    from crowdsim.export import TrajectoryLog, majority_labels
    from crowdsim.state import CrowdState

    def state(frame, peds, labels):
        k = len(peds)
        return CrowdState(pos=np.c_[np.arange(k), -np.arange(k)].astype(float), vel=np.zeros((k, 2)),
                          goal=np.zeros((k, 2)), radius=np.full(k, 0.2), group_id=np.zeros(k, np.int64),
                          ped_id=np.array(peds), active=np.array(peds) > 0, label=np.array(labels),
                          frame=frame, time_s=0.4 * frame)

    states = [state(1, [5, 2, -1, 9], [7, 3, -1, 7]), state(0, [2, 5], [3, 4]), state(2, [9, 5, 2], [7, 7, 4])]
    log = TrajectoryLog()
    for s in states:
        log.add(s)
    table = log.table()  # added out of frame order: sorted by frame, then ped id
    assert table[:, :2].tolist() == [[0, 2], [0, 5], [10, 2], [10, 5], [10, 9], [20, 2], [20, 5], [20, 9]]
    in_order = TrajectoryLog()
    for s in sorted(states, key=lambda s: s.frame):
        in_order.add(s)
    np.testing.assert_array_equal(in_order.table(), table)
    # ped 2: labels 3, 3, 4 -> 3; ped 5: 4, 7, 7 -> 7; ped 9: 7, 7 -> 7; a tie goes to the smaller label
    assert majority_labels(table) == {2: 3, 5: 7, 9: 7}
    assert majority_labels(table[[0, 1, 3]]) == {2: 3, 5: 4}  # ped 5: labels 4 and 7 once each
