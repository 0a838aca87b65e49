"""Turn a :class:`PedPrediction` and obstacle segments into the fixed-size arrays the MPC takes.

Steps, all numpy:

1. **K representative samples** (:func:`select_modes`). Samples are chosen per group (a singleton
   is a group of one) so that the members of a group keep a jointly sampled future. Within a group,
   the distance between two samples is the mean Euclidean distance between their member positions
   over all steps. The first pick is the medoid (the sample with the smallest summed distance to
   all others, i.e. the most typical future); each further pick is the sample farthest from the
   picks so far (farthest-point sampling), so the K picks cover the spread of futures, tails
   included. Ties go to the lower index, so the choice is deterministic. With fewer samples than
   K, the samples are repeated in turn.
2. **Time resampling** (:func:`resample_in_time`): linear interpolation from the prediction step
   to the plan step, with the current positions at t = 0; positions after the last predicted step
   are held.
3. **Nearest M pedestrians and G groups** to the robot, padded to fixed sizes with masks.
4. **Group regions** (:func:`group_capsules`): per stage and mode, each group of >= 2 real members
   becomes a capsule: a segment along the members' principal axis spanning their projections,
   with radius = largest perpendicular offset + largest member radius. It contains every member's
   disc; the robot keeps (capsule radius + robot radius + margin) from the segment. A capsule longer
   than ``max_group_span_m`` (members predicted to drift apart) is dropped for that time and mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.config import MPCConfig
from planner.prediction import PedPrediction, current_positions
from planner.risk import clearance_inflation, resample_scalar, sample_spread

FAR_M = 1.0e3  # padding entries are placed this far from the robot


@dataclass(frozen=True)
class SceneArrays:
    """Fixed-size MPC inputs, metres. nt = sub * H checked times t = dt/sub, 2 dt/sub, .., H dt (sub = 2
    with ``check_midpoints``, else 1), M peds, K modes, G groups, W walls."""

    ped_pos: np.ndarray  # (nt, M, K, 2)
    ped_clear: np.ndarray  # (nt, M) robot radius + ped radius + margin (+ inflation, planner/risk.py)
    ped_mask: np.ndarray  # (M,) 1.0 real, 0.0 padding
    grp_a: np.ndarray  # (nt, G, K, 2) capsule segment start
    grp_b: np.ndarray  # (nt, G, K, 2) capsule segment end
    grp_clear: np.ndarray  # (nt, G, K) capsule radius + robot radius + margin
    grp_mask: np.ndarray  # (G,)
    walls: np.ndarray  # (W, 4) segments x1, y1, x2, y2
    wall_mask: np.ndarray  # (W,)
    wall_side: np.ndarray  # (W,) +1 / -1: the side of each wall's line the robot is on now (left of x1y1->x2y2: +1)
    ped_index: np.ndarray  # (m_real,) which input pedestrians fill the first rows
    start_penetration_m: float  # > 0 when the robot already overlaps a pedestrian or a wall now


def _ped_sample_distances(positions: np.ndarray) -> np.ndarray:
    """positions (S, T, N, 2) -> (S, S, N) per-pedestrian mean Euclidean distance between samples (symmetric, zero
    diagonal: each pair is computed once)."""
    s = positions.shape[0]
    first, second = np.triu_indices(s, 1)
    diff = positions[first] - positions[second]  # (P, T, N, 2)
    dx, dy = diff[..., 0], diff[..., 1]
    pair = np.sqrt(dx * dx + dy * dy).mean(axis=1)  # (P, N)
    out = np.zeros((s, s, positions.shape[2]))
    out[first, second] = pair
    out[second, first] = pair
    return out


def _fps(dist: np.ndarray, k: int) -> np.ndarray:
    """Farthest-point sampling on a (S, S) distance matrix, medoid first."""
    s = dist.shape[0]
    if s <= k:
        return np.arange(k) % s
    picks = [int(np.argmin(dist.sum(axis=1)))]
    min_dist = dist[picks[0]].copy()
    while len(picks) < k:
        nxt = int(np.argmax(min_dist))
        picks.append(nxt)
        min_dist = np.minimum(min_dist, dist[nxt])
    return np.array(picks)


def farthest_point_samples(traj: np.ndarray, k: int) -> np.ndarray:
    """Indices (k,) of representative samples of traj (S, T, n, 2): medoid first, then farthest-point."""
    return _fps(_ped_sample_distances(traj).mean(axis=2), k)


def select_modes(positions: np.ndarray, group_ids: np.ndarray, mask: np.ndarray, k: int) -> np.ndarray:
    """(K_in, T, N, 2) -> (k, T, N, 2): k representative samples chosen per group (see module doc).
    Rows with mask False are left at zero."""
    positions = np.asarray(positions, float)
    out = np.zeros((k, *positions.shape[1:]))
    real = np.flatnonzero(mask)
    if real.size == 0:
        return out
    per_ped = _ped_sample_distances(positions[:, :, real])  # (S, S, R)
    for gid in np.unique(group_ids[real]):
        cols = np.flatnonzero(group_ids[real] == gid)
        picks = _fps(per_ped[:, :, cols].mean(axis=2), k)
        members = real[cols]
        out[:, :, members] = positions[picks][:, :, members]
    return out


def resample_in_time(positions: np.ndarray, current: np.ndarray, step_s: float, dt_s: float,
                     n_stages: int) -> np.ndarray:
    """(K, T, N, 2) at +step_s.. and current (N, 2) at t=0 -> (K, n_stages, N, 2) at +dt_s, .., +H dt_s."""
    k = positions.shape[0]
    known = np.concatenate([np.broadcast_to(current, (k, 1, *current.shape)), positions], axis=1)
    t_known = step_s * np.arange(known.shape[1])
    t_query = np.minimum(dt_s * np.arange(1, n_stages + 1), t_known[-1])
    hi = np.clip(np.searchsorted(t_known, t_query, side="left"), 1, len(t_known) - 1)
    lo = hi - 1
    w = ((t_query - t_known[lo]) / (t_known[hi] - t_known[lo]))[None, :, None, None]
    return (1.0 - w) * known[:, lo] + w * known[:, hi]


def _principal_axis(pts: np.ndarray) -> np.ndarray:
    """pts (..., n, 2) -> unit principal directions (..., 2); the x axis when degenerate."""
    centred = pts - pts.mean(axis=-2, keepdims=True)
    sxx = (centred[..., 0] ** 2).sum(-1)
    syy = (centred[..., 1] ** 2).sum(-1)
    sxy = (centred[..., 0] * centred[..., 1]).sum(-1)
    angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)


def group_capsules(pts: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Capsules containing member discs: pts (..., n, 2), radii (n,) -> a, b (..., 2), radius (...)."""
    centre = pts.mean(axis=-2)
    axis = _principal_axis(pts)
    normal = np.stack([-axis[..., 1], axis[..., 0]], axis=-1)
    rel = pts - centre[..., None, :]
    along = (rel * axis[..., None, :]).sum(-1)
    across = np.abs((rel * normal[..., None, :]).sum(-1))
    a = centre + along.min(-1)[..., None] * axis
    b = centre + along.max(-1)[..., None] * axis
    return a, b, (across + radii).max(-1)


def segment_projection(p: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points p (..., 2) against segments seg (W, 4) x0, y0, x1, y1: (rel, t, ab) with rel = p - start (..., W, 2) m,
    t (..., W) the clipped position of the closest point along each segment (0 at its start, 1 at its end) and
    ab (W, 2) m the segments' vectors: the closest points are start + t ab. The project's one point-to-segment
    computation (the env's wall checks use it too); crowdsim keeps a twin (crowdsim.forces, it may not import the
    planner), checked against this one in tests/test_shared_facts.py. seg may carry leading axes (..., W, 4) that
    broadcast against p's (the shield's moving group capsules: one segment per sample and time)."""
    a, b = seg[..., :2], seg[..., 2:]
    ab = b - a
    rel = np.asarray(p, float)[..., None, :] - a
    t = np.clip((rel * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    return rel, t, ab


def point_segment_distances(p: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Points p (..., 2), segments seg (W, 4) x0, y0, x1, y1 -> distances (..., W) in m."""
    rel, t, ab = segment_projection(p, seg)
    return np.linalg.norm(rel - t[..., None] * ab, axis=-1)


def wall_clearance(points: np.ndarray, walls: np.ndarray | None) -> np.ndarray:
    """Distance (m) from each point (..., 2) to the nearest wall segment (W, 4); +inf without walls (the safety
    shield's and the global route's)."""
    points = np.asarray(points, float)
    if walls is None or len(walls) == 0:
        return np.full(points.shape[:-1], np.inf)
    return point_segment_distances(points, walls).min(-1)


def wall_sides(point: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """(W,) +1 where `point` (2,) m lies left of the wall's direction x1y1 -> x2y2 (or on its line), else -1."""
    walls = np.asarray(walls, float).reshape(-1, 4)
    ab, ap = walls[:, 2:] - walls[:, :2], np.asarray(point, float) - walls[:, :2]
    return np.where(ab[:, 0] * ap[:, 1] - ab[:, 1] * ap[:, 0] >= 0.0, 1.0, -1.0)


def _nearest_walls(obstacles: np.ndarray | None, robot_xy: np.ndarray, w: int) -> tuple[np.ndarray, ...]:
    walls = np.tile(np.r_[robot_xy + FAR_M, robot_xy + FAR_M + 1.0], (w, 1))
    wall_mask = np.zeros(w)
    if obstacles is not None and len(obstacles) and w:
        order = np.argsort(point_segment_distances(robot_xy, obstacles), kind="stable")[:w]
        walls[: order.size] = obstacles[order]
        wall_mask[: order.size] = 1.0
    return walls, wall_mask, wall_sides(robot_xy, walls)


def _nearest_groups(group_ids: np.ndarray, mask: np.ndarray, dist: np.ndarray, g: int) -> list[np.ndarray]:
    """Member index arrays of the g groups with >= 2 real members nearest to the robot."""
    real = np.flatnonzero(mask)
    ids, slot, counts = np.unique(group_ids[real], return_inverse=True, return_counts=True)
    nearest = np.full(ids.size, np.inf)
    np.minimum.at(nearest, slot, dist[real])
    order = [i for i in np.lexsort((ids, nearest)) if counts[i] >= 2][:g]  # by distance, then id
    return [real[slot == i] for i in order]


def _group_arrays(stage_pos: np.ndarray, radii: np.ndarray, groups: list[np.ndarray], robot_xy: np.ndarray,
                  cfg: MPCConfig):
    """Capsule arrays from stage positions (K, H, N, 2) of the chosen groups' members."""
    k, h, g = stage_pos.shape[0], stage_pos.shape[1], cfg.max_groups
    grp_a = np.broadcast_to(robot_xy + FAR_M, (h, g, k, 2)).copy()
    grp_b = grp_a + 1.0
    grp_clear = np.zeros((h, g, k))
    grp_mask = np.zeros(g)
    for slot, members in enumerate(groups):
        pts = np.transpose(stage_pos[:, :, members], (1, 0, 2, 3))  # (H, K, n, 2)
        a, b, rad = group_capsules(pts, radii[members])
        grp_a[:, slot], grp_b[:, slot] = a, b
        clear = rad + cfg.robot.radius_m + cfg.safety_margin_m
        too_wide = np.linalg.norm(b - a, axis=-1) > cfg.max_group_span_m
        grp_clear[:, slot] = np.where(too_wide, -FAR_M, clear)  # -FAR_M: constraint always satisfied
        grp_mask[slot] = 1.0
    return grp_a, grp_b, grp_clear, grp_mask


def _start_penetration(robot_xy, now, radii, real, obstacles, robot_radius: float) -> float:
    """How deep (m) the robot's body overlaps a real pedestrian or an obstacle now; <= 0 if it does not."""
    depth = -np.inf
    if real.size:
        depth = float(np.max(robot_radius + radii[real] - np.linalg.norm(now[real] - robot_xy, axis=1)))
    if obstacles is not None and len(obstacles):
        depth = max(depth, float(np.max(robot_radius - point_segment_distances(robot_xy, obstacles))))
    return depth


def build_scene(state: np.ndarray, pred: PedPrediction, obstacles: np.ndarray | None, cfg: MPCConfig) -> SceneArrays:
    """Fixed-size MPC arrays from the robot state (state_dim,) (or just its position (2,)), a validated
    prediction and obstacle segments (S, 4) or None; metres."""
    state = np.asarray(state, float)
    robot_xy = state[:2]
    h, m, k = cfg.horizon_steps, cfg.max_peds, cfg.n_modes
    sub = 2 if cfg.check_midpoints else 1
    mask = np.asarray(pred.mask, bool)
    radii = np.where(mask, np.asarray(pred.radii, float), 0.0)
    group_ids = np.asarray(pred.group_ids)
    now = np.where(mask[:, None], current_positions(pred), robot_xy + FAR_M)
    dist = np.linalg.norm(now - robot_xy, axis=1)
    real = np.flatnonzero(mask)
    raw = np.where(mask[None, None, :, None], np.asarray(pred.positions, float), 0.0)
    order = real[np.argsort(dist[real], kind="stable")][:m]
    groups = _nearest_groups(group_ids, mask, dist, cfg.max_groups)
    used = np.zeros_like(mask)
    used[order] = True
    for members in groups:
        used[members] = True
    modes = select_modes(raw, group_ids, used, k)
    stage_pos = resample_in_time(modes, now, pred.step_s, cfg.dt_s / sub, sub * h)  # (K, sub H, N, 2)
    ped_pos = np.broadcast_to(robot_xy + FAR_M, (sub * h, m, k, 2)).copy()
    ped_pos[:, : order.size] = np.transpose(stage_pos[:, :, order], (1, 2, 0, 3))
    ped_clear = np.full((sub * h, m), cfg.robot.radius_m + cfg.safety_margin_m)
    ped_clear[:, : order.size] += radii[order]
    if order.size and (cfg.clearance_growth_mps > 0 or cfg.spread_inflation > 0):
        spread = resample_scalar(sample_spread(raw[:, :, order]), pred.step_s, cfg.dt_s / sub, sub * h)
        ped_clear[:, : order.size] += clearance_inflation(spread, cfg, cfg.dt_s / sub)
    ped_mask = np.zeros(m)
    ped_mask[: order.size] = 1.0
    grp = _group_arrays(stage_pos, radii, groups, robot_xy, cfg)
    walls, wall_mask, wall_side = _nearest_walls(obstacles, robot_xy, cfg.max_walls)
    depth = _start_penetration(robot_xy, now, radii, real, obstacles, cfg.robot.radius_m)
    return SceneArrays(ped_pos, ped_clear, ped_mask, *grp, walls, wall_mask, wall_side, order, depth)


def validate_obstacles(obstacles) -> np.ndarray | None:
    """Obstacles as segments (S, 4) [x1, y1, x2, y2] in m. Accepts such an array, or a list of closed
    polygons, each (V_i, 2) in m. Raises ValueError on bad shapes or non-finite values."""
    if obstacles is None:
        return None
    if isinstance(obstacles, list | tuple) and all(np.ndim(poly) == 2 and np.shape(poly)[1:] == (2,)
                                                  and len(poly) >= 2 for poly in obstacles):
        obstacles = [polygon_to_segments(poly) for poly in obstacles] or [np.zeros((0, 4))]
        obstacles = np.concatenate(obstacles)
    obs = np.asarray(obstacles, float)
    if obs.ndim != 2 or obs.shape[1] != 4:
        raise ValueError(f"obstacles must be segments (S, 4) [x1, y1, x2, y2] or a list of polygons (V, 2), "
                         f"got shape {obs.shape}")
    if not np.all(np.isfinite(obs)):
        raise ValueError("obstacles has NaN or inf values")
    return obs


def polygon_to_segments(vertices: np.ndarray, closed: bool = True) -> np.ndarray:
    """Polygon or polyline vertices (V, 2) in m -> segments (V or V-1, 4) for ``obstacles``."""
    v = np.asarray(vertices, float)
    nxt = np.roll(v, -1, axis=0) if closed else v[1:]
    start = v if closed else v[:-1]
    return np.concatenate([start, nxt], axis=1)
