"""Compiled (numba) clearance kernels of the sampling arbiter (planner/sampling.py), imported on first use so that
`import planner` stays numpy + casadi."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def person_clearance(points: np.ndarray, futures: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Smallest centre distance minus the person's radius (m), robot points (C, T, 2) against futures (F, T, n, 2)
    with radii (n,): (C, F, T); +inf without people."""
    c, t = points.shape[0], points.shape[1]
    f, n = futures.shape[0], futures.shape[2]
    out = np.full((c, f, t), np.inf)
    for a in range(c):
        for b in range(f):
            for s in range(t):
                px, py = points[a, s, 0], points[a, s, 1]
                best = np.inf
                for j in range(n):
                    dx, dy = px - futures[b, s, j, 0], py - futures[b, s, j, 1]
                    d = np.sqrt(dx * dx + dy * dy) - radii[j]
                    if d < best:
                        best = d
                out[a, b, s] = best
    return out


@numba.njit(cache=True)
def capsule_clearance(points: np.ndarray, seg: np.ndarray, rad: np.ndarray) -> np.ndarray:
    """Smallest distance to a capsule's axis minus its radius (m), robot points (C, T, 2) against capsules seg
    (F, T, G, 4) (x0, y0, x1, y1) with radii rad (F, T, G): (C, F, T); +inf without capsules."""
    c, t = points.shape[0], points.shape[1]
    f, g = seg.shape[0], seg.shape[2]
    out = np.full((c, f, t), np.inf)
    for a in range(c):
        for b in range(f):
            for s in range(t):
                px, py = points[a, s, 0], points[a, s, 1]
                best = np.inf
                for j in range(g):
                    ax, ay, bx, by = seg[b, s, j, 0], seg[b, s, j, 1], seg[b, s, j, 2], seg[b, s, j, 3]
                    ex, ey = bx - ax, by - ay
                    den = ex * ex + ey * ey
                    u = 0.0 if den < 1e-12 else min(max(((px - ax) * ex + (py - ay) * ey) / den, 0.0), 1.0)
                    dx, dy = px - ax - u * ex, py - ay - u * ey
                    d = np.sqrt(dx * dx + dy * dy) - rad[b, s, j]
                    if d < best:
                        best = d
                out[a, b, s] = best
    return out
