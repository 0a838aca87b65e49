"""Following a walker going the robot's way: where the robot's lane meets an oncoming flow, a subgoal behind a leader.

In a two-way flow of people who do not avoid the robot (crowdnav-v1's invisible corridor), the MPC meets a file of
oncoming walkers one at a time, every local move looks unsafe, and the robot is walked into or walks into someone.
People do avoid each other: the space just behind someone walking the robot's way is kept clear of the oncoming flow
by that person. `FollowLayer.subgoal` puts the MPC's subgoal there:

1. The way: the unit vector from the robot to its target (the goal, or the route's carrot). Each person's velocity is
   their predicted mean's first step from where they are now; `along` and `lateral` are their offsets along the way
   and across it.
2. Nothing to do (the target is returned) unless someone is oncoming in the robot's lane: ahead within `look_m`,
   within `band_m` of the way's line, walking at the robot faster than `oncoming_mps`.
3. Leaders: people ahead (0.3 m to `look_m`, nearer than the target), within `max_lateral_m` of the way, walking the
   robot's way at `min_speed_mps` or faster. Each leader's lane (`band_m` either side of them, from just behind them
   to `look_m` beyond) is scored by how many oncoming people are in it; the leader of the emptiest lane is followed,
   ties to the nearest; the last call's leader is kept while it is still a leader and its lane holds at most one
   oncoming person more than the best (no switching every step between equal lanes).
4. The subgoal: the leader's predicted mean position `at_s` ahead (held at its last velocity past the prediction's
   end), `gap_m` back along the way; the target itself when that point is past the target.

Units: metres, seconds; arrays as in planner/prediction.py. numpy only; state: the last leader's position now
(`leader`, (2,) m or None), kept for the hysteresis and for drawing; `reset` forgets it.
"""

from __future__ import annotations

import numpy as np

from planner.config import FollowConfig
from planner.prediction import PedPrediction, current_positions

KEEP_M = 0.6  # the last leader is the leader now nearest its predicted position, if within this, m
MIN_AHEAD_M = 0.3  # a leader is at least this far ahead of the robot along the way, m


class FollowLayer:
    """`subgoal` as in the module docstring."""

    def __init__(self, config: FollowConfig) -> None:
        self.config = config
        self.leader: np.ndarray | None = None  # the followed person's position now (2,) m; None: nobody followed
        self._expected: np.ndarray | None = None  # where the last leader should be at the next call (2,) m

    def reset(self) -> None:
        self.leader, self._expected = None, None

    def subgoal(self, robot_xy: np.ndarray, target: np.ndarray, prediction: PedPrediction | None,
                step_s: float = 0.1) -> np.ndarray:
        """The MPC's subgoal (2,) m: `target` (2,) m, or a point behind a leader (module docstring). robot_xy (2,) m;
        step_s: time to the next call (s), for keeping the leader."""
        self.leader = None
        target = np.asarray(target, float)
        way = target - robot_xy
        dist = float(np.hypot(*way))
        if prediction is None or not prediction.mask.any() or dist < 1.0:
            self._expected = None
            return target
        u = way / dist
        n = np.array([-u[1], u[0]])
        rows = np.flatnonzero(prediction.mask)
        now = current_positions(prediction)[rows]
        mean = prediction.positions[:, :, rows].mean(axis=0)  # (T, n, 2)
        vel = (mean[0] - now) / prediction.step_s
        rel = now - robot_xy
        along, lateral, v_along = rel @ u, rel @ n, vel @ u
        cfg = self.config
        oncoming = (v_along < -cfg.oncoming_mps) & (along > 0.0) & (along < cfg.look_m)
        blocked = bool(np.any(oncoming & (np.abs(lateral) < cfg.band_m)))
        leaders = np.flatnonzero((along > MIN_AHEAD_M) & (along < min(cfg.look_m, dist)) &
                                 (np.abs(lateral) < cfg.max_lateral_m) & (v_along >= cfg.min_speed_mps))
        if not blocked or leaders.size == 0:
            self._expected = None
            return target
        busy = np.array([np.sum(oncoming & (np.abs(lateral - lateral[c]) < cfg.band_m) & (along > along[c] - 0.5))
                         for c in leaders])
        order = np.lexsort((np.hypot(along[leaders], lateral[leaders]), busy))
        pick = leaders[order[0]]
        if self._expected is not None:  # the last call's leader, if it is still one, between lanes about as empty
            gaps = np.hypot(*(now[leaders] - self._expected).T)
            kept = int(np.argmin(gaps))
            if gaps[kept] < KEEP_M and busy[kept] <= busy[order[0]] + 1:
                pick = leaders[kept]
        ahead = _position_at(mean[:, pick], now[pick], prediction.step_s, cfg.at_s)
        self.leader = now[pick].copy()
        self._expected = now[pick] + vel[pick] * step_s
        point = ahead - cfg.gap_m * u
        return target if float((point - robot_xy) @ u) >= dist else point


def _position_at(track: np.ndarray, now: np.ndarray, step_s: float, t_s: float) -> np.ndarray:
    """A person's position (2,) m at t_s ahead from their predicted track (T, 2) m at step_s, step_s .. T step_s
    (linear between steps, their last step's velocity held past the end) and their position now (2,) m."""
    times = step_s * np.arange(len(track) + 1)
    pts = np.vstack([now[None], track])
    if t_s <= times[-1]:
        return np.array([np.interp(t_s, times, pts[:, 0]), np.interp(t_s, times, pts[:, 1])])
    last_vel = (pts[-1] - pts[-2]) / step_s
    return pts[-1] + last_vel * (t_s - times[-1])
