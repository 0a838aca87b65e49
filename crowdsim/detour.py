"""Detours round wall corners: where a pedestrian aims when a wall stands between it and its goal.

The social-force driving term pulls straight at the goal. A pedestrian pushed round a corner (into the other
street of a crossing, out through the wrong gate of a plaza) then presses against the wall that hides its goal
and stays there for good: in 10 minutes of the default 24-person crossing one or two people in most runs, who
hold slots for the rest of the run and lower the share of people in groups (they are singles, pushed aside by
groups). Real people walk round the corner. Here such a pedestrian aims instead at a waypoint `clearance_m` off
the end of a wall, outside the corner (the route round at most one corner, the shortest that sees both the
pedestrian and the goal); people whose goal is in sight aim at it as before, bit for bit. In sight: the straight
line crosses no wall and passes no wall end ahead closer than half the clearance (a body's radius, 0.2-0.3 m,
and a little: a line that grazes a corner presses its walker into it, and two people pressing into one corner
from the two streets of a crossing held each other there for minutes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdsim.forces import crossed_walls


def corner_waypoints(walls: np.ndarray, clearance_m: float) -> np.ndarray:
    """(K, 2) m: one point clearance_m off each distinct end of the wall segments walls (S, 2, 2) m, along the
    negated sum of the unit vectors of the walls that leave that end (outside a corner; along the wall's
    extension at a free end). Ends where walls meet in a straight line (the sum is ~0) get none; clearance_m = 0
    (detours off) or no walls: none at all."""
    if clearance_m <= 0 or len(walls) == 0:
        return np.zeros((0, 2))
    ends = walls.reshape(-1, 2)
    # from each end into its wall, in the order of `ends` (each segment's first end, then its second)
    along = np.stack([walls[:, 1] - walls[:, 0], walls[:, 0] - walls[:, 1]], axis=1).reshape(-1, 2)
    along /= np.maximum(np.linalg.norm(along, axis=1, keepdims=True), 1e-12)
    out = []
    keys = np.round(ends, 6)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    for k, start in enumerate(first):
        total = along[inverse == k].sum(axis=0)
        norm = float(np.hypot(*total))
        if norm > 1e-6:
            out.append(ends[start] - clearance_m * total / norm)
    return np.array(out, dtype=float).reshape(-1, 2)


def wall_ends(walls: np.ndarray) -> np.ndarray:
    """(E, 2) m: the distinct ends of the wall segments walls (S, 2, 2) m."""
    return np.unique(np.round(walls.reshape(-1, 2), 6), axis=0)


def sight_blocked(start: np.ndarray, end: np.ndarray, walls: np.ndarray, ends: np.ndarray,
                  margin_m: float) -> np.ndarray:
    """(n,) bool: whether the straight line start -> end (n, 2) m crosses a wall (S, 2, 2) or passes closer than
    margin_m to a wall end (E, 2) that lies ahead of start (its projection strictly between start and end)."""
    blocked = crossed_walls(start, end, walls)
    if margin_m <= 0 or len(ends) == 0 or len(start) == 0:
        return blocked
    d = end - start  # (n, 2)
    rel = ends[None] - start[:, None]  # (n, E, 2)
    t = np.einsum("nek,nk->ne", rel, d) / np.maximum(np.einsum("nk,nk->n", d, d), 1e-12)[:, None]
    perp = np.linalg.norm(rel - t[..., None] * d[:, None], axis=2)
    return blocked | ((t > 0) & (t < 1) & (perp < margin_m)).any(axis=1)


@dataclass(frozen=True)
class Corners:
    """A scene's walls (S, 2, 2) m, their distinct ends (E, 2) m, the waypoints (K, 2) m `clearance_m` outside
    them (`corner_waypoints`) and the sight margin, half the clearance (m). Built once per scene."""

    walls: np.ndarray
    ends: np.ndarray
    waypoints: np.ndarray
    margin_m: float

    @classmethod
    def of(cls, walls: np.ndarray, clearance_m: float) -> Corners:
        return cls(walls, wall_ends(walls) if len(walls) else np.zeros((0, 2)), corner_waypoints(walls, clearance_m),
                   0.5 * clearance_m)


def aims(pos: np.ndarray, goal: np.ndarray, corners: Corners, reach_m: float) -> np.ndarray:
    """(n, 2) m: where each pedestrian at pos (n, 2) heading for goal (n, 2) aims: the goal itself (the same
    array) when it is in sight (`sight_blocked` with the corners' margin) or there are no waypoints; otherwise
    towards the waypoint seen from both the pedestrian and the goal with the shortest route through it; with no
    such waypoint, the goal (a goal behind a wall with no corner to walk round, such as a formation place beyond a
    corridor's wall at its exit, is aimed at as before). A waypoint aim lies at least reach_m away, in
    the waypoint's direction (reach_m: the slowdown radius, so that nobody slows down for a corner)."""
    c = corners
    if len(c.waypoints) == 0:
        return goal
    blocked = np.flatnonzero(sight_blocked(pos, goal, c.walls, c.ends, c.margin_m))
    if len(blocked) == 0:
        return goal
    k, b = len(c.waypoints), len(blocked)
    p, g = np.repeat(pos[blocked], k, 0), np.repeat(goal[blocked], k, 0)  # (b k, 2): each blocked one x waypoint
    w = np.tile(c.waypoints, (b, 1))
    through = ~(sight_blocked(p, w, c.walls, c.ends, c.margin_m) | sight_blocked(w, g, c.walls, c.ends, c.margin_m))
    through = through.reshape(b, k)
    to_goal = np.linalg.norm(w - g, axis=1).reshape(b, k)
    cost = np.where(through, np.linalg.norm(w - p, axis=1).reshape(b, k) + to_goal, np.inf)
    found = np.isfinite(cost).any(axis=1)
    step = c.waypoints[np.argmin(cost, axis=1)] - pos[blocked]
    dist = np.maximum(np.hypot(step[:, 0], step[:, 1]), 1e-9)
    out = goal.copy()
    out[blocked[found]] = (pos[blocked] + step * np.maximum(1.0, reach_m / dist)[:, None])[found]
    return out
