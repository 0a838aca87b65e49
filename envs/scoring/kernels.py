"""The env's per-step work compiled with numba: the step's robot-pedestrian distances (`step_distances`), the
group-intrusion test (`intruded_groups`), the observation's arrays (`observation_arrays`) and the smallest time to
collision of the social-navigation metrics (`min_time_to_collision`, the same floats as
`envs.scoring.social_metrics.time_to_collision`).

Each computes the same floats as the numpy code it replaced (`envs.scoring.geometry`, `envs.observation`; numpy's small
matrix products are reproduced with `crowdsim.fma`), in one call instead of a dozen small array operations, so
episodes do not change; `tests/envs/test_kernels.py` compares them bit for bit.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from crowdsim.fma import fma
from envs.scoring import geometry


@numba.njit(cache=True)
def _step_distances(here, start, pos, radius, active, ped_id, pos0, active0, ped_id0, robot_radius):
    n = 0
    for s in range(active.shape[0]):
        n += active[s]
    centre = np.empty(n)
    surface = np.empty(n)
    m = 0
    for s in range(active.shape[0]):
        if not active[s]:
            continue
        c = math.hypot(pos[s, 0] - here[0], pos[s, 1] - here[1])
        centre[m] = c
        surface[m] = c - radius[s] - robot_radius
        if active0[s] and ped_id0[s] == ped_id[s]:  # present at both ends: the closest approach along the step
            d0x, d0y = pos0[s, 0] - start[0], pos0[s, 1] - start[1]
            dvx = (pos[s, 0] - pos0[s, 0]) - (here[0] - start[0])
            dvy = (pos[s, 1] - pos0[s, 1]) - (here[1] - start[1])
            denom = dvx * dvx + dvy * dvy
            t = -(d0x * dvx + d0y * dvy) / max(denom, 1e-12) if denom > 1e-12 else 0.0
            t = min(max(t, 0.0), 1.0)
            dx, dy = d0x + t * dvx, d0y + t * dvy
            swept = math.sqrt(dx * dx + dy * dy) - radius[s] - robot_radius
            surface[m] = min(surface[m], swept)
        m += 1
    return centre, surface


def step_distances(here: np.ndarray, start: np.ndarray, pos: np.ndarray, radius: np.ndarray, active: np.ndarray,
                   ped_id: np.ndarray, pos0: np.ndarray, active0: np.ndarray, ped_id0: np.ndarray,
                   robot_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Robot-pedestrian distances over one step, for the active slots in slot order: centre distances now (n,) m
    (``np.hypot``) and surface distances (n,) m, the smaller of now's (centre - radius - robot_radius) and, for a
    slot that holds the same pedestrian at the step's start, the closest approach of the two linear motions
    (`geometry.swept_distances` - radius - robot_radius).

    here, start (2,): the robot at the step's end and start; pos (S, 2), radius (S,), active (S,) bool,
    ped_id (S,) the slots at the end; pos0, active0, ped_id0 the same slots at the start."""
    return _step_distances(np.ascontiguousarray(here, dtype=float), np.ascontiguousarray(start, dtype=float),
                           np.ascontiguousarray(pos, dtype=float), np.ascontiguousarray(radius, dtype=float),
                           active, ped_id, np.ascontiguousarray(pos0, dtype=float), active0, ped_id0,
                           float(robot_radius))


@numba.njit(cache=True)
def _clip32(v, lo, hi):
    """np.clip(v, lo, hi) (as np.minimum(np.maximum(v, lo), hi)) cast to float32."""
    v = v if v >= lo else lo
    return np.float32(v if v <= hi else hi)


@numba.njit(cache=True)
def _rotate_rows(rows, xy, origin, rot, out, col, lo, hi):
    """out[m, col:col + 2] = clip((xy[rows[m]] - origin) @ rot.T) as float32, with the roundings of numpy's
    (OpenBLAS) product, accumulated from +0.0: a matrix-matrix product (two or more rows) computes each entry as
    fma(y, r1, fma(x, r0, 0)), a single row (a matrix-vector product) as fma(x, r0, fma(y, r1, 0))."""
    n = rows.shape[0]
    for m in range(n):
        x, y = xy[rows[m], 0] - origin[0], xy[rows[m], 1] - origin[1]
        for i in range(2):
            if n >= 2:
                v = fma(y, rot[i, 1], fma(x, rot[i, 0], 0.0))
            else:
                v = fma(x, rot[i, 0], fma(y, rot[i, 1], 0.0))
            out[m, col + i] = _clip32(v, lo[m, col + i], hi[m, col + i])


@numba.njit(cache=True)
def _observation(state, goal, rot, unicycle, robot_radius, time_left, pos, vel, radius, group_id, p, sensor_range,
                 robot_lo, robot_hi, ped_lo, ped_hi):
    here = state[:2]
    gx, gy = goal[0] - here[0], goal[1] - here[1]
    robot = np.empty(7)
    robot[0] = fma(rot[0, 0], gx, fma(rot[0, 1], gy, 0.0))  # rot @ (goal - here), as numpy's matrix-vector product
    robot[1] = fma(rot[1, 0], gx, fma(rot[1, 1], gy, 0.0))
    robot[2] = math.sqrt(fma(gy, gy, gx * gx))  # np.linalg.norm, as numpy's dot
    robot[3], robot[4] = (state[3], state[4]) if unicycle else (state[2], state[3])
    robot[5], robot[6] = robot_radius, time_left
    robot32 = np.empty(7, np.float32)
    for i in range(7):
        robot32[i] = _clip32(robot[i], robot_lo[i], robot_hi[i])
    dist = np.empty(pos.shape[0])
    for k in range(pos.shape[0]):
        dx, dy = pos[k, 0] - here[0], pos[k, 1] - here[1]
        dist[k] = math.sqrt(dx * dx + dy * dy)
    rows = np.empty(min(p, pos.shape[0]), np.int64)  # within sensor range, nearest first (stable), at most p
    n = 0
    for k in np.argsort(dist, kind="mergesort"):
        if n == rows.shape[0] or not dist[k] <= sensor_range:
            break
        rows[n] = k
        n += 1
    rows = rows[:n]
    peds = np.zeros((p, 5), np.float32)
    _rotate_rows(rows, pos, here, rot, peds, 0, ped_lo, ped_hi)
    _rotate_rows(rows, vel, np.zeros(2), rot, peds, 2, ped_lo, ped_hi)
    mask = np.zeros(p, np.float32)
    groups = np.full(p, -1.0, np.float32)
    seen = np.empty(n, np.int64)  # group ids renumbered in order of first appearance
    n_seen = 0
    for m in range(n):
        peds[m, 4] = _clip32(radius[rows[m]], ped_lo[m, 4], ped_hi[m, 4])
        mask[m] = 1.0
        g = group_id[rows[m]]
        rank = 0
        while rank < n_seen and seen[rank] != g:
            rank += 1
        if rank == n_seen:
            seen[n_seen] = g
            n_seen += 1
        groups[m] = np.float32(min(rank, p - 1))
    return robot32, peds, mask, groups, rows


def observation_arrays(state: np.ndarray, goal: np.ndarray, rot: np.ndarray, unicycle: bool, robot_radius: float,
                       time_left: float, pos: np.ndarray, vel: np.ndarray, radius: np.ndarray, group_id: np.ndarray,
                       p: int, sensor_range: float, robot_box: tuple[np.ndarray, np.ndarray],
                       ped_box: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, ...]:
    """The observation's robot (7,), pedestrians (p, 5), pedestrian_mask (p,) and group_ids (p,) arrays, float32
    and clipped to their boxes (bounds (low, high)), and the rows (n,) of pos it shows: the same numbers as
    `envs.observation.build_observation`'s numpy code (tests compare them bit for bit). rot (2, 2): world to
    robot frame; pos, vel (N, 2), radius (N,), group_id (N,) int."""
    return _observation(np.ascontiguousarray(state, dtype=float), np.ascontiguousarray(goal, dtype=float),
                        np.ascontiguousarray(rot), bool(unicycle), float(robot_radius), float(time_left),
                        np.ascontiguousarray(pos, dtype=float), np.ascontiguousarray(vel, dtype=float),
                        np.ascontiguousarray(radius, dtype=float), np.ascontiguousarray(group_id, dtype=np.int64),
                        int(p), float(sensor_range), *robot_box, *ped_box)


@numba.njit(cache=True)
def _cross(ox, oy, ax, ay, bx, by):
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@numba.njit(cache=True)
def _segment_distance(px, py, ax, ay, bx, by):
    abx, aby = bx - ax, by - ay
    den = abx * abx + aby * aby
    t = ((px - ax) * abx + (py - ay) * aby) / (den if den > 1e-12 else 1e-12)
    t = 0.0 if not t > 0.0 else t if t < 1.0 else 1.0
    dx, dy = px - (ax + t * abx), py - (ay + t * aby)
    return math.sqrt(dx * dx + dy * dy)


@numba.njit(cache=True)
def _hull(xs, ys):
    """`geometry._hull_list` of the points (xs, ys): (hx, hy) counter-clockwise, duplicates dropped."""
    n = xs.shape[0]
    order = np.arange(n)
    for a in range(1, n):  # insertion sort by (x, y)
        k = order[a]
        b = a - 1
        while b >= 0 and (xs[order[b]] > xs[k] or (xs[order[b]] == xs[k] and ys[order[b]] > ys[k])):
            order[b + 1] = order[b]
            b -= 1
        order[b + 1] = k
    px, py = np.empty(n), np.empty(n)
    m = 0
    for k in order:
        if m == 0 or xs[k] != px[m - 1] or ys[k] != py[m - 1]:
            px[m], py[m] = xs[k], ys[k]
            m += 1
    if m <= 2:
        return px[:m], py[:m]
    hx, hy = np.empty(2 * m), np.empty(2 * m)
    h = 0
    for rev in range(2):  # lower chain, then upper chain; each without its last point
        start = h
        for q in range(m):
            k = m - 1 - q if rev else q
            while h - start >= 2 and _cross(hx[h - 2], hy[h - 2], hx[h - 1], hy[h - 1], px[k], py[k]) <= 1e-12:
                h -= 1
            hx[h], hy[h] = px[k], py[k]
            h += 1
        h -= 1
    return hx[:h], hy[:h]


@numba.njit(cache=True)
def _hull_distance(px, py, hx, hy):
    h = hx.shape[0]
    if h == 2:
        return _segment_distance(px, py, hx[0], hy[0], hx[1], hy[1])
    inside = True
    for e in range(h):
        f = (e + 1) % h
        if not (hx[f] - hx[e]) * (py - hy[e]) - (hy[f] - hy[e]) * (px - hx[e]) >= 0.0:
            inside = False
    if inside:
        return 0.0
    best = np.inf
    for e in range(h):
        f = (e + 1) % h
        best = min(best, _segment_distance(px, py, hx[e], hy[e], hx[f], hy[f]))
    return best


@numba.njit(cache=True)
def _intruded(px, py, reach, pos, radius, group_id, max_span2, near_m, dist):
    cand = np.unique(group_id[dist <= near_m])
    out = np.empty(cand.shape[0], np.int64)
    n_out = 0
    for g in cand:
        sel = np.flatnonzero(group_id == g)
        if sel.shape[0] < 2:
            continue
        xs, ys = pos[sel, 0], pos[sel, 1]
        span2 = 0.0
        for a in range(sel.shape[0]):
            for b in range(sel.shape[0]):
                span2 = max(span2, (xs[a] - xs[b]) * (xs[a] - xs[b]) + (ys[a] - ys[b]) * (ys[a] - ys[b]))
        if span2 > max_span2:
            continue
        hx, hy = _hull(xs, ys)
        if hx.shape[0] == 1:  # all members at one point: left to the numpy code
            return out[:0], False
        if _hull_distance(px, py, hx, hy) < reach + radius[sel].max():
            out[n_out] = g
            n_out += 1
    return out[:n_out], True


def intruded_groups(robot: np.ndarray, reach_m: float, pos: np.ndarray, radius: np.ndarray, group_id: np.ndarray,
                    max_span_m: float, dist: np.ndarray) -> list[int]:
    """`geometry.intruded_groups` (the same groups, from the same float operations), compiled, given the centre
    distances dist (n,) m; a group whose members all stand at one point goes to the numpy function."""
    if len(pos) == 0:
        return []
    out, ok = _intruded(float(robot[0]), float(robot[1]), float(reach_m), np.ascontiguousarray(pos, dtype=float),
                        np.ascontiguousarray(radius, dtype=float), np.ascontiguousarray(group_id, dtype=np.int64),
                        float(max_span_m) ** 2, float(max_span_m + reach_m + 0.5), np.ascontiguousarray(dist))
    return out.tolist() if ok else geometry.intruded_groups(robot, reach_m, pos, radius, group_id, max_span_m, dist)


@numba.njit(cache=True)
def _min_ttc(sx, sy, rvx, rvy, pos, vel, radius, active, robot_radius):
    best = math.inf
    for s in range(active.shape[0]):
        if not active[s]:
            continue
        px, py = pos[s, 0] - sx, pos[s, 1] - sy
        vx, vy = vel[s, 0] - rvx, vel[s, 1] - rvy
        r = radius[s] + robot_radius
        c = px * px + py * py - r * r
        if c <= 0:
            return 0.0
        a = vx * vx + vy * vy
        b = 2.0 * (px * vx + py * vy)
        disc = b * b - 4.0 * a * c
        if a > 0 and b < 0 and disc >= 0:
            t = (-b - math.sqrt(max(disc, 0.0))) / (2.0 * a)
            best = min(best, t)
    return best


def min_time_to_collision(start: np.ndarray, robot_vel: np.ndarray, pos: np.ndarray, vel: np.ndarray,
                          radius: np.ndarray, active: np.ndarray, robot_radius: float) -> float:
    """The smallest constant-velocity time to collision (s; 0 in contact, inf on no course) between the robot's disc
    at `start` (2,) m moving at `robot_vel` (2,) m/s and the active rows of pos (S, 2) m, vel (S, 2) m/s, radius (S,)
    m, active (S,) bool: `min(envs.scoring.social_metrics.time_to_collision(...))` over those rows, in one pass."""
    return float(_min_ttc(float(start[0]), float(start[1]), float(robot_vel[0]), float(robot_vel[1]), pos, vel,
                          radius, active, float(robot_radius)))
