"""Pedestrian position history at the predictor's 0.4 s step, keyed by pedestrian identity.

Besides the 0.4 s snapshots, the history notes when each pedestrian was first seen (at the env's control rate)
and its velocity over its first `EARLY_WINDOW_S` in view. A pedestrian seen for less than the window's 2.8 s
has no recorded past; `extrapolate_back` fills those rows by running that early velocity backwards, so the
predictors and the constant-velocity baselines see a walker who has just come into view walking, not standing.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from envs.timing import DEFAULT_TIMING

EARLY_WINDOW_S = 0.4  # a pedestrian's velocity is measured over its first this-many seconds in view, s
# snapshots the env keeps for the group rules' track: 19.2 s at 0.4 s, `coherent-motion-track`'s length (chosen on the
# UCY validation, RESULTS.md "sim-to-real")
TRACK_ROWS = 48


@dataclass
class _Arrival:
    """When a pedestrian was first seen (time_s, s; pos (2,) m) and its mean velocity since (vel (2,) m/s,
    fixed once it has been in view for `EARLY_WINDOW_S`)."""

    time_s: float
    pos: np.ndarray
    vel: np.ndarray


class PedHistory:
    """The last `length` snapshots (ped ids (n,), positions (n, 2) m), one per 0.4 s tick, and each present
    pedestrian's arrival (`observe`, every control step)."""

    def __init__(self, length: int = DEFAULT_TIMING.obs_len) -> None:
        self.length = length
        self._snaps: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=length)
        self._arrivals: dict[int, _Arrival] = {}
        self._rows: dict[int, int] = {}  # ped id -> row in the last observed ids
        self._ids_key = b""
        self._young: set[int] = set()  # ids still inside their early window

    def clear(self) -> None:
        self._snaps.clear()
        self._arrivals, self._rows, self._ids_key, self._young = {}, {}, b"", set()

    def __len__(self) -> int:
        return len(self._snaps)

    def times_seen(self, ped_id: int) -> int:
        """In how many of the kept snapshots (at most `length`) pedestrian `ped_id` appears."""
        return sum(int(ped_id) in ids for ids, _ in self._snaps)

    def record(self, ped_id: np.ndarray, pos: np.ndarray) -> None:
        """Add a snapshot: ids (n,) int and positions (n, 2) m of the pedestrians in the scene."""
        order = np.argsort(ped_id, kind="stable")
        self._snaps.append((np.asarray(ped_id)[order].copy(), np.asarray(pos, float)[order].copy()))

    def observe(self, time_s: float, ped_id: np.ndarray, pos: np.ndarray) -> None:
        """Note the pedestrians in view at time_s (s): ids (n,) int, positions (n, 2) m. Call it at every control
        step; it costs one comparison when nobody came, left or is inside the early window."""
        key = np.asarray(ped_id).tobytes()
        if key == self._ids_key and not self._young:
            return
        if key != self._ids_key:
            self._ids_key = key
            ids = [int(i) for i in ped_id]
            self._rows = {i: k for k, i in enumerate(ids)}
            old, self._arrivals = self._arrivals, {}
            for k, i in enumerate(ids):
                arrival = old.get(i)
                if arrival is None:
                    arrival = _Arrival(float(time_s), np.array(pos[k], float), np.zeros(2))
                    self._young.add(i)
                self._arrivals[i] = arrival
            self._young &= self._arrivals.keys()
        for i in list(self._young):
            arrival = self._arrivals[i]
            age = time_s - arrival.time_s
            if age > 0:
                arrival.vel = (np.asarray(pos[self._rows[i]], float) - arrival.pos) / age
            if age >= EARLY_WINDOW_S - 1e-9:
                self._young.discard(i)

    def forget(self, ped_ids: list[int]) -> None:
        """Drop pedestrians ped_ids from every kept snapshot and from the arrivals, as if never seen: one who comes
        back is a newcomer, back-filled from its new early velocity (the env's limited view, `envs.perception`:
        someone out of sight is not in the history). Ids not held are ignored."""
        if not ped_ids:
            return
        gone = np.asarray(sorted(int(i) for i in ped_ids))
        kept = [(ids, pos) if not (hit := np.isin(ids, gone)).any() else (ids[~hit], pos[~hit])
                for ids, pos in self._snaps]
        self._snaps = deque(kept, maxlen=self.length)
        for i in gone.tolist():
            self._arrivals.pop(i, None)
        self._young -= set(gone.tolist())
        self._ids_key = b""  # the next `observe` rebuilds the rows from what is left

    def early_velocity(self, ped_id: np.ndarray) -> np.ndarray:
        """(n, 2) m/s: each pedestrian's mean velocity over its first `EARLY_WINDOW_S` in view (so far, if it came
        more recently); zero for one seen at a single instant or never observed."""
        out = np.zeros((len(ped_id), 2))
        for k, i in enumerate(np.asarray(ped_id).tolist()):
            arrival = self._arrivals.get(int(i))
            if arrival is not None:
                out[k] = arrival.vel
        return out

    def window_now(self, ped_id: np.ndarray, pos: np.ndarray, frac: float, step_s: float,
                   rows: int | None = None) -> np.ndarray:
        """(length, n, 2) m history of pedestrians ped_id (n,) now at pos (n, 2) m, `frac` (in [0, 1)) of a step_s
        snapshot interval after the newest snapshot, rows step_s apart and the last one now. Off the tick each
        row is interpolated between the two snapshots around its time; the rows before a pedestrian's first
        observation (its first snapshot, or now if it came after the newest one) are extrapolated back at its
        early velocity (`extrapolate_back`). `rows` (1 .. length): only the newest rows, (rows, n, 2), the whole
        window's last rows exactly, from the newest snapshots only (cheaper)."""
        snaps, first = self._window(ped_id, None if frac == 0.0 else pos, rows)
        out = _between_ticks(snaps, frac, pos)
        seen = first < len(out)  # in a snapshot (else only now: the current position stands in)
        if seen.all() and not first.any():
            return out  # everyone seen for the whole window
        anchor_row = np.where(seen, first, len(out) - 1)
        anchor_pos = np.where(seen[:, None], snaps[np.minimum(first, len(out) - 1), np.arange(len(first))], pos)
        lag = np.where(seen, frac * step_s, 0.0)
        return extrapolate_back(out, anchor_row, anchor_pos, lag, self.early_velocity(ped_id), step_s)

    def track_now(self, ped_id: np.ndarray, pos: np.ndarray, frac: float, window: np.ndarray) -> np.ndarray:
        """(length, n, 2) m: what a group rule reads (`predictor.api`'s `track`). Its newest rows are `window`
        (w, n, 2), the predictor's history window now (`window_now` of the env's obs_len history, extrapolated back
        where need be); the older rows are this history's snapshots on the same grid (interpolated off the tick as
        `window_now` does), NaN before each pedestrian's first kept snapshot (and where none is kept yet)."""
        w = len(window)
        if not 1 <= w <= self.length or window.shape[1:] != (len(ped_id), 2):
            raise ValueError(f"window must be (1..{self.length}, {len(ped_id)}, 2), got {window.shape}")
        snaps, first = self._window(ped_id, None if frac == 0.0 else pos)
        out = _between_ticks(snaps, frac, pos)  # a new array (`_window` makes one each call)
        out[np.arange(len(out))[:, None] < first[None]] = np.nan  # before its first snapshot (or only seen now)
        out[-w:] = window
        return out

    def window(self, ped_id: np.ndarray, current: np.ndarray | None = None) -> np.ndarray:
        """(length, n, 2) m history of pedestrians ped_id (n,), oldest first; the last row is the newest
        snapshot, which must contain every requested id unless `current` (n, 2) m is given to stand in for
        those missing from it. A pedestrian seen for fewer ticks is padded backwards with its earliest known
        position (standing still), so the array is always finite (`window_now` replaces the padding)."""
        return self._window(ped_id, current)[0]

    def _window(self, ped_id: np.ndarray, current: np.ndarray | None = None,
                rows: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """`window` (its newest `rows` rows; default all `length`) and, found in the same pass, (n,) int the oldest
        row holding a snapshot of each pedestrian (`rows` for one in no kept snapshot, whose rows are all
        `current`)."""
        if not self._snaps:
            raise RuntimeError("no snapshot recorded yet")
        length = self.length if rows is None else rows
        if not 1 <= length <= self.length:
            raise ValueError(f"rows must be in 1..{self.length}, got {rows}")
        ped_id = np.asarray(ped_id)
        out = np.empty((length, len(ped_id), 2))
        first = np.full(len(ped_id), length)
        kept = list(self._snaps)
        snaps = kept[-length:]
        row = length - 1
        for ids, pos in reversed(snaps):
            loc = np.clip(np.searchsorted(ids, ped_id), 0, max(len(ids) - 1, 0))
            found = (ids[loc] == ped_id) if len(ids) else np.zeros(len(ped_id), bool)
            if row == length - 1:
                if current is not None:
                    out[row] = np.where(found[:, None], pos[loc] if len(ids) else 0.0, current)
                elif not found.all():
                    raise KeyError(f"pedestrians {ped_id[~found].tolist()} are not in the newest snapshot")
                else:
                    out[row] = pos[loc]
            else:  # not seen at this tick: keep the next newer position
                out[row] = np.where(found[:, None], pos[loc] if len(ids) else 0.0, out[row + 1])
            first[found] = row
            row -= 1
        out[: row + 1] = out[row + 1]
        if length < len(kept) and (late := np.flatnonzero(first > 0)).size:  # seen in an older snapshot: no row before
            older = set().union(*(ids.tolist() for ids, _ in kept[: len(kept) - length]))
            first[[k for k in late.tolist() if int(ped_id[k]) in older]] = 0
        return out, first


def _between_ticks(snaps: np.ndarray, frac: float, pos: np.ndarray) -> np.ndarray:
    """Rows (L, n, 2) m `frac` of a snapshot interval after `snaps`' (L, n, 2): each interpolated between its
    snapshot and the next, the newest one `pos` (n, 2) now; `snaps` itself on the tick (frac 0)."""
    if frac == 0.0:
        return snaps
    out = np.empty_like(snaps)
    out[:-1] = (1.0 - frac) * snaps[:-1] + frac * snaps[1:]
    out[-1] = pos
    return out


def extrapolate_back(window: np.ndarray, anchor_row: np.ndarray, anchor_pos: np.ndarray, anchor_lag_s: np.ndarray,
                     velocity: np.ndarray, step_s: float) -> np.ndarray:
    """`window` (L, n, 2) m with the rows before each pedestrian's first observation filled at constant velocity.

    Pedestrian i was first observed at anchor_pos[i] (2,) m, at the time of row anchor_row[i] minus
    anchor_lag_s[i] s; rows r < anchor_row[i] (each `step_s` s apart) become
    anchor_pos[i] + velocity[i] * ((r - anchor_row[i]) * step_s + anchor_lag_s[i]). velocity (n, 2) m/s."""
    rows = np.arange(len(window))[:, None]
    dt = (rows - anchor_row[None]) * step_s + anchor_lag_s[None]  # (L, n) s, relative to the anchor
    filled = anchor_pos[None] + velocity[None] * dt[..., None]
    return np.where((rows < anchor_row[None])[..., None], filled, window)
