"""A space-time search layer: where the robot can be at the end of the MPC's horizon without meeting the predicted
people on the way, and which of those places is nearest the goal.

The MPC optimises locally from its warm start and the goal's pull. Among oncoming walkers every local move can look
unsafe; the safety shield then runs (docs/results/planner.md, "Against the reference"). Yet a path usually exists
(the benchmark's reachable-set bounds, `envs/evaluation/reachability.py`, find one for the oracle's failures):
through a gap that opens later, or by waiting. `SpaceTimeSearch.subgoal` looks for it:

1. A local grid (``cell_m``) around the robot, as wide as the robot can go over the horizon.
2. Every ``step_s`` up to the horizon, the cells whose centre keeps robot radius + person radius + ``clearance_m``
   + ``spread_inflation`` x the samples' spread (capped at ``max_inflation_m``) from every person's sample mean
   (interpolated between the prediction's steps, from the people's positions now), and the MPC's wall clearance
   from every wall.
3. Reachable sets: from the robot's cell, grown by the robot's top speed times ``step_s`` (Euclidean, on cell
   centres), cut to the free cells, step by step.
4. If some reachable cell is within ``goal_reach_m`` of the goal, the goal is the subgoal. If the set lives to the
   horizon and holds the point a straight run at full speed would reach, the goal too: the layer acts only where
   the straight run is blocked. Otherwise the reachable cell nearest the goal at the last step the set was alive,
   traced back along one path through the sets to where that path is ``lead_s`` from now: the subgoal (the way
   into the gap, or a place to wait).
5. No free cell after the first step: the goal (the MPC and the shield handle it).

Units: metres, seconds. Pure numpy and scipy (imported on first use); stateless.
"""

from __future__ import annotations

import math

import numpy as np

from planner.config import SpaceTimeConfig
from planner.prediction import PedPrediction, current_positions
from planner.scene import point_segment_distances


class SpaceTimeSearch:
    """`subgoal` as in the module docstring; speed_mps the robot's top speed, horizon_s the MPC's horizon."""

    def __init__(self, config: SpaceTimeConfig, speed_mps: float, horizon_s: float, robot_radius_m: float,
                 wall_clearance_m: float) -> None:
        self.config = config
        self.speed_mps = speed_mps
        self.horizon_s = horizon_s
        self.robot_radius_m = robot_radius_m
        self.wall_clearance_m = wall_clearance_m

    def subgoal(self, position: np.ndarray, goal: np.ndarray, prediction: PedPrediction | None,
                walls: np.ndarray | None) -> np.ndarray:
        """The point (2,) m to head for from position (2,) towards goal (2,), or the goal itself."""
        from scipy.ndimage import distance_transform_edt  # lazily: `import planner` stays numpy and casadi only

        cfg = self.config
        position, goal = np.asarray(position, float), np.asarray(goal, float)
        if prediction is None or not np.any(prediction.mask):
            return goal
        n_steps = max(1, int(round(self.horizon_s / cfg.step_s)))
        half = self.speed_mps * n_steps * cfg.step_s + cfg.cell_m
        k = int(math.ceil(half / cfg.cell_m))
        axis = cfg.cell_m * np.arange(-k, k + 1)
        xy = position + np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1)  # (G, G, 2), centre = robot
        free_walls = self._free_of_walls(xy, walls)
        tracks, spread = _tracks(prediction, cfg.step_s, n_steps)  # (n_steps + 1, n, 2), (n_steps + 1, n)
        radii = np.asarray(prediction.radii, float)[np.asarray(prediction.mask, bool)]
        clear = radii + self.robot_radius_m + cfg.clearance_m \
            + np.minimum(cfg.max_inflation_m, cfg.spread_inflation * spread)  # (n_steps + 1, n)
        near = np.any(np.all(np.abs(tracks - position) <= half + clear[..., None], axis=-1), axis=0)
        tracks, clear = tracks[:, near], clear[:, near]  # only the people who ever enter the grid
        start = np.zeros(xy.shape[:2], bool)
        start[k, k] = True
        step_m = self.speed_mps * cfg.step_s
        goal_d = np.hypot(*(xy - goal).transpose(2, 0, 1))
        blocked = _blocked(xy, tracks, clear)
        sets = [start]  # sets[j]: the cells reachable at j step_s, while the set lives
        for j in range(1, n_steps + 1):
            grown = distance_transform_edt(~sets[-1], sampling=cfg.cell_m) <= step_m + 1e-9
            alive = grown & free_walls & ~blocked[j]
            if not alive.any():
                break
            if np.any(alive & (goal_d < cfg.goal_reach_m)):
                return goal
            sets.append(alive)
        last, reach = len(sets) - 1, sets[-1]
        if last == 0:
            return goal
        dist = float(np.hypot(*(goal - position)))
        ahead = position + (goal - position) * min(1.0, self.speed_mps * last * cfg.step_s / max(dist, 1e-9))
        gap = np.hypot(*(xy - ahead).transpose(2, 0, 1))
        if last == n_steps and np.any(reach & (gap <= step_m)):
            return goal  # the straight run is open to the horizon (within a step): leave the pull as it is
        cell = np.unravel_index(np.argmin(np.where(reach, goal_d, np.inf)), reach.shape)
        lead = min(last, max(1, int(round(cfg.lead_s / cfg.step_s))))
        path = trace_back(sets[lead:], cell, int(math.ceil(step_m / cfg.cell_m)) + 1)  # to the set `lead` ahead
        return xy[path[0]]

    def _free_of_walls(self, xy: np.ndarray, walls: np.ndarray | None) -> np.ndarray:
        if walls is None or len(walls) == 0:
            return np.ones(xy.shape[:2], bool)
        d = point_segment_distances(xy, np.asarray(walls, float).reshape(-1, 4)).min(axis=-1)
        return d >= self.robot_radius_m + self.wall_clearance_m


def trace_back(sets: list[np.ndarray], end: tuple[int, ...], pad: int) -> list[tuple[int, ...]]:
    """One path of grid cells back through reachable sets: `end` (a cell of sets[-1]), then for each set before it
    the nearest of its cells within `pad` cells (the set grew by less than that per step, so one is there).
    Returns the cells in forward order, sets[0]'s first."""
    cell = tuple(int(c) for c in end)
    path = [cell]
    for mask in sets[-2::-1]:
        lo = np.maximum(np.array(cell) - pad, 0)
        cand = np.argwhere(mask[lo[0]:cell[0] + pad + 1, lo[1]:cell[1] + pad + 1]) + lo
        cell = tuple(int(c) for c in cand[np.argmin(np.hypot(*(cand - np.array(cell)).T))])
        path.append(cell)
    return path[::-1]


def _tracks(prediction: PedPrediction, step_s: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The sample mean (n_steps + 1, N_real, 2) m of every real person at 0, step_s, ... and the samples' RMS distance
    from it (n_steps + 1, N_real) m (both linear between the prediction's steps, held after its last)."""
    mask = np.asarray(prediction.mask, bool)
    pos = np.asarray(prediction.positions, float)[:, :, mask]  # (K, T, n, 2)
    now = current_positions(prediction)[mask]
    mean = np.concatenate([now[None], pos.mean(axis=0)])  # (T + 1, n, 2)
    rms = np.concatenate([np.zeros((1, len(now))), np.sqrt(((pos - pos.mean(axis=0)) ** 2).sum(-1).mean(0))])
    t = pos.shape[1]
    times = prediction.step_s * np.arange(t + 1)
    want = np.minimum(step_s * np.arange(n_steps + 1), times[-1])
    i = np.clip(np.searchsorted(times, want, side="right") - 1, 0, t - 1)
    w = (want - times[i]) / prediction.step_s
    return mean[i] * (1 - w)[:, None, None] + mean[i + 1] * w[:, None, None], rms[i] * (1 - w)[:, None] \
        + rms[i + 1] * w[:, None]


def _blocked(xy: np.ndarray, tracks: np.ndarray, clear: np.ndarray) -> np.ndarray:
    """(T, G, G) bool: at each of the T rows of tracks (T, S, 2), the cells of grid xy (G, G, 2) whose centre is
    closer than clear[t, i] to person i."""
    return disc_cells(xy[0, 0], float(xy[1, 0, 0] - xy[0, 0, 0]), xy.shape[:2], tracks, clear)


def disc_cells(origin: np.ndarray, h: float, shape: tuple[int, int], centres: np.ndarray,
               clear: np.ndarray) -> np.ndarray:
    """(..., nx, ny) bool: the cells of the grid with centres origin + (i, j) h (m) whose centre is closer than
    clear[..., s] (m) to centres[..., s, :] (..., S, 2) m; one stencil for all discs, vectorised."""
    centres, clear = np.asarray(centres, float), np.asarray(clear, float)
    lead = centres.shape[:-2]
    out = np.zeros((*lead, *shape), bool)
    if centres.shape[-2] == 0 or float(clear.max()) <= 0:
        return out
    k = int(math.ceil(float(clear.max()) / h)) + 1
    r = np.arange(-k, k + 1)
    stencil = np.stack(np.meshgrid(r, r, indexing="ij"), axis=-1).reshape(-1, 2)  # (M, 2)
    idx = np.floor((centres - origin) / h).astype(int)[..., None, :] + stencil  # (..., S, M, 2)
    gap = origin + idx * h - centres[..., None, :]
    hit = (np.hypot(gap[..., 0], gap[..., 1]) < clear[..., None]) & np.all(idx >= 0, axis=-1) \
        & np.all(idx < np.array(shape), axis=-1)
    where = np.nonzero(hit)
    out[(*where[:-2], idx[hit][:, 0], idx[hit][:, 1])] = True
    return out
