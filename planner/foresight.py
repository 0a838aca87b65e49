"""The foresight search: where the robot can be over a long view (seconds past the MPC's horizon) without meeting the
predicted people, and the earliest way to its target; the MPC heads for a point on that way.

In dense flows of people who do not avoid the robot the MPC's failures are made seconds before the contact: in half
of a failing episode's plans no local move is clear (docs/decisions/planner-guidance.md, "The shield's share of
control"). The benchmark's witness (`envs/evaluation/reachability.py`), which knows the whole future, wins such
episodes by stepping aside or waiting at the right time. `ForesightSearch.subgoal` does the same over `horizon_s`,
against the prediction:

1. Tracks: each person's sample mean at every half `step_s` up to `horizon_s` (linear between the prediction's
   steps; past its end, its last step's velocity held: constant velocity). Clearance: robot radius + person radius
   + `clearance_m` + `spread_inflation` x the samples' RMS spread about their mean (capped at `max_inflation_m`).
2. A grid of side `cell_m` over the box around robot and target (3 m beyond both), clipped to how far the searched
   robot (`speed_fraction` of the top speed: room to track its way) gets in `horizon_s`; cells nearer a wall than
   the MPC's wall clearance are never free.
3. Reachable sets: from the robot's cell, each step grown by the searched speed x `step_s` (a disc of cells) and
   cut to the cells free of everyone at that step and half a step before (people move up to 0.6 m in 0.4 s).
4. If the straight run to the target stays free (point by point at the sets' times) the target is the subgoal: the
   MPC as without the search. Else the first set holding a cell within `goal_reach_m` of the target, or the last
   set alive, gives the cell nearest the target; one path back through the sets to the start; its point `lead_s`
   ahead is the subgoal (the way round, or a place to wait). Where no set lives to the end (or to the target) with
   `clearance_m`, the search runs again at contact distance (`retry_without_margin`; else the target).
5. Nothing alive after the first step, or nobody predicted: the target (the MPC and the shield handle it).
6. A subgoal farther from the goal than the nearest the robot has come to it in this episode plus `retreat_m` is
   not taken: the robot holds where it is. In a corridor's oncoming flow the sets are pushed back by everyone walking
   at the robot, and the search would have it walk back with them for good (crowdnav-tune corridor-high-visible 1002:
   from 8.8 m to 16 m from the goal); a step back to let a crossing file pass stays within the bound.

Units: metres, seconds. numpy and scipy (imported on first use); its state is `last_path`, the searched path (P, 2) m
of the last call (None when the target was returned without one), for drawing, and `nearest_m`, the nearest approach
to the goal since `reset` (a new episode).
"""

from __future__ import annotations

import math

import numpy as np

from planner.config import ForesightConfig
from planner.prediction import PedPrediction, current_positions
from planner.scene import point_segment_distances

BOX_MARGIN_M = 3.0  # the grid covers robot and target with this much room around both


class ForesightSearch:
    """`subgoal` as in the module docstring; speed_mps the robot's top speed, wall_clearance_m the distance its centre
    keeps from walls (robot radius + wall margin)."""

    def __init__(self, config: ForesightConfig, speed_mps: float, robot_radius_m: float,
                 wall_clearance_m: float) -> None:
        self.config = config
        self.speed_mps = float(speed_mps)
        self.robot_radius_m = float(robot_radius_m)
        self.wall_clearance_m = float(wall_clearance_m)
        self.last_path: np.ndarray | None = None
        self.nearest_m = math.inf  # the nearest the robot has come to its goal since `reset` (retreat_m)

    def reset(self) -> None:
        """Forget the episode: the nearest approach to the goal."""
        self.nearest_m, self.last_path = math.inf, None

    def subgoal(self, position: np.ndarray, target: np.ndarray, prediction: PedPrediction | None,
                walls: np.ndarray | None, goal: np.ndarray | None = None) -> np.ndarray:
        """The point (2,) m to head for from position (2,) towards target (2,), or the target itself. goal (2,) m:
        the episode's goal where target is a waypoint to it (the route's), for `retreat_m`; default target."""
        self.last_path = None
        position, target = np.asarray(position, float), np.asarray(target, float)
        goal = target if goal is None else np.asarray(goal, float)
        self.nearest_m = min(self.nearest_m, float(np.hypot(*(position - goal))))
        if prediction is None or not np.any(prediction.mask):
            return target
        cfg = self.config
        n = max(1, int(round(cfg.horizon_s / cfg.step_s)))
        xy, origin = self._grid(position, target, n * cfg.step_s)
        tracks, spread = person_tracks(prediction, cfg.step_s / 2.0, 2 * n)  # (2n + 1, P, 2), (2n + 1, P)
        radii = np.asarray(prediction.radii, float)[np.asarray(prediction.mask, bool)]
        contact = radii + self.robot_radius_m + np.minimum(cfg.max_inflation_m, cfg.spread_inflation * spread)
        free = self._free_of_walls(xy, walls)
        margins = (cfg.clearance_m, 0.0) if cfg.retry_without_margin else (cfg.clearance_m,)
        for margin in dict.fromkeys(margins):  # the margin first; without it if no set lives to the end
            hit = disc_cells(xy[0, 0], cfg.cell_m, xy.shape[:2], tracks, contact + margin)  # (2n + 1, G0, G1)
            blocked = hit[2::2] | hit[1::2]  # step j: at j step_s and half a step before
            if self._straight_is_free(position, target, xy, free, blocked):
                return target
            sets, end = self._reach(origin, xy, target, free, blocked)
            lives = end is not None and (len(sets) == n + 1 or np.hypot(*(xy[end] - target)) < cfg.goal_reach_m)
            if lives:
                break
        if end is None or not (lives or cfg.retry_without_margin):
            return target
        step_cells = int(math.ceil(self._speed * cfg.step_s / cfg.cell_m)) + 1
        path = trace_back(sets, end, step_cells)
        self.last_path = xy[tuple(np.array(path).T)]
        lead = int(round(cfg.lead_s / cfg.step_s))
        if lead >= len(path) - 1 and np.hypot(*(self.last_path[-1] - target)) < cfg.goal_reach_m:
            return target
        subgoal = self.last_path[min(lead, len(path) - 1)]
        if np.hypot(*(subgoal - goal)) > self.nearest_m + cfg.retreat_m:
            return position  # hold: backing away with an oncoming flow loses the ground gained (module docstring)
        return subgoal

    @property
    def _speed(self) -> float:
        return self.speed_mps * self.config.speed_fraction

    def _grid(self, position: np.ndarray, target: np.ndarray, horizon_s: float) -> tuple[np.ndarray, tuple[int, int]]:
        """Cell centres (G0, G1, 2) m, one of them exactly at `position`, and that cell's index."""
        h, reach = self.config.cell_m, self._speed * horizon_s + self.config.cell_m
        lo = np.maximum(np.minimum(position, target) - BOX_MARGIN_M, position - reach)
        hi = np.minimum(np.maximum(position, target) + BOX_MARGIN_M, position + reach)
        below = np.ceil((position - lo) / h).astype(int)
        above = np.ceil((hi - position) / h).astype(int)
        ax = [position[i] + h * np.arange(-below[i], above[i] + 1) for i in range(2)]
        return np.stack(np.meshgrid(ax[0], ax[1], indexing="ij"), axis=-1), (int(below[0]), int(below[1]))

    def _free_of_walls(self, xy: np.ndarray, walls: np.ndarray | None) -> np.ndarray:
        if walls is None or len(walls) == 0:
            return np.ones(xy.shape[:2], bool)
        d = point_segment_distances(xy.reshape(-1, 2), np.asarray(walls, float).reshape(-1, 4)).min(axis=-1)
        return (d >= self.wall_clearance_m).reshape(xy.shape[:2])

    def _straight_is_free(self, position: np.ndarray, target: np.ndarray, xy: np.ndarray, free: np.ndarray,
                          blocked: np.ndarray) -> bool:
        """Whether the searched speed straight at the target meets nobody at the sets' times until it arrives."""
        cfg, h = self.config, self.config.cell_m
        dist = float(np.hypot(*(target - position)))
        u = (target - position) / max(dist, 1e-9)
        for j in range(1, len(blocked) + 1):
            travelled = min(dist, self._speed * cfg.step_s * j)
            i = np.round((position + u * travelled - xy[0, 0]) / h).astype(int)
            if np.any(i < 0) or np.any(i >= np.array(free.shape)):
                return True  # off the grid: nothing known there
            if blocked[j - 1][i[0], i[1]] or not free[i[0], i[1]]:
                return False
            if travelled >= dist - cfg.goal_reach_m:
                return True
        return True

    def _reach(self, origin: tuple[int, int], xy: np.ndarray, target: np.ndarray, free: np.ndarray,
               blocked: np.ndarray) -> tuple[list[np.ndarray], tuple[int, int] | None]:
        """The reachable sets (sets[0] the start) and the cell (a cell of sets[-1]) to trace back from."""
        cfg = self.config
        start = np.zeros(free.shape, bool)
        start[origin] = True
        goal_d = np.hypot(*(xy - target).transpose(2, 0, 1))
        sets = [start]
        for j in range(len(blocked)):
            alive = dilate(sets[-1], self._speed * cfg.step_s, cfg.cell_m) & free & ~blocked[j]
            if not alive.any():
                break
            sets.append(alive)
            if np.any(alive & (goal_d < cfg.goal_reach_m)):
                break
        if len(sets) == 1:
            return sets, None
        end = np.unravel_index(np.argmin(np.where(sets[-1], goal_d, np.inf)), start.shape)
        return sets, (int(end[0]), int(end[1]))


def person_tracks(prediction: PedPrediction, step_s: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Each real person's sample mean (n_steps + 1, P, 2) m at 0, step_s, ..., n_steps step_s s and the samples' RMS
    distance from it (n_steps + 1, P) m: linear between the prediction's steps; past its last, the last step's
    velocity of the mean held and the spread kept."""
    mask = np.asarray(prediction.mask, bool)
    pos = np.asarray(prediction.positions, float)[:, :, mask]  # (K, T, P, 2)
    mean = np.concatenate([current_positions(prediction)[mask][None], pos.mean(axis=0)])  # (T + 1, P, 2)
    rms = np.concatenate([np.zeros((1, mean.shape[1])), np.sqrt(((pos - pos.mean(axis=0)) ** 2).sum(-1).mean(0))])
    t_end = prediction.step_s * (len(mean) - 1)
    velocity = (mean[-1] - mean[-2]) / prediction.step_s  # (P, 2)
    want = step_s * np.arange(n_steps + 1)
    u = np.minimum(want, t_end) / prediction.step_s
    i = np.minimum(np.floor(u).astype(int), len(mean) - 2)
    w = (u - i)[:, None]
    inside = mean[i] * (1.0 - w)[..., None] + mean[i + 1] * w[..., None]
    beyond = np.maximum(want - t_end, 0.0)[:, None, None] * velocity
    return inside + beyond, rms[i] * (1.0 - w) + rms[i + 1] * w


def disc_cells(origin: np.ndarray, h: float, shape: tuple[int, int], centres: np.ndarray,
               clear: np.ndarray) -> np.ndarray:
    """(..., G0, G1) bool: the cells of the grid with centres origin + (i, j) h (m) whose centre is closer than
    clear[..., s] (m) to centres[..., s, :] (..., S, 2) m. By scanlines: for each disc and each grid row its stencil
    crosses, the run of columns inside it (from the row's half-width), marked at its two ends in a difference array
    whose running sum along the row fills it; vectorised over all discs (6-9x the speed of marking every stencil cell
    on the search's grids, the same cells on 500 random cases)."""
    centres, clear = np.asarray(centres, float), np.asarray(clear, float)
    lead, (g0, g1) = centres.shape[:-2], shape
    if centres.shape[-2] == 0 or float(clear.max()) <= 0:
        return np.zeros((*lead, g0, g1), bool)
    n_lead = math.prod(lead)
    c = centres.reshape(n_lead, -1, 2)
    radius = np.broadcast_to(clear, centres.shape[:-1]).reshape(n_lead, -1)
    k = int(math.ceil(float(radius.max()) / h)) + 1  # stencil rows each side of a centre's cell
    r = np.arange(-k, k + 1)
    cell = np.floor((c - origin) / h)  # (L, S, 2): the cell below-left of each centre
    off = origin + cell * h - c  # (L, S, 2) m: that cell's centre from the disc's centre
    half2 = radius[..., None] ** 2 - (off[..., 0, None] + h * r) ** 2  # (L, S, M) m^2: each stencil row's half-width^2
    half = np.sqrt(np.maximum(half2, 0.0))
    row = cell[..., 0, None] + r
    lo = np.maximum(cell[..., 1, None] + np.floor((-half - off[..., 1, None]) / h) + 1, 0)  # strictly inside
    hi = np.minimum(cell[..., 1, None] + np.ceil((half - off[..., 1, None]) / h) - 1, g1 - 1)
    run = (half2 > 0) & (row >= 0) & (row < g0) & (lo <= hi)
    which = np.broadcast_to(np.arange(n_lead)[:, None, None], run.shape)[run]
    start = (which * g0 + row[run].astype(np.int64)) * (g1 + 1)
    size = n_lead * g0 * (g1 + 1)
    ends = (np.bincount(start + lo[run].astype(np.int64), minlength=size)
            - np.bincount(start + hi[run].astype(np.int64) + 1, minlength=size))
    return (np.cumsum(ends.reshape(n_lead, g0, g1 + 1), axis=-1)[..., :g1] > 0).reshape(*lead, g0, g1)


def distance_to_marked(mask: np.ndarray, radius_m: float, h: float) -> np.ndarray:
    """Distance (m) from each cell centre (cells of side h m) to the nearest marked centre (exact Euclidean), computed
    on the marked cells' bounding box grown by radius_m; inf outside that box or with nothing marked."""
    from scipy.ndimage import distance_transform_edt  # lazily: `import planner` stays numpy and casadi only

    out = np.full(mask.shape, np.inf)
    idx = np.argwhere(mask)
    if len(idx) == 0:
        return out
    pad = int(math.ceil(radius_m / h)) + 1
    lo = np.maximum(idx.min(axis=0) - pad, 0)
    hi = np.minimum(idx.max(axis=0) + pad + 1, mask.shape)
    out[lo[0]:hi[0], lo[1]:hi[1]] = distance_transform_edt(~mask[lo[0]:hi[0], lo[1]:hi[1]], sampling=h)
    return out


def dilate(mask: np.ndarray, radius_m: float, h: float) -> np.ndarray:
    """Cells whose centre lies within radius_m of a marked centre (cells of side h m)."""
    return distance_to_marked(mask, radius_m, h) <= radius_m + 1e-9


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
