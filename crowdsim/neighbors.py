"""Neighbour search: all pairs closer than a cut-off, via a uniform cell grid compiled with numba.

Cost is linear in the number of pedestrians for a bounded density. Compilation is cached on disk
(`cache=True`) so only the first run on a machine pays it.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _grid_pairs(pos: np.ndarray, cutoff: float, cap: int) -> tuple[np.ndarray, np.ndarray, bool]:
    n = pos.shape[0]
    if n < 2:
        return np.empty(0, np.int64), np.empty(0, np.int64), False
    xmin, ymin = pos[:, 0].min(), pos[:, 1].min()
    nx = int((pos[:, 0].max() - xmin) / cutoff) + 1
    ny = int((pos[:, 1].max() - ymin) / cutoff) + 1
    cell = np.empty(n, np.int64)
    for k in range(n):
        cell[k] = int((pos[k, 0] - xmin) / cutoff) * ny + int((pos[k, 1] - ymin) / cutoff)
    start = np.zeros(nx * ny + 1, np.int64)
    for k in range(n):
        start[cell[k] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    order = np.empty(n, np.int64)  # counting sort by cell, stable
    fill = start[:-1].copy()
    xs = np.empty(n)
    ys = np.empty(n)
    for k in range(n):
        slot = fill[cell[k]]
        order[slot] = k
        xs[slot] = pos[k, 0]
        ys[slot] = pos[k, 1]
        fill[cell[k]] += 1
    offset_y = np.array([0, 1, -1, 0, 1])
    out_i = np.empty(cap, np.int64)
    out_j = np.empty(cap, np.int64)
    m = 0
    c2 = cutoff * cutoff
    for c in range(nx * ny):
        if start[c] == start[c + 1]:
            continue
        cx, cy = c // ny, c % ny
        for s in range(5):  # half stencil: self, then (0,+1), (+1,-1), (+1,0), (+1,+1)
            ox = 0 if s < 2 else 1
            oy = offset_y[s]
            x, y = cx + ox, cy + oy
            if x >= nx or y < 0 or y >= ny:
                continue
            d = x * ny + y
            for a in range(start[c], start[c + 1]):
                b0 = a + 1 if s == 0 else start[d]
                for b in range(b0, start[d + 1]):
                    dx = xs[a] - xs[b]
                    dy = ys[a] - ys[b]
                    if dx * dx + dy * dy < c2:
                        if m == cap:  # out of room: the caller retries with a larger buffer
                            return out_i, out_j, True
                        oa, ob = order[a], order[b]
                        out_i[m] = min(oa, ob)
                        out_j[m] = max(oa, ob)
                        m += 1
    return out_i[:m].copy(), out_j[:m].copy(), False


def neighbor_pairs(pos: np.ndarray, cutoff_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Unordered pairs (i < j) with |pos_i - pos_j| < cutoff_m.

    pos: (N, 2) metres, finite. Returns two int64 arrays (P,), sorted by (i, j) so that results do not
    depend on the grid traversal order.
    """
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise ValueError(f"pos must have shape (N, 2), got {pos.shape}")
    cap = 8 * len(pos) + 64
    while True:
        i, j, overflow = _grid_pairs(pos, float(cutoff_m), cap)
        if not overflow:
            return i, j
        cap *= 4


def brute_force_pairs(pos: np.ndarray, cutoff_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Reference O(N^2) implementation of `neighbor_pairs` (for tests and small crowds)."""
    i, j = np.triu_indices(len(pos), k=1)
    d = np.linalg.norm(pos[i] - pos[j], axis=1)
    keep = d < cutoff_m
    return i[keep].astype(np.int64), j[keep].astype(np.int64)

