"""Pedestrian position history at the predictor's 0.4 s step, keyed by pedestrian identity."""

from __future__ import annotations

from collections import deque

import numpy as np

from envs.timing import DEFAULT_TIMING


class PedHistory:
    """The last `length` snapshots (ped ids (n,), positions (n, 2) m), one per 0.4 s tick."""

    def __init__(self, length: int = DEFAULT_TIMING.obs_len) -> None:
        self.length = length
        self._snaps: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=length)

    def clear(self) -> None:
        self._snaps.clear()

    def __len__(self) -> int:
        return len(self._snaps)

    def times_seen(self, ped_id: int) -> int:
        """In how many of the kept snapshots (at most `length`) pedestrian `ped_id` appears."""
        return sum(int(ped_id) in ids for ids, _ in self._snaps)

    def record(self, ped_id: np.ndarray, pos: np.ndarray) -> None:
        """Add a snapshot: ids (n,) int and positions (n, 2) m of the pedestrians in the scene."""
        order = np.argsort(ped_id, kind="stable")
        self._snaps.append((np.asarray(ped_id)[order].copy(), np.asarray(pos, float)[order].copy()))

    def window(self, ped_id: np.ndarray, current: np.ndarray | None = None) -> np.ndarray:
        """(length, n, 2) m history of pedestrians ped_id (n,), oldest first; the last row is the newest
        snapshot, which must contain every requested id unless `current` (n, 2) m is given to stand in for
        those missing from it. A pedestrian seen for fewer ticks is padded backwards with its earliest known
        position (standing still), so the array is always finite."""
        if not self._snaps:
            raise RuntimeError("no snapshot recorded yet")
        ped_id = np.asarray(ped_id)
        out = np.empty((self.length, len(ped_id), 2))
        snaps = list(self._snaps)
        row = self.length - 1
        for ids, pos in reversed(snaps):
            loc = np.clip(np.searchsorted(ids, ped_id), 0, max(len(ids) - 1, 0))
            found = (ids[loc] == ped_id) if len(ids) else np.zeros(len(ped_id), bool)
            if row == self.length - 1:
                if current is not None:
                    out[row] = np.where(found[:, None], pos[loc] if len(ids) else 0.0, current)
                elif not found.all():
                    raise KeyError(f"pedestrians {ped_id[~found].tolist()} are not in the newest snapshot")
                else:
                    out[row] = pos[loc]
            else:  # not seen at this tick: keep the next newer position
                out[row] = np.where(found[:, None], pos[loc] if len(ids) else 0.0, out[row + 1])
            row -= 1
        out[: row + 1] = out[row + 1]
        return out
