"""ReplayCrowd: recorded pedestrians replayed behind the env's Crowd protocol."""

from __future__ import annotations

from dataclasses import replace
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest

from crowdsim.config import SimConfig
from crowdsim.generate import RunSpec, generate
from envs.crowds.replay import ReplayConfig, ReplayCrowd, assign_slots, infer_frame_increment
from predictor.ethucy import DEFAULT_DATA_DIR, read_groups

ETH_UCY = DEFAULT_DATA_DIR.absolute()  # resolved before any test changes the working folder

# ped 1 over frames 0..20, ped 2 over 10..30, ped 3 only at 30; 10 frame ids per 0.4 s step
ROWS = """0\t1\t0.13\t0.27
10\t1\t1.17\t0.31
20\t1\t2.29\t2.03
10\t2\t5.11\t5.07
20\t2\t5.13\t6.19
30\t2\t5.17\t7.23
30\t3\t9.0\t1.0
"""


def _write(tmp_path: Path, text: str, name: str = "rec.txt") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _crowd(tmp_path: Path, text: str = ROWS, **kw) -> ReplayCrowd:
    kw.setdefault("start_mode", "fixed")
    return ReplayCrowd(ReplayConfig(path=_write(tmp_path, text), **kw))


def _by_id(state) -> dict[int, np.ndarray]:
    return {int(p): state.pos[r] for r, p in enumerate(state.ped_id) if state.active[r]}


def _episode(crowd: ReplayCrowd, seed: int | None, steps: int) -> list:
    return [crowd.reset(seed)] + [crowd.step() for _ in range(steps)]


def test_annotated_times_match_the_file_and_midway_is_the_average(tmp_path):
    states = _episode(_crowd(tmp_path), 0, 12)  # dt 0.1 s: every 4th step is an annotated frame
    table = np.loadtxt(tmp_path / "rec.txt")
    for k in range(4):
        frame_rows = table[table[:, 0] == 10 * k]
        got = _by_id(states[4 * k])
        for _, ped, x, y in frame_rows:
            np.testing.assert_array_equal(got[int(ped)], [x, y])  # exact, not approximate
    mid = _by_id(states[2])  # 0.2 s: halfway between frames 0 and 10
    np.testing.assert_allclose(mid[1], [(0.13 + 1.17) / 2, (0.27 + 0.31) / 2], rtol=0, atol=1e-12)
    # velocity: the slope of the current segment, m/s
    s = states[6]
    row = int(np.flatnonzero(s.ped_id == 1)[0])
    np.testing.assert_allclose(s.vel[row], [(2.29 - 1.17) / 0.4, (2.03 - 0.31) / 0.4])
    np.testing.assert_allclose(s.goal[row], [2.29, 2.03])  # a pedestrian's goal is its last position
    assert s.frame == 6 and s.time_s == pytest.approx(0.6)


def test_velocity_is_consistent_with_the_interpolation(tmp_path):
    crowd = _crowd(tmp_path)
    states = _episode(crowd, 0, 12)
    for a, b in pairwise(states):
        both = a.active & b.active & (a.ped_id == b.ped_id)
        # forward differences equal the velocity of the earlier state (piecewise-linear tracks)
        np.testing.assert_allclose((b.pos[both] - a.pos[both]) / crowd.dt_s, a.vel[both], atol=1e-9)


def test_pedestrians_are_active_only_within_their_tracks(tmp_path):
    crowd = _crowd(tmp_path)
    states = _episode(crowd, 0, 14)
    present = [set(_by_id(s)) for s in states]
    assert all((1 in p) == (0 <= k <= 8) for k, p in enumerate(present))
    assert all((2 in p) == (4 <= k <= 12) for k, p in enumerate(present))
    assert [k for k, p in enumerate(present) if 3 in p] == [12]  # a single annotation: one instant
    for s in states:  # unused rows are blank
        assert np.all(np.isnan(s.pos[~s.active])) and np.all(s.ped_id[~s.active] == -1)
    assert crowd.duration_s == pytest.approx(1.2)
    assert states[12].n_active == 2  # ped 2's last instant and ped 3's only one
    assert states[13].n_active == 0 and crowd.finished  # the recording is over: the crowd empties


def test_rows_are_stable_and_capacity_is_the_peak_count(tmp_path):
    crowd = _crowd(tmp_path)
    assert crowd.capacity == 2  # at most two pedestrians at once (ped 3 appears as ped 1 is long gone)
    rows: dict[int, set[int]] = {}
    for s in _episode(crowd, 0, 12):
        assert s.pos.shape == (2, 2) and s.active.shape == (2,)
        for r in np.flatnonzero(s.active):
            rows.setdefault(int(s.ped_id[r]), set()).add(int(r))
    assert all(len(r) == 1 for r in rows.values())  # a pedestrian keeps its row
    assert _crowd(tmp_path, capacity=5).capacity == 5
    with pytest.raises(ValueError, match="capacity"):
        _crowd(tmp_path, capacity=1)
    slots = assign_slots(np.array([0.0, 1.0, 2.0, 2.0]), np.array([2.0, 3.0, 4.0, 2.0]))
    assert len(set(slots[[0, 1, 2]])) == 3 and len(set(slots[[1, 2, 3]])) == 3  # closed intervals


def test_float_ids_whitespace_and_inferred_frame_increment(tmp_path):
    text = "0.0 7.0 1.0 1.0\n6.0   7.0\t2.0  1.0\n\n12.0\t7.0 3.0 1.0\n24.0 8.0 0.0 0.0\n"
    crowd = _crowd(tmp_path, text, frame_step_s=0.5, dt_s=0.25)
    assert infer_frame_increment(np.array([0.0, 6.0, 12.0, 24.0])) == 6.0
    assert list(crowd.ped_ids) == [7, 8]
    assert crowd.duration_s == pytest.approx(2.0)  # frames 0..24 = 4 steps of 0.5 s
    ids, pos, _ = crowd.positions_at(0.75)  # frame 9: halfway between frames 6 and 12
    assert list(ids) == [7]
    np.testing.assert_allclose(pos[0], [2.5, 1.0])
    given = _crowd(tmp_path, text, frame_increment=12.0)
    assert given.duration_s == pytest.approx(0.8)


def test_groups_from_a_synthetic_group_file(tmp_path):
    text = "".join(f"0\t{p}\t{p}.0\t0.0\n10\t{p}\t{p}.0\t1.0\n" for p in (1, 2, 3, 4, 5, 6))
    groups = _write(tmp_path, "4 5 3\n\n  \n1 2 99\n", "g.txt")  # 99: not in the recording, ignored
    state = _crowd(tmp_path, text, groups_path=groups).reset(0)
    g = {int(p): int(state.group_id[r]) for r, p in enumerate(state.ped_id) if state.active[r]}
    assert g[1] == g[2] and g[3] == g[4] == g[5]
    assert len({g[1], g[3], g[6]}) == 3  # 6 is unlisted: its own group
    assert sorted(set(g.values())) == [0, 1, 2]  # dense over the active rows
    alone = _crowd(tmp_path, text).reset(0)
    assert sorted(alone.group_id[alone.active]) == list(range(6))  # no group file: everyone alone


def test_groups_of_a_crowdsim_export_share_ids(tmp_path):
    paths = generate(SimConfig(scenario="plaza", n_pedestrians=12), RunSpec(duration_s=6.0, seed=1),
                     tmp_path, name="sim")
    listed = read_groups(paths["groups"])
    assert any(len(m) >= 2 for m in listed)
    crowd = ReplayCrowd(ReplayConfig(path=paths["trajectories"], groups_path=paths["groups"],
                                     start_mode="fixed"))
    table = np.loadtxt(paths["trajectories"])
    for k, s in enumerate(_episode(crowd, None, 24)):
        gid = {int(p): int(s.group_id[r]) for r, p in enumerate(s.ped_id) if s.active[r]}
        for members in listed:
            assert len({gid[m] for m in members if m in gid}) <= 1
        if k % 4 == 0:  # an exported frame: replayed positions are the file's
            rows = table[table[:, 0] == 10 * (k // 4)]
            got = _by_id(s)
            np.testing.assert_array_equal(np.array([got[int(p)] for p in rows[:, 1]]), rows[:, 2:4])


def test_same_seed_gives_the_same_episode(tmp_path):
    text = "".join(f"{10 * f}\t{p}\t{p + 0.1 * f}\t{0.2 * f}\n" for p in range(4) for f in range(40))
    crowd = _crowd(tmp_path, text, start_mode="random", min_remaining_s=2.0)
    a, b = _episode(crowd, 3, 5), _episode(crowd, 3, 5)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.pos, y.pos)
    starts = set()
    for seed in range(20):
        crowd.reset(seed)
        starts.add(crowd.start_time_s)
        assert 0.0 <= crowd.start_time_s <= crowd.duration_s - 2.0
    assert len(starts) == 20
    fixed = _crowd(tmp_path, text, start_time_s=1.0)
    fixed.reset(1)
    assert fixed.start_time_s == 1.0 and fixed.reset(2) is not None and fixed.start_time_s == 1.0
    assert fixed.recording_time_s == 1.0


def test_the_robot_does_not_move_pedestrians(tmp_path):
    free, pushed = _crowd(tmp_path), _crowd(tmp_path)
    a, b = [free.reset(0)], [pushed.reset(0)]
    for _ in range(12):
        pos = np.nan_to_num(b[-1].pos[b[-1].active][:1]).reshape(-1)[:2]
        pushed.set_robot(pos if pos.size else np.zeros(2), np.array([1.0, 0.0]), 0.5)
        a.append(free.step())
        b.append(pushed.step())
    assert pushed.robot is not None and pushed.robot[2] == 0.5
    pushed.clear_robot()
    assert pushed.robot is None
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.pos, y.pos)
        np.testing.assert_array_equal(x.vel, y.vel)


def test_walls_and_bounds(tmp_path):
    crowd = _crowd(tmp_path, bounds_margin_m=0.5)
    assert crowd.walls.shape == (0, 2, 2)
    assert crowd.bounds == pytest.approx((0.13 - 0.5, 0.27 - 0.5, 9.0 + 0.5, 7.23 + 0.5))
    walled = _crowd(tmp_path, walls=[[[-3.0, 0.0], [-3.0, 5.0]]], bounds_margin_m=0.0)
    assert walled.walls.shape == (1, 2, 2) and walled.bounds[0] == -3.0
    again = replace(walled.config, dt_s=0.2)  # what the env does with its own step
    assert again.walls == walled.config.walls and again.dt_s == 0.2
    assert crowd.name == "rec"


def test_robot_route_crosses_the_long_axis_and_avoids_pedestrians(tmp_path):
    # a 20 m x 8 m scene; pedestrian 1 stands still where left-side starts are likely
    text = "0 1 1.5 4.0\n400 1 1.5 4.0\n0 2 0.0 0.0\n400 2 20.0 8.0\n"
    crowd = _crowd(tmp_path, text)
    crowd.reset(0)
    sides = set()
    for seed in range(40):
        start, goal = crowd.robot_route(np.random.default_rng(seed))
        assert {start[0], goal[0]} == {1.5, 18.5}  # inset by the 1.5 m margin
        assert 2.0 <= start[1] <= 6.0 and 2.0 <= goal[1] <= 6.0  # middle half of the short side
        assert np.linalg.norm(start - [1.5, 4.0]) > 0.75  # clear of the standing pedestrian
        sides.add(start[0])
    assert sides == {1.5, 18.5}


@pytest.mark.parametrize("row, what", [
    ("20 1 2.0", "expected 4 fields"),
    ("20 1 2.0 1.0 7", "expected 4 fields"),
    ("20 1 abc 1.0", "non-numeric"),
    ("20 1 nan 1.0", "non-finite"),
    ("20 1 1.0 inf", "non-finite"),
    ("20 1.5 1.0 1.0", "whole number"),
    ("10 1 1.0 1.0", "twice"),
])
def test_malformed_rows_name_file_and_line(tmp_path, row, what):
    path = _write(tmp_path, f"0 1 0.0 0.0\n10 1 1.0 1.0\n\n{row}\n", "bad.txt")
    with pytest.raises(ValueError, match=rf"bad\.txt:4: .*{what}"):
        ReplayCrowd(ReplayConfig(path=path))


def test_empty_files_and_bad_group_files(tmp_path):
    with pytest.raises(ValueError, match="empty"):
        ReplayCrowd(ReplayConfig(path=_write(tmp_path, "\n\n", "none.txt")))
    for text, line in (("1 2\n\n3 x\n", 3), ("1 2\n2 3\n", 2), ("1 2.5\n", 1)):
        with pytest.raises(ValueError, match=rf"g\.txt:{line}"):
            read_groups(_write(tmp_path, text, "g.txt"))


@pytest.mark.parametrize("kw", [dict(dt_s=0.0), dict(frame_step_s=-1.0), dict(start_mode="later"),
                                dict(capacity=0), dict(walls=[[1.0, 2.0]]), dict(route_margin_m=float("nan"))])
def test_config_is_validated(kw):
    with pytest.raises(ValueError):
        ReplayConfig(path="x.txt", **kw)


def test_start_past_the_end_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="past the recording"):
        _crowd(tmp_path, start_time_s=10.0)


def test_replays_a_benchmark_file():
    path = ETH_UCY / "zara1" / "test" / "crowds_zara01.txt"
    if not path.exists():
        pytest.skip(f"shared ETH/UCY data not found at {path}")
    table = np.loadtxt(path)
    crowd = ReplayCrowd(ReplayConfig(path=path, start_mode="fixed"))
    ids = np.unique(table[:, 1]).astype(int)
    np.testing.assert_array_equal(crowd.ped_ids, ids)
    frames = np.unique(table[:, 0])
    assert crowd.duration_s == pytest.approx((frames[-1] - frames[0]) / 10 * 0.4)
    x0, y0, x1, y1 = crowd.bounds
    assert x0 < table[:, 2].min() and x1 > table[:, 2].max() and y0 < table[:, 3].min() and y1 > table[:, 3].max()
    first = {p: table[table[:, 1] == p, 0].min() for p in ids}
    last = {p: table[table[:, 1] == p, 0].max() for p in ids}
    present = [sum(first[p] <= f <= last[p] for p in ids) for f in frames]
    assert crowd.capacity == max(present)
    states = _episode(crowd, None, 40)
    for k in range(0, 41, 4):
        f = frames[0] + 10 * (k // 4)
        rows = table[table[:, 0] == f]
        got = _by_id(states[k])
        assert states[k].n_active == present[int(np.searchsorted(frames, f))]
        for _, p, x, y in rows:
            np.testing.assert_array_equal(got[int(p)], [x, y])


# ------------------------------------------------------------------------------------------ annotation rate
def test_the_frame_step_of_a_known_recording_comes_from_its_name(tmp_path):
    from envs.crowds.replay import DEFAULT_FRAME_STEP_S, KNOWN_FRAME_STEPS_S

    assert DEFAULT_FRAME_STEP_S == 0.4 and KNOWN_FRAME_STEPS_S["biwi_eth"] == pytest.approx(0.6667)
    steps = {name: ReplayConfig(path=tmp_path / name).frame_step_s
             for name in ("biwi_eth.txt", "biwi_eth_train.txt", "biwi_eth_val.txt", "biwi_hotel.txt",
                          "crowds_zara01.txt", "students003.txt", "uni_examples_train.txt", "rec.txt")}
    assert steps == {"biwi_eth.txt": 0.6667, "biwi_eth_train.txt": 0.6667, "biwi_eth_val.txt": 0.6667,
                     "biwi_hotel.txt": 0.4, "crowds_zara01.txt": 0.4, "students003.txt": 0.4,
                     "uni_examples_train.txt": 0.4, "rec.txt": 0.4}  # unknown files: the format's 0.4 s
    assert ReplayConfig(path=tmp_path / "biwi_eth.txt", frame_step_s=0.4).frame_step_s == 0.4  # given wins
    assert ReplayConfig(path="biwi_eth.txt") == ReplayConfig(path="biwi_eth.txt", frame_step_s=0.6667)
    # the rate is what the replay runs at: 3 annotated steps of biwi_eth last 2.0001 s, of another file 1.2 s
    rows = "".join(f"{10 * k}\t1\t{k:.1f}\t0.0\n" for k in range(4))
    eth, other = (ReplayCrowd(ReplayConfig(path=_write(tmp_path, rows, n))) for n in ("biwi_eth.txt", "other.txt"))
    assert eth.duration_s == pytest.approx(3 * 0.6667) and other.duration_s == pytest.approx(1.2)


def test_the_suites_state_the_same_rates_and_their_cells_are_unchanged():
    """The benchmark cells give frame_step_s explicitly; the table agrees with every one of them, so a replay of
    the same file without --frame-step runs exactly as the suite's cell does."""
    from envs.crowds.replay import known_frame_step
    from envs.evaluation.suite import load_suite, suite_names

    seen = 0
    for name in suite_names():
        for cell in load_suite(name).cells:
            if cell.is_real:
                for seed in cell.seeds[:2]:
                    replay = cell.env_config(seed).replay
                    assert replay.frame_step_s == cell.spec["frame_step_s"]
                    assert known_frame_step(replay.path) == cell.spec["frame_step_s"], (name, cell.name)
                    seen += 1
    assert seen >= 20


def test_cli_replay_of_biwi_eth_runs_at_its_own_rate_unless_told(tmp_path, capsys):
    from envs.cli import main

    rows = "".join(f"{10 * k}\t{p}\t{0.3 * k:.2f}\t{4.0 * p}\n" for k in range(60) for p in (1, 2))
    path = _write(tmp_path, rows, "biwi_eth.txt")
    base = ["evaluate", "--policy", "random", "--scenario", "replay", "--replay-file", str(path), "--episodes", "1",
            "--workers", "1", "--time-limit", "2", "--no-progress"]
    assert main([*base, "--out", str(tmp_path / "a")]) == 0
    assert capsys.readouterr().err == ""
    import json

    saved = json.loads((tmp_path / "a" / "random.json").read_text())
    assert saved["config"]["replay_frame_step_s"] == 0.6667
    assert main([*base, "--frame-step", "0.4", "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and "0.6667" in err[0]
    assert json.loads((tmp_path / "b" / "random.json").read_text())["config"]["replay_frame_step_s"] == 0.4


def test_a_group_file_listing_somebody_twice_is_refused_or_merged_and_said_once(tmp_path, capsys):
    from envs.cli import main

    rows = (f"{10 * t}\t{p}\t{0.4 * t:.1f}\t{p:.1f}\n" for t in range(60) for p in (1, 2, 3, 4))
    rec = _write(tmp_path, "".join(rows))
    groups = _write(tmp_path, "1 2\n2 3\n", "g.txt")
    with pytest.raises(ValueError, match="already listed"):
        ReplayCrowd(ReplayConfig(path=rec, groups_path=groups))
    crowd = ReplayCrowd(ReplayConfig(path=rec, groups_path=groups, group_overlaps="merge"))
    state = crowd.reset(0)
    ids = dict(zip(state.ped_id[state.active].tolist(), state.group_id[state.active].tolist(), strict=True))
    assert ids[1] == ids[2] == ids[3] != ids[4]  # 1, 2 and 3 walk together after the merge
    note = f"{groups}: pedestrian 2 is listed on lines 1 and 2: their groups are merged into one"
    assert crowd.group_notes == (note,)
    with pytest.raises(ValueError, match="valid: error, merge"):
        ReplayConfig(path=rec, group_overlaps="union")
    base = ["evaluate", "--policy", "random", "--scenario", "replay", "--replay-file", str(rec), "--groups-file",
            str(groups), "--episodes", "1", "--time-limit", "1", "--workers", "1", "--no-progress"]
    assert main([*base, "--out", str(tmp_path / "refused")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "already listed (line 1)" in err[0] and not (tmp_path / "refused").exists()
    assert main([*base, "--group-overlaps", "merge", "--out", str(tmp_path / "merged")]) == 0
    assert capsys.readouterr().err.splitlines() == [f"crowdnav: warning: {crowd.group_notes[0]}"]
    assert main(["evaluate", "--policy", "random", "--group-overlaps", "merge", "--out", str(tmp_path / "x")]) == 2


def test_group_intrusion_is_measured_only_with_a_group_file(tmp_path):
    """A recording without a group file has no labels: the crowd says so and the episode's group intrusion is None
    (printed n/a); with the file it is a measurement (a bool)."""
    from envs import CrowdNavConfig
    from envs.evaluation.episode import episode_record, run_episode
    from envs.policies import PolicyConfig

    text = "".join(f"{10 * f}\t{p}\t{p + 0.1 * f}\t{0.5 * p}\n" for f in range(200) for p in (1, 2, 3))
    rec, groups = _write(tmp_path, text), _write(tmp_path, "1 2\n", "g.txt")
    for groups_path, labelled in ((None, False), (groups, True)):
        replay = ReplayConfig(path=rec, groups_path=groups_path, start_mode="fixed")
        assert ReplayCrowd(replay).group_labels is labelled
        env = CrowdNavConfig(scenario="replay", replay=replay, time_limit_s=2.0, warmup_s=0.0)
        record = episode_record(run_episode(env, PolicyConfig("random"), seed=0), "random", 0)
        assert (record.group_intrusion is not None) is labelled
        assert (record.intrusion_fraction is not None) is labelled
