"""A lane layer: in a flow of people, head for the side that is not coming the other way.

The MPC's goal cost pulls straight at the goal. In a bidirectional corridor or street that line runs into the
oncoming flow: the MPC dodges one walker after another, is pushed back, turns at speed and is herded out of the
corridor (traced in docs/results/planner.md, "Against the reference"). People in such a flow form lanes; a robot
that joins the lane going its way meets walkers at a small relative speed. `LaneKeeper.subgoal` does that with one
number, a lateral offset of the subgoal:

1. ``d``: the unit vector from the robot to its goal, ``n`` its left normal. Used only while the goal is in sight
   (the route layer, planner/route.py, handles walls in the way) and farther than ``min_goal_distance_m``.
2. Every pedestrian with an along-track coordinate in ``[0, lookahead_m]`` lays a Gaussian (width ``kernel_m``) on
   the lateral axis at its lateral coordinate, weighted 1 when it walks against ``d`` faster than
   ``min_speed_mps`` and ``other_weight`` otherwise (standing people and the robot's own flow are obstacles too,
   smaller ones). Its velocity is the prediction's first step (mean over samples) minus its position now.
3. Candidate offsets ``s`` every ``offset_step_m`` up to ``max_offset_m`` each way; a candidate's carrot is
   ``robot + carrot_m d + s n``, kept only when the straight segment to it keeps the MPC's wall clearance
   plus ``wall_extra_m`` (so a lane never presses the robot into a wall). Cost: the density at ``s``, plus
   ``straight_weight`` per metre of ``|s|`` and ``switch_weight`` per metre of change from the last offset.
4. The cheapest candidate's carrot is the subgoal. With no feasible candidate, or nobody in the window, the goal.

Units: metres, seconds. Pure numpy; one ``LaneKeeper`` per robot (it remembers the last offset).
"""

from __future__ import annotations

import numpy as np

from planner.config import LaneConfig
from planner.prediction import PedPrediction, current_positions
from planner.route import in_sight


def walker_states(prediction: PedPrediction | None) -> tuple[np.ndarray, np.ndarray]:
    """Real pedestrians' positions now (n, 2) m and velocities (n, 2) m/s (the prediction's first step, mean over
    its samples, minus the position now, per the prediction's step)."""
    if prediction is None:
        return np.zeros((0, 2)), np.zeros((0, 2))
    real = np.asarray(prediction.mask, bool)
    now = current_positions(prediction)[real]
    first = np.asarray(prediction.positions, float)[:, 0][:, real].mean(axis=0)
    return now, (first - now) / prediction.step_s


def lane_costs(offsets: np.ndarray, lateral: np.ndarray, weights: np.ndarray, cfg: LaneConfig,
               last: float) -> np.ndarray:
    """Cost (S,) of each lateral offset (S,) m given pedestrians' lateral coordinates (n,) m and weights (n,)."""
    gap = (offsets[:, None] - lateral[None]) / cfg.kernel_m
    density = (weights[None] * np.exp(-0.5 * gap * gap)).sum(-1)
    return density + cfg.straight_weight * np.abs(offsets) + cfg.switch_weight * np.abs(offsets - last)


class LaneKeeper:
    """Lane subgoals for a local planner (see the module docstring); `reset()` forgets the last offset."""

    def __init__(self, config: LaneConfig, wall_clearance_m: float) -> None:
        self.config, self.wall_clearance_m = config, float(wall_clearance_m)
        self.offset_m = 0.0

    def reset(self) -> None:
        self.offset_m = 0.0

    def subgoal(self, position: np.ndarray, goal: np.ndarray, prediction: PedPrediction | None,
                walls: np.ndarray | None) -> np.ndarray:
        """The point (2,) m to head for from position (2,) m towards goal (2,) m, or the goal itself."""
        cfg = self.config
        position, goal = np.asarray(position, float), np.asarray(goal, float)
        walls = np.zeros((0, 4)) if walls is None else np.asarray(walls, float).reshape(-1, 4)
        dist = float(np.linalg.norm(goal - position))
        if dist < max(cfg.min_goal_distance_m, 1e-6):
            self.offset_m = 0.0
            return goal
        pos, vel = walker_states(prediction)
        d = (goal - position) / dist
        n = np.array([-d[1], d[0]])
        rel = pos - position
        along, lateral = rel @ d, rel @ n
        ahead = (along >= 0.0) & (along <= cfg.lookahead_m)
        if not ahead.any():
            self.offset_m = 0.0
            return goal
        oncoming = (vel @ d) < -cfg.min_speed_mps
        weights = np.where(oncoming, 1.0, cfg.other_weight)[ahead]
        k = int(np.floor(cfg.max_offset_m / cfg.offset_step_m + 1e-9))
        offsets = cfg.offset_step_m * np.arange(-k, k + 1)
        carrots = position + cfg.carrot_m * d + offsets[:, None] * n
        ok = in_sight(position, carrots, walls, self.wall_clearance_m + cfg.wall_extra_m, 0.1)
        if not ok.any():
            return goal
        cost = np.where(ok, lane_costs(offsets, lateral[ahead], weights, cfg, self.offset_m), np.inf)
        best = int(np.argmin(cost))
        self.offset_m = float(offsets[best])
        return carrots[best]
