"""Compiled fast path: every social acceleration of one force step in a single numba call.

It evaluates exactly the formulas of the numpy reference in `crowdsim.forces` (tests assert equality to
1e-10); one call replaces ~60 small numpy calls whose overhead dominates at crowd sizes below a few
hundred. Compilation is cached on disk.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from crowdsim import detour, forces, groups
from crowdsim.config import GroupForceParams, SocialForceParams
from crowdsim.fma import fma


def pack_params(social: SocialForceParams, group: GroupForceParams) -> np.ndarray:
    """(16,) float64 parameter vector in the order the kernel reads it."""
    return np.array([
        social.ped_strength_mps2, social.ped_range_m, social.anisotropy, social.relaxation_time_s,
        social.wall_strength_mps2, social.wall_range_m, social.cutoff_m, group.gaze_strength,
        group.coherence_strength_mps2, group.repulsion_strength_mps2, group.repulsion_distance_m,
        math.radians(group.vision_half_angle_deg), group.catch_up_strength, group.gaze_fade_m,
        group.whole_group_gaze_share, group.member_ped_repulsion_scale,
    ])


@numba.njit(cache=True)
def _walls(acc, pos, radius, n, walls, aw, bw, cutoff):
    for k in range(n):
        for s in range(walls.shape[0]):
            ax, ay = walls[s, 0, 0], walls[s, 0, 1]
            abx, aby = walls[s, 1, 0] - ax, walls[s, 1, 1] - ay
            len2 = max(abx * abx + aby * aby, 1e-9)
            t = min(max(((pos[k, 0] - ax) * abx + (pos[k, 1] - ay) * aby) / len2, 0.0), 1.0)
            dx, dy = pos[k, 0] - (ax + t * abx), pos[k, 1] - (ay + t * aby)
            d = math.sqrt(dx * dx + dy * dy)
            if d < cutoff and d > 1e-9:
                mag = aw * math.exp((radius[k] - d) / bw) / d
                acc[k, 0] += mag * dx
                acc[k, 1] += mag * dy


@numba.njit(cache=True)
def _look(acc, k, sum_x, sum_y, count, pos, vel, e, speed, weight, p):
    """Add weight x the gaze brake and catch-up push of member k towards the centre of the count - 1 others
    whose positions, with its own, sum to (sum_x, sum_y) (`forces._gaze_and_catch_up`)."""
    ox = (sum_x - pos[k, 0]) / (count - 1.0) - pos[k, 0]
    oy = (sum_y - pos[k, 1]) / (count - 1.0) - pos[k, 1]
    on = math.sqrt(ox * ox + oy * oy)
    cos = (e[k, 0] * ox + e[k, 1] * oy) / on if on > 1e-9 else 0.0
    angle = math.acos(min(max(cos, -1.0), 1.0))
    fade = min(on / p[13], 1.0)
    brake = p[7] * max(angle - p[11], 0.0) * fade
    catch = p[12] * max(math.pi - p[11] - angle, 0.0) * fade * speed
    acc[k, 0] += weight * (catch * e[k, 0] - brake * vel[k, 0])
    acc[k, 1] += weight * (catch * e[k, 1] - brake * vel[k, 1])


@numba.njit(cache=True)
def _groups(acc, pos, vel, v_des, e, label, gaze_label, n, i, j, p):
    g = label.max() + 1
    sx, sy, cnt = np.zeros(g), np.zeros(g), np.zeros(g)
    gx, gy, gcnt = np.zeros(n), np.zeros(n), np.zeros(n)
    for k in range(n):
        sx[label[k]] += pos[k, 0]
        sy[label[k]] += pos[k, 1]
        cnt[label[k]] += 1.0
        gx[gaze_label[k]] += pos[k, 0]
        gy[gaze_label[k]] += pos[k, 1]
        gcnt[gaze_label[k]] += 1.0
    share = p[14]
    for k in range(n):
        size = cnt[label[k]]
        if size < 2:
            continue
        cx, cy = sx[label[k]] / size, sy[label[k]] / size
        gsize = gcnt[gaze_label[k]]
        speed = min(math.sqrt(v_des[k, 0] ** 2 + v_des[k, 1] ** 2), math.sqrt(vel[k, 0] ** 2 + vel[k, 1] ** 2))
        if gsize == size:  # one row: the whole group
            _look(acc, k, gx[gaze_label[k]], gy[gaze_label[k]], gsize, pos, vel, e, speed, 1.0, p)
        else:  # a row of a larger group: mostly its own row, the share `whole_group_gaze_share` the whole group
            if gsize > 1:
                _look(acc, k, gx[gaze_label[k]], gy[gaze_label[k]], gsize, pos, vel, e, speed, 1.0 - share, p)
            if share > 0.0:
                _look(acc, k, sx[label[k]], sy[label[k]], size, pos, vel, e, speed, share, p)
        tx, ty = cx - pos[k, 0], cy - pos[k, 1]
        dc = math.sqrt(tx * tx + ty * ty)
        if dc > 1e-9:
            q = min(max((dc - 0.5 * (size - 1.0)) / 0.25, 0.0), 1.0)
            acc[k, 0] += p[8] * q * tx / dc
            acc[k, 1] += p[8] * q * ty / dc
    for m in range(i.shape[0]):
        a, b = i[m], j[m]
        if a >= n or b >= n or label[a] != label[b]:
            continue
        dx, dy = pos[a, 0] - pos[b, 0], pos[a, 1] - pos[b, 1]
        d = math.sqrt(dx * dx + dy * dy)
        if d < p[10] and d > 1e-9:
            acc[a, 0] += p[9] * dx / d
            acc[a, 1] += p[9] * dy / d
            acc[b, 0] -= p[9] * dx / d
            acc[b, 1] -= p[9] * dy / d


@numba.njit(cache=True)
def _pairs(acc, pos, radius, e, i, j, n, pair_label, p):
    for m in range(i.shape[0]):
        a, b = i[m], j[m]
        if a >= n and b >= n:
            continue
        dx, dy = pos[a, 0] - pos[b, 0], pos[a, 1] - pos[b, 1]
        d = math.sqrt(dx * dx + dy * dy)
        if d < 1e-9:
            continue
        nx, ny = dx / d, dy / d
        mag = p[0] * math.exp((radius[a] + radius[b] - d) / p[1])
        if pair_label[a] >= 0 and pair_label[a] == pair_label[b]:  # members of one group
            mag *= p[15]
        if a < n:
            w = p[2] + (1.0 - p[2]) * 0.5 * (1.0 - (nx * e[a, 0] + ny * e[a, 1]))
            acc[a, 0] += mag * w * nx
            acc[a, 1] += mag * w * ny
        if b < n:
            w = p[2] + (1.0 - p[2]) * 0.5 * (1.0 + (nx * e[b, 0] + ny * e[b, 1]))
            acc[b, 0] -= mag * w * nx
            acc[b, 1] -= mag * w * ny


@numba.njit(cache=True)
def _all(pos, radius, e, i, j, n, vel, v_des, walls, label, gaze_label, pair_label, p):
    acc = np.zeros((n, 2))
    _pairs(acc, pos, radius, e, i, j, n, pair_label, p)
    for k in range(n):
        acc[k, 0] += (v_des[k, 0] - vel[k, 0]) / p[3]
        acc[k, 1] += (v_des[k, 1] - vel[k, 1]) / p[3]
    _walls(acc, pos, radius, n, walls, p[4], p[5], p[6])
    if n > 0:
        _groups(acc, pos, vel, v_des, e, label, gaze_label, n, i, j, p)
    return acc


def social_acc(pos: np.ndarray, radius: np.ndarray, e: np.ndarray, i: np.ndarray, j: np.ndarray, n: int,
               vel: np.ndarray, v_des: np.ndarray, walls: np.ndarray, label: np.ndarray,
               gaze_label: np.ndarray, params: np.ndarray, pair_label: np.ndarray | None = None) -> np.ndarray:
    """(n, 2) m/s^2: driving + pedestrian + wall + group accelerations of the first n agents.

    pos/radius/e (M, 2)/(M,)/(M, 2) include M - n extra agents (robot, periodic ghosts) that push the
    real ones but are not pushed; pairs (i, j) index those rows; vel, v_des (n, 2); walls (S, 2, 2);
    label (n,) dense group labels; gaze_label (n,) dense labels of the sub-groups whose members each one looks
    at (`groups.gaze_subgroups`); params from `pack_params`. pair_label (M,): the group label of every row for
    the pedestrian repulsion (`forces.pedestrian_acc`; negative: in no group), default label then -1 for the
    extra rows; members of one group repel each other `GroupForceParams.member_ped_repulsion_scale` as much.
    """
    if pair_label is None:
        pair_label = np.concatenate([label, np.full(len(pos) - n, -1, label.dtype)])
    return _all(np.ascontiguousarray(pos), radius, np.ascontiguousarray(e), i, j, n,
                np.ascontiguousarray(vel), np.ascontiguousarray(v_des), np.ascontiguousarray(walls, dtype=float),
                label, gaze_label, np.ascontiguousarray(pair_label, dtype=np.int64), params)


@numba.njit(cache=True)
def _desired_and_heading(pos, vel, goal, speed, slowdown_m, min_speed):
    n = pos.shape[0]
    v_des = np.zeros((n, 2))
    e = np.zeros((n, 2))
    for k in range(n):
        gx, gy = goal[k, 0] - pos[k, 0], goal[k, 1] - pos[k, 1]
        dist = math.sqrt(gx * gx + gy * gy)
        if dist > 1e-9:
            s = speed[k] * min(max(dist / slowdown_m, 0.0), 1.0) / dist
            v_des[k, 0], v_des[k, 1] = gx * s, gy * s
        sp = math.sqrt(vel[k, 0] ** 2 + vel[k, 1] ** 2)
        if sp > min_speed:
            e[k, 0], e[k, 1] = vel[k, 0] / sp, vel[k, 1] / sp
        else:
            dn = math.sqrt(v_des[k, 0] ** 2 + v_des[k, 1] ** 2)
            if dn > 1e-9:
                e[k, 0], e[k, 1] = v_des[k, 0] / dn, v_des[k, 1] / dn
    return v_des, e


def desired_and_heading(pos: np.ndarray, vel: np.ndarray, goal: np.ndarray, speed: np.ndarray,
                        slowdown_m: float, min_speed_mps: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Compiled `forces.desired_velocity` and `forces.headings` in one call: (v_des, e), each (n, 2)."""
    return _desired_and_heading(np.ascontiguousarray(pos), np.ascontiguousarray(vel), np.ascontiguousarray(goal),
                                np.ascontiguousarray(speed), float(slowdown_m), float(min_speed_mps))


@numba.njit(cache=True)
def _gaze_subgroups(pos, goal, label, max_abreast):
    n = label.shape[0]
    sub = label * 2
    if n == 0:
        return sub, True
    n_groups = label.max() + 1
    counts = np.zeros(n_groups, np.int64)
    for k in range(n):
        counts[label[k]] += 1
    for g in range(n_groups):
        size = counts[g]
        if size <= max_abreast:
            continue
        if size > 15:  # numpy's mean switches to pairwise summation: left to the numpy path
            return sub, False
        members = np.empty(size, np.int64)
        m = 0
        for k in range(n):  # members in increasing index order, as np.flatnonzero(label == g)
            if label[k] == g:
                members[m] = k
                m += 1
        gx = gy = px = py = 0.0
        for k in members:  # rows added in order, then divided: what .mean(axis=0) does for up to 15 rows
            gx += goal[k, 0]
            gy += goal[k, 1]
            px += pos[k, 0]
            py += pos[k, 1]
        hx, hy = gx / size - px / size, gy / size - py / size
        neg_proj = np.empty(size)
        for m in range(size):  # -(pos[members] @ heading) as numpy rounds it (signed zeros do not change the order)
            neg_proj[m] = -fma(pos[members[m], 0], hx, pos[members[m], 1] * hy)
        order = np.argsort(neg_proj, kind="mergesort")
        for m in range((size + 1) // 2, size):
            sub[members[order[m]]] += 1
    present = np.zeros(sub.max() + 1, np.int64)
    for k in range(n):
        present[sub[k]] = 1
    rank = np.cumsum(present) - 1
    out = np.empty(n, np.int64)
    for k in range(n):
        out[k] = rank[sub[k]]
    return out, True


def gaze_subgroups(pos: np.ndarray, goal: np.ndarray, label: np.ndarray, max_abreast: int = 3) -> np.ndarray:
    """`groups.gaze_subgroups` (the same labels bit for bit), compiled; a group of more than 15 that splits goes
    to the numpy function (numpy's mean sums that many rows pairwise)."""
    out, ok = _gaze_subgroups(np.ascontiguousarray(pos, dtype=float), np.ascontiguousarray(goal, dtype=float),
                              np.ascontiguousarray(label, dtype=np.int64), int(max_abreast))
    return out if ok else groups.gaze_subgroups(pos, goal, label, max_abreast)


@numba.njit(cache=True)
def _cap_speed(vel, idx, speed, factor, eps):
    for k in idx:
        vx, vy = vel[k, 0], vel[k, 1]
        norm = math.sqrt(vx * vx + vy * vy)
        limit = speed[k] * factor
        if norm > limit:
            scale = limit / max(norm, eps)
            vel[k, 0], vel[k, 1] = vx * scale, vy * scale


def cap_speed_rows(vel: np.ndarray, idx: np.ndarray, speed: np.ndarray, factor: float) -> None:
    """In place, ``vel[idx] = forces.cap_speed(vel[idx], speed[idx] * factor)`` (the same values): rows of vel
    (C, 2) m/s faster than speed (C,) m/s x factor are scaled back onto that limit."""
    _cap_speed(vel, idx, speed, float(factor), forces._EPS)


@numba.njit(cache=True)
def _any_within(pos, goal, idx, radius):
    for k in idx:
        dx, dy = pos[k, 0] - goal[k, 0], pos[k, 1] - goal[k, 1]
        if math.sqrt(dx * dx + dy * dy) < radius:
            return True
    return False


def any_within(pos: np.ndarray, goal: np.ndarray, idx: np.ndarray, radius_m: float) -> bool:
    """Whether some row k of idx has |pos[k] - goal[k]| < radius_m (pos, goal (C, 2) m)."""
    return bool(_any_within(pos, goal, idx, float(radius_m)))


@numba.njit(cache=True)
def _sight_blocked(px, py, qx, qy, walls, ends, margin):
    for s in range(walls.shape[0]):  # forces.crossed_walls: a proper intersection with a wall
        ax, ay, bx, by = walls[s, 0, 0], walls[s, 0, 1], walls[s, 1, 0], walls[s, 1, 1]
        d1 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        d2 = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
        d3 = (qx - px) * (ay - py) - (qy - py) * (ax - px)
        d4 = (qx - px) * (by - py) - (qy - py) * (bx - px)
        if d1 * d2 < 0 and d3 * d4 < 0:
            return True
    if margin <= 0:
        return False
    dx, dy = qx - px, qy - py
    len2 = max(dx * dx + dy * dy, 1e-12)
    for e in range(ends.shape[0]):  # a wall end ahead closer than the margin
        rx, ry = ends[e, 0] - px, ends[e, 1] - py
        t = (rx * dx + ry * dy) / len2
        if 0 < t < 1 and math.hypot(rx - t * dx, ry - t * dy) < margin:
            return True
    return False


@numba.njit(cache=True)
def _aims(pos, goal, walls, ends, waypoints, margin, reach, out):
    for i in range(pos.shape[0]):
        px, py = pos[i, 0], pos[i, 1]
        if not _sight_blocked(px, py, goal[i, 0], goal[i, 1], walls, ends, margin):
            continue
        best, best_cost = -1, math.inf
        for w in range(waypoints.shape[0]):
            wx, wy = waypoints[w, 0], waypoints[w, 1]
            if _sight_blocked(px, py, wx, wy, walls, ends, margin):
                continue
            if _sight_blocked(wx, wy, goal[i, 0], goal[i, 1], walls, ends, margin):
                continue
            cost = math.hypot(wx - px, wy - py) + math.hypot(wx - goal[i, 0], wy - goal[i, 1])
            if cost < best_cost:
                best, best_cost = w, cost
        if best >= 0:
            sx, sy = waypoints[best, 0] - px, waypoints[best, 1] - py
            f = max(1.0, reach / max(math.hypot(sx, sy), 1e-9))
            out[i, 0], out[i, 1] = px + sx * f, py + sy * f
    return out


def aims(pos: np.ndarray, goal: np.ndarray, corners: detour.Corners, reach_m: float) -> np.ndarray:
    """`detour.aims` compiled: the same aims (n, 2) m (to rounding; tests compare them), one numba call."""
    if len(corners.waypoints) == 0:
        return goal
    return _aims(pos, goal, corners.walls, corners.ends, corners.waypoints, corners.margin_m, reach_m, goal.copy())
