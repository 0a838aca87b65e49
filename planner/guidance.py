"""The guidance layer: passing options found in space-time, each held by half-planes in its own solve.

One local solve from one warm start keeps whatever side of each person its warm start was on: among a file of
walkers every local move looks unsafe, and extra warm starts converge to the same plan (RESULTS, "the foresight
ladder": `n_starts=3` did not help). Following T-MPC++ (de Groot et al., T-RO 2024), the MPC instead solves
several problems, each told which side to pass each nearby person on, and keeps the cheapest:

1. **Paths** (:func:`goal_rollouts`): the robot's own kinematics driven towards the subgoal at
   ``heading_offsets_deg`` from its direction and at ``speed_fractions`` of top speed, plus a standing path (brake,
   turning towards the goal): (C, H+1, state_dim) states and (C, H, 2) controls.
2. **Score** (:func:`path_costs`): the MPC's own goal terms, plus ``risk_weight`` x each knot's shortfall below the
   MPC's clearance from every constrained person's modes (mean over modes); a path nearer a wall than the MPC's wall
   clearance is no option (+inf).
3. **Passing sides** (:func:`passing_sides`): for each constrained person, how the bearing from them to the path
   turns over the horizon (the winding angle against their medoid future): +1 left, -1 right, 0 not passed (under
   ``min_winding_deg``, or never within ``relevance_m`` of the path). Paths with the same sides are one option.
4. **Options**: paths in order of cost, each kept only if it passes someone on the other side from every path kept
   before it and from the free solve's plan, and never one that comes nearer a wall than the MPC's wall clearance;
   the first ``n_paths`` kept become guided solves.
5. **Half-planes** (:func:`half_planes`): for a guided solve, each person within ``relevance_m`` of its path gets,
   at every checked time and mode, the constraint ``n . (p - q) >= clearance`` with ``n`` the unit vector from the
   person's predicted position q to the path's point: the plan stays on the path's side of everyone near it (and
   clear of them). The others keep the usual disc constraint.

The planner then compares every solved plan under the free problem's objective (discs, not half-planes) and keeps
the cheapest; a plan that keeps the last applied plan's sides costs ``hold_discount`` less (hysteresis).

Units: metres, seconds, radians inside (degrees in the config). Pure numpy, stateless.
"""

from __future__ import annotations

import numpy as np

from planner.config import GuidanceConfig, MPCConfig
from planner.dynamics import clip_control, step_numpy
from planner.ocp import HUBER_M  # the OCP's goal cost: a path is scored as the NLP scores its plan
from planner.scene import SceneArrays, point_segment_distances

MIN_NORMAL_M = 1e-6


def goal_rollouts(state: np.ndarray, goal: np.ndarray, offsets_rad: np.ndarray, speeds_mps: np.ndarray,
                  cfg: MPCConfig) -> tuple[np.ndarray, np.ndarray]:
    """States (C, H+1, nz) and controls (C, H, 2) of a bounded proportional controller heading for the goal direction
    rotated by offsets_rad (C,) at speeds_mps (C,) (the acceleration bounds applied; speed 0: brake, turning)."""
    rc = cfg.robot
    speeds = np.asarray(speeds_mps, float)
    x = np.tile(state, (len(offsets_rad), 1))
    states, controls = [x], []
    for _ in range(cfg.horizon_steps):
        delta = goal - x[:, :2]
        heading = np.arctan2(delta[:, 1], delta[:, 0]) + offsets_rad
        if rc.model == "unicycle":
            err = (heading - x[:, 2] + np.pi) % (2 * np.pi) - np.pi
            want = np.stack([speeds * np.maximum(np.cos(err), 0.0), 2.0 * err], axis=-1)
        else:
            speed = np.minimum(speeds, np.linalg.norm(delta, axis=1) / cfg.dt_s)
            want = speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        u = clip_control(x, want, cfg.dt_s, rc)
        x = step_numpy(x, u, cfg.dt_s, rc.model)
        states.append(x)
        controls.append(u)
    return np.stack(states, axis=1), np.stack(controls, axis=1)


def guidance_rollouts(state: np.ndarray, goal: np.ndarray, cfg: MPCConfig) -> tuple[np.ndarray, np.ndarray]:
    """Every (heading offset, speed) pair of ``cfg.guidance`` and a standing path, as `goal_rollouts` returns them."""
    gc: GuidanceConfig = cfg.guidance
    offsets = np.deg2rad(np.asarray(gc.heading_offsets_deg, float))
    speeds = cfg.robot.max_speed_mps * np.asarray(gc.speed_fractions, float)
    off, spd = (a.ravel() for a in np.meshgrid(offsets, speeds))
    return goal_rollouts(state, goal, np.r_[off, 0.0], np.r_[spd, 0.0], cfg)


def checked_points(states: np.ndarray, sub: int) -> np.ndarray:
    """Robot positions (C, sub H, 2) at the OCP's checked times (j + 1) dt / sub from states (C, H+1, nz), straight
    lines between the knots."""
    xy = states[:, :, :2]
    if sub == 1:
        return xy[:, 1:]
    half = 0.5 * (xy[:, :-1] + xy[:, 1:])
    return np.stack([half, xy[:, 1:]], axis=2).reshape(len(xy), -1, 2)


def ped_gaps(points: np.ndarray, scene: SceneArrays) -> np.ndarray:
    """(C, nt, M, K) m: how far each checked point (C, nt, 2) is beyond each constrained person's clearance (negative:
    inside it); padding rows +inf."""
    diff = points[:, :, None, None, :] - scene.ped_pos[None]
    gap = np.sqrt((diff * diff).sum(-1)) - scene.ped_clear[None, :, :, None]
    return np.where(scene.ped_mask[None, None, :, None] > 0, gap, np.inf)


def path_costs(states: np.ndarray, goal: np.ndarray, scene: SceneArrays, cfg: MPCConfig,
               gaps: np.ndarray) -> np.ndarray:
    """(C,) cost of each path (C, H+1, nz): the OCP's goal terms plus ``risk_weight`` x its summed shortfall below the
    people's clearance (mean over modes, ``gaps`` from `ped_gaps`); +inf for a path that comes nearer a wall than the
    MPC's wall clearance (never an option)."""
    w = cfg.weights
    d = np.sqrt(((states[:, 1:, :2] - goal) ** 2).sum(-1) + HUBER_M**2) - HUBER_M  # (C, H)
    cost = w.goal * d.sum(-1) + w.goal_terminal * d[:, -1]
    short = np.maximum(-np.where(np.isfinite(gaps), gaps, 0.0), 0.0).mean(-1).sum((-1, -2))
    cost = cost + cfg.guidance.risk_weight * short
    return np.where((wall_distances(states, scene) >= cfg.wall_clearance_m).all(-1), cost, np.inf)


def wall_distances(states: np.ndarray, scene: SceneArrays) -> np.ndarray:
    """(C, H) m: each path's (C, H+1, nz) knots' distance to the nearest constrained wall (+inf without walls)."""
    real = scene.wall_mask > 0
    if not real.any():
        return np.full(states[:, 1:, 0].shape, np.inf)
    return point_segment_distances(states[:, 1:, :2], scene.walls[real]).min(-1)


def passing_sides(states: np.ndarray, now: np.ndarray, scene: SceneArrays, gaps: np.ndarray,
                  cfg: MPCConfig) -> np.ndarray:
    """(C, M) int: the side each path (C, H+1, nz) passes each constrained person on: +1 when the bearing from the
    person to the robot turns anticlockwise by at least ``min_winding_deg`` over the horizon (the person's medoid
    future, mode 0; now (M, 2) their positions at t = 0), -1 clockwise, 0 otherwise or when the path never comes
    within ``relevance_m`` of them (``gaps`` from `ped_gaps`, any mode)."""
    gc: GuidanceConfig = cfg.guidance
    sub = scene.ped_pos.shape[0] // cfg.horizon_steps
    ped = np.concatenate([now[None], scene.ped_pos[sub - 1::sub, :, 0]])  # (H+1, M, 2): the medoid at the knots
    rel = states[:, :, None, :2] - ped[None]  # (C, H+1, M, 2)
    ang = np.arctan2(rel[..., 1], rel[..., 0])
    step = (np.diff(ang, axis=1) + np.pi) % (2 * np.pi) - np.pi
    winding = step.sum(1)  # (C, M) rad
    near = gaps.min(axis=(1, 3)) < gc.relevance_m
    turned = np.abs(winding) >= np.deg2rad(gc.min_winding_deg)
    return np.where(near & turned & (scene.ped_mask > 0), np.sign(winding), 0.0).astype(int)


def contradicts(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two rows of passing sides (M,) pass some person on opposite sides (0 contradicts nothing)."""
    return bool(np.any(a * b < 0))


def pick_options(costs: np.ndarray, sides: np.ndarray, exclude: list[np.ndarray], n: int) -> list[int]:
    """Indices of at most n paths, cheapest first, each passing some person on the other side from every path picked
    before it and from every row in `exclude` (each (M,): the free solves' sides). sides: (C, M), costs: (C,); a path
    of infinite cost is never picked."""
    taken = list(exclude)
    picks: list[int] = []
    for c in np.argsort(costs, kind="stable"):
        if len(picks) == n or not np.isfinite(costs[c]):  # inf: not an option (a path into a wall)
            break
        if all(contradicts(sides[c], other) for other in taken):
            taken.append(sides[c])
            picks.append(int(c))
    return picks


def half_planes(states: np.ndarray, scene: SceneArrays, gaps: np.ndarray, cfg: MPCConfig,
                now_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For one path (H+1, nz) with its gaps (nt, M, K): unit normals (nt, M, K, 2) from each person's predicted
    position to the path's point (from the person to the robot now, now_xy (2,), where the two coincide), and the
    switch (M,): 1 where the person comes within ``relevance_m`` of the path (half-plane), 0 elsewhere (disc)."""
    sub = scene.ped_pos.shape[0] // cfg.horizon_steps
    points = checked_points(states[None], sub)[0]  # (nt, 2)
    vec = points[:, None, None, :] - scene.ped_pos
    norm = np.linalg.norm(vec, axis=-1, keepdims=True)
    fallback = now_xy - scene.ped_pos
    fallback = fallback / np.maximum(np.linalg.norm(fallback, axis=-1, keepdims=True), MIN_NORMAL_M)
    normal = np.where(norm > MIN_NORMAL_M, vec / np.maximum(norm, MIN_NORMAL_M), fallback)
    on = ((gaps.min(axis=(0, 2)) < cfg.guidance.relevance_m) & (scene.ped_mask > 0)).astype(float)
    return normal, on


def keeps_sides(sides: dict[int, int], previous: dict[int, int]) -> bool:
    """True when a plan's passing sides (input row -> +1 / -1, `side_map`) contradict none of `previous` (the last
    applied plan's; empty: nothing to keep)."""
    return all(previous.get(row, side) == side for row, side in sides.items())


def side_map(sides: np.ndarray, index: np.ndarray) -> dict[int, int]:
    """The nonzero sides (M,) keyed by input row (`SceneArrays.ped_index`)."""
    return {int(row): int(s) for row, s in zip(index, sides[: len(index)], strict=False) if s != 0}
