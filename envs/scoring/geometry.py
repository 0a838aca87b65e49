"""Vectorised geometry for the env: swept robot-pedestrian distances, wall distances, group regions.

Everything is a pure function of arrays (metres).
"""

from __future__ import annotations

import math

import numpy as np

from planner import point_segment_distances as planner_segment_distances


def swept_distances(robot0: np.ndarray, robot1: np.ndarray, peds0: np.ndarray, peds1: np.ndarray) -> np.ndarray:
    """Closest centre distances (N,) m over one step, robot moving robot0 -> robot1 (2,) and pedestrians
    peds0 -> peds1 (N, 2), all linearly in time (CrowdNav checks collisions along each step's motion)."""
    d0 = peds0 - robot0  # relative position at the step start
    dv = (peds1 - peds0) - (robot1 - robot0)  # relative displacement over the step
    denom = np.einsum("ij,ij->i", dv, dv)
    t = np.where(denom > 1e-12, -np.einsum("ij,ij->i", d0, dv) / np.maximum(denom, 1e-12), 0.0)
    # = np.linalg.norm(d0 + clip(t, 0, 1) dv, axis=1): a -0.0 that np.clip would turn into 0.0 only flips the sign
    # of a zero added to d0, which squaring removes
    d = d0 + np.minimum(np.maximum(t, 0.0), 1.0)[:, None] * dv
    return np.sqrt(np.einsum("ij,ij->i", d, d))


def point_segment_distances(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances (S,) m from point p (2,) to segments segs (S, 2, 2): the planner's computation
    (`planner.point_segment_distances`, the project's one), on the env's (S, 2, 2) layout."""
    return planner_segment_distances(p, np.asarray(segs, float).reshape(-1, 4))


def ray_distances(origin: np.ndarray, angles: np.ndarray, segs: np.ndarray, max_range: float) -> np.ndarray:
    """Range readings (R,) m: how far each ray from origin (2,) at angles (R,) rad (world frame) travels before it
    meets a segment of segs (S, 2, 2); max_range where it meets none within max_range."""
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (R, 2)
    if len(segs) == 0:
        return np.full(len(d), float(max_range))
    a, e = segs[:, 0], segs[:, 1] - segs[:, 0]  # (S, 2)
    w = a - origin
    denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # cross(d, e): (R, S)
    safe = np.where(np.abs(denom) > 1e-12, denom, 1.0)
    t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / safe  # along the ray, m
    u = (w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]) / safe  # along the segment, 0..1
    hit = (np.abs(denom) > 1e-12) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
    return np.minimum(np.where(hit, t, np.inf).min(axis=1), float(max_range))


class WallIndex:
    """Static wall segments (S, 2, 2) m with their bounding boxes, for the per-step robot-wall contact test."""

    def __init__(self, segments: np.ndarray) -> None:
        self.segments = np.asarray(segments, float).reshape(-1, 2, 2)
        lo, hi = self.segments.min(axis=1), self.segments.max(axis=1)
        self._centre, self._half = 0.5 * (lo + hi), 0.5 * (hi - lo)

    def within(self, p: np.ndarray, r: float) -> bool:
        """Whether point p (2,) is closer than r m to a wall: ``point_segment_distances(p, segments).min() < r``,
        computed exactly for the walls whose bounding box grown by r (+1 um) holds p (no other can be that close)."""
        if len(self.segments) == 0:
            return False
        near = np.flatnonzero(np.all(np.abs(p - self._centre) <= self._half + (r + 1e-6), axis=1))
        return bool(len(near)) and float(point_segment_distances(p, self.segments[near]).min()) < r


def _cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _hull_list(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """`convex_hull` on a list of (x, y) floats (the same operations, without numpy's per-call overhead)."""
    pts = sorted(set(points))  # lexicographic (x, then y), duplicates dropped, as np.unique(axis=0)
    if len(pts) <= 2:
        return pts

    def chain(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and _cross(out[-2], out[-1], p) <= 1e-12:
                out.pop()
            out.append(p)
        return out

    lower, upper = chain(pts), chain(pts[::-1])
    return lower[:-1] + upper[:-1]


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull (H, 2) of points (n, 2) (Andrew's monotone chain); collinear points
    collapse to the two ends, a single point to itself."""
    pts = np.asarray(points, float).reshape(-1, 2)
    return np.array(_hull_list([(x, y) for x, y in pts.tolist()]), float).reshape(-1, 2)


def _segment_distance(px: float, py: float, a: tuple[float, float], b: tuple[float, float]) -> float:
    """`point_segment_distances` of one segment a -> b on Python floats: a scalar twin for the per-step convex-hull
    test, where numpy's per-call overhead dominates (`envs.scoring.kernels` compiles the same operations); checked
    against the planner's vectorised one in tests/envs/test_env_fast_paths.py."""
    abx, aby = b[0] - a[0], b[1] - a[1]
    den = abx * abx + aby * aby
    t = ((px - a[0]) * abx + (py - a[1]) * aby) / (den if den > 1e-12 else 1e-12)
    t = 0.0 if not t > 0.0 else t if t < 1.0 else 1.0
    dx, dy = px - (a[0] + t * abx), py - (a[1] + t * aby)
    return math.sqrt(dx * dx + dy * dy)


def _hull_distance(px: float, py: float, hull: list[tuple[float, float]]) -> float:
    """`distance_to_hull` for a hull of 2 or more vertices given as floats."""
    if len(hull) == 2:
        return _segment_distance(px, py, hull[0], hull[1])
    edges = list(zip(hull, hull[1:] + hull[:1], strict=True))
    if all((b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]) >= 0.0 for a, b in edges):
        return 0.0
    return min(_segment_distance(px, py, a, b) for a, b in edges)


def distance_to_hull(p: np.ndarray, hull: np.ndarray) -> float:
    """Distance m from p (2,) to the convex polygon hull (H, 2) (counter-clockwise); 0 inside."""
    if len(hull) == 1:
        return float(np.linalg.norm(p - hull[0]))
    return _hull_distance(float(p[0]), float(p[1]), [(x, y) for x, y in np.asarray(hull, float).tolist()])


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
    near = group_id[dist <= max_span_m + reach_m + 0.5]
    if len(near) == 0:
        return []
    px, py = float(robot[0]), float(robot[1])
    out = []
    for g in set(near.tolist()):
        sel = np.flatnonzero(group_id == g)
        if len(sel) < 2:
            continue
        members = [(x, y) for x, y in pos[sel].tolist()]
        span2 = max((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) for a in members for b in members)
        if span2 > max_span_m**2:
            continue
        hull = _hull_list(members)
        d = float(np.linalg.norm(robot - np.array(hull[0]))) if len(hull) == 1 else _hull_distance(px, py, hull)
        if d < reach_m + float(radius[sel].max()):
            out.append(int(g))
    return sorted(out)
