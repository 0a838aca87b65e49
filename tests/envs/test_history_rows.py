"""The history window's newest rows alone (`PedHistory.window_now(rows=k)`, what the shielded agents read) are the
whole window's last k rows, bit for bit: with people arriving, leaving and coming back, off the 0.4 s tick and on."""

import numpy as np
import pytest

from envs.history import PedHistory


def _random_history(rng: np.random.Generator, n_ticks: int) -> tuple[PedHistory, np.ndarray, np.ndarray]:
    """A history of n_ticks snapshots of up to 12 people, each present at a tick with probability 0.7 (so some leave
    and come back), observed at the control rate; and the people present now (ids, positions)."""
    hist = PedHistory()
    ids_all = np.arange(100, 112)
    walk = rng.normal(0.0, 1.0, (12, 2)) + np.cumsum(rng.normal(0.0, 0.1, (n_ticks * 4 + 1, 12, 2)), axis=0)
    for step in range(n_ticks * 4 + 1):
        present = rng.random(12) < 0.7
        if step % 4 == 0:
            present_tick = present
            hist.record(ids_all[present_tick], walk[step][present_tick])
        hist.observe(0.1 * step, ids_all[present], walk[step][present])
    now = rng.random(12) < 0.8
    return hist, ids_all[now], walk[-1][now] + rng.normal(0.0, 0.05, (int(now.sum()), 2))


@pytest.mark.parametrize("rows", [1, 2, 3, 8])
def test_the_newest_rows_are_the_whole_windows_last_rows(rows):
    rng = np.random.default_rng(rows)
    checked = 0
    for trial in range(300):
        hist, ids, pos = _random_history(rng, int(rng.integers(1, 12)))
        frac = 0.0 if trial % 3 == 0 else float(rng.choice([0.25, 0.5, 0.75]))
        if frac == 0.0:  # on the tick everyone must be in the newest snapshot: ask for those
            ids, pos = hist._snaps[-1]
        full = hist.window_now(ids, pos, frac, 0.4)
        short = hist.window_now(ids, pos, frac, 0.4, rows=rows)
        assert short.shape == (rows, len(ids), 2)
        assert short.tobytes() == full[-rows:].tobytes()
        checked += 1
    assert checked == 300


def test_rows_out_of_range_is_an_error():
    hist = PedHistory()
    hist.record(np.array([1]), np.zeros((1, 2)))
    for rows in (0, 9):
        with pytest.raises(ValueError, match=r"rows must be in 1\.\.8"):
            hist.window_now(np.array([1]), np.zeros((1, 2)), 0.0, 0.4, rows=rows)


def test_the_track_is_the_window_extended_back_over_what_was_seen():
    """`track_now` (what a group rule reads): its newest 8 rows are the predictor's window bit for bit; the older rows
    are the recorded positions (interpolated off the tick like the window's), NaN before a pedestrian's first one."""
    rng = np.random.default_rng(7)
    for trial in range(200):
        n_ticks = int(rng.integers(1, 30))
        hist, longer = PedHistory(8), PedHistory(24)
        ids_all = np.arange(100, 106)
        first_tick = rng.integers(0, n_ticks, size=6)  # each person arrives at some tick and stays
        walk = np.cumsum(rng.normal(0.0, 0.1, (n_ticks * 4 + 1, 6, 2)), axis=0)
        for step in range(n_ticks * 4 + 1):
            present = first_tick <= step // 4
            if step % 4 == 0:
                hist.record(ids_all[present], walk[step][present])
                longer.record(ids_all[present], walk[step][present])
            hist.observe(0.1 * step, ids_all[present], walk[step][present])
        frac = 0.0 if trial % 2 == 0 else 0.5
        ids, pos = hist._snaps[-1] if frac == 0.0 else (ids_all, walk[-1] + 0.01)
        window = hist.window_now(ids, pos, frac, 0.4)
        track = longer.track_now(ids, pos, frac, window)
        assert track.shape == (24, len(ids), 2) and track[-8:].tobytes() == window.tobytes()
        kept = min(n_ticks + 1, 24)  # snapshots recorded at ticks 0..n_ticks, the newest 24 kept
        for k, pid in enumerate(ids.tolist()):
            seen_rows = min(n_ticks - int(first_tick[pid - 100]) + 1, kept)  # its snapshots among the kept
            unseen = min(24 - seen_rows, 16)  # rows before its first kept snapshot, older than the window
            assert np.isnan(track[:unseen, k]).all() and not np.isnan(track[unseen:, k]).any()
            if frac == 0.0:  # on the tick the older rows are the snapshots themselves
                snaps = [snap_pos[list(snap_ids).index(pid)] for snap_ids, snap_pos in list(longer._snaps)[-seen_rows:]
                         if pid in snap_ids]
                np.testing.assert_array_equal(track[unseen:16, k], np.array(snaps)[: 16 - unseen])
    with pytest.raises(ValueError, match="window must be"):
        longer.track_now(ids, pos, frac, np.zeros((25, len(ids), 2)))
