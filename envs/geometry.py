"""Vectorised geometry for the env: swept robot-pedestrian distances, wall distances, group regions.

Everything is a pure function of arrays (metres).
"""

from __future__ import annotations

import numpy as np


def swept_distances(robot0: np.ndarray, robot1: np.ndarray, peds0: np.ndarray, peds1: np.ndarray) -> np.ndarray:
    """Closest centre distances (N,) m over one step, robot moving robot0 -> robot1 (2,) and pedestrians
    peds0 -> peds1 (N, 2), all linearly in time (CrowdNav checks collisions along each step's motion)."""
    d0 = peds0 - robot0  # relative position at the step start
    dv = (peds1 - peds0) - (robot1 - robot0)  # relative displacement over the step
    denom = np.einsum("ij,ij->i", dv, dv)
    t = np.where(denom > 1e-12, -np.einsum("ij,ij->i", d0, dv) / np.maximum(denom, 1e-12), 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(d0 + t[:, None] * dv, axis=1)


def point_segment_distances(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances (S,) m from point p (2,) to segments segs (S, 2, 2)."""
    if len(segs) == 0:
        return np.zeros(0)
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    t = np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    closest = a + np.clip(t, 0.0, 1.0)[:, None] * ab
    return np.linalg.norm(p - closest, axis=1)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull (H, 2) of points (n, 2) (Andrew's monotone chain); collinear points
    collapse to the two ends, a single point to itself."""
    pts = np.unique(np.asarray(points, float), axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def chain(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2 and cross(out[-2], out[-1], p) <= 1e-12:
                out.pop()
            out.append(p)
        return out

    lower, upper = chain(pts), chain(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def distance_to_hull(p: np.ndarray, hull: np.ndarray) -> float:
    """Distance m from p (2,) to the convex polygon hull (H, 2) (counter-clockwise); 0 inside."""
    if len(hull) == 1:
        return float(np.linalg.norm(p - hull[0]))
    edges = np.stack([hull, np.roll(hull, -1, axis=0)], axis=1)
    if len(hull) == 2:
        edges = edges[:1]
    if len(hull) >= 3:
        e = edges[:, 1] - edges[:, 0]
        rel = p - edges[:, 0]
        if np.all(e[:, 0] * rel[:, 1] - e[:, 1] * rel[:, 0] >= 0.0):
            return 0.0
    return float(point_segment_distances(p, edges).min())


def intruded_groups(robot: np.ndarray, reach_m: float, pos: np.ndarray, radius: np.ndarray, group_id: np.ndarray,
                    max_span_m: float, dist: np.ndarray | None = None) -> list[int]:
    """Ground-truth groups whose region the robot enters. A group's region is the convex hull of its
    members' discs (pos (N, 2) m, radius (N,) m) grown by a personal-space margin; the robot enters it when
    its centre (2,) is closer than reach_m (robot radius + margin) + the largest member radius to the hull
    of the members' centres. Groups wider than max_span_m (largest pairwise centre distance, m) are skipped:
    they are not walking together at that moment. Only groups with a member within max_span_m + reach_m +
    0.5 m can qualify. dist (N,): robot-pedestrian centre
    distances, if already known."""
    if len(pos) == 0:
        return []
    if dist is None:
        dist = np.hypot(*(pos - robot).T)
    out = []
    for g in set(group_id[dist <= max_span_m + reach_m + 0.5].tolist()):
        sel = group_id == g
        members = pos[sel]
        if len(members) < 2:
            continue
        diff = members[:, None] - members[None]
        if np.einsum("ijk,ijk->ij", diff, diff).max() > max_span_m**2:
            continue
        if distance_to_hull(robot, convex_hull(members)) < reach_m + radius[sel].max():
            out.append(int(g))
    return sorted(out)
