"""Crowd-risk helpers of the scene builder (numpy only): which pedestrians to constrain, how much to inflate
their clearance, and how fast the robot may go near them.

* **Ranking** (:func:`predicted_gaps`): with ``MPCConfig.rank_peds_by == "predicted"`` the M constrained
  pedestrians are those that come closest to the robot's reference path (the shifted previous plan, or the
  robot coasting at its current velocity) at the same time, over all samples and the horizon, instead of the
  M nearest now. A pedestrian walking at the robot from behind or the side is then constrained even in a
  dense crowd where eight others stand closer.
* **Clearance inflation** (:func:`clearance_inflation`): at a checked time t (s) the clearance of a pedestrian
  grows by ``clearance_growth_mps * t + spread_inflation * spread(t)``, capped at
  ``max_clearance_inflation_m``; spread(t) is the root-mean-square distance (m) of the predictor's samples
  from their mean at t (0 now). Both are chance-constraint-like margins: the later and the less certain a
  predicted position, the wider the berth.
* **Speed cap** (:func:`speed_cap`): the speed the robot may plan is at most
  ``speed_cap_min_mps + speed_cap_gain_per_s * d`` (m/s), d the smallest surface gap (m) between the robot's
  current position and a pedestrian in front of it (bearing within ``speed_cap_half_angle_deg`` of the
  heading) now and at its predicted mean positions up to ``speed_cap_lookahead_s``. Per stage k the cap is
  relaxed to what braking at the acceleration limit allows, so it never makes the problem infeasible.
"""

from __future__ import annotations

import numpy as np

from planner.config import MPCConfig


def sample_spread(positions: np.ndarray) -> np.ndarray:
    """(S, T, N, 2) samples -> (T, N) root-mean-square distance (m) of the samples from their mean."""
    dev = positions - positions.mean(axis=0, keepdims=True)
    return np.sqrt((dev * dev).sum(-1).mean(axis=0))


def resample_scalar(values: np.ndarray, step_s: float, dt_s: float, n_times: int, now: float = 0.0) -> np.ndarray:
    """(T, N) values at +step_s, .., +T step_s (``now`` at t=0) -> (n_times, N) at +dt_s, .., held after T."""
    t_known = step_s * np.arange(values.shape[0] + 1)
    known = np.concatenate([np.full((1, values.shape[1]), now), values], axis=0)
    t_query = dt_s * np.arange(1, n_times + 1)
    return np.stack([np.interp(t_query, t_known, known[:, n]) for n in range(values.shape[1])], axis=1) \
        if values.shape[1] else np.zeros((n_times, 0))


def clearance_inflation(spread: np.ndarray, cfg: MPCConfig, sub_dt_s: float) -> np.ndarray:
    """Clearance added (m) at the checked times (nt, N) from spread (nt, N) m (see the module doc)."""
    t = sub_dt_s * np.arange(1, spread.shape[0] + 1)[:, None]
    extra = cfg.clearance_growth_mps * t + cfg.spread_inflation * spread
    return np.minimum(extra, cfg.max_clearance_inflation_m)


def predicted_gaps(stage_samples: np.ndarray, now: np.ndarray, reference_xy: np.ndarray) -> np.ndarray:
    """Smallest centre distance (m) per pedestrian (N,) between samples (S, H, N, 2) / current positions
    (N, 2) and the robot's reference path (H+1, 2) at the same times (row 0 = now)."""
    d_now = np.linalg.norm(now - reference_xy[0], axis=-1)
    if stage_samples.shape[1] == 0:
        return d_now
    diff = stage_samples - reference_xy[None, 1: stage_samples.shape[1] + 1, None, :]
    d_pred = np.sqrt((diff * diff).sum(-1)).min(axis=(0, 1))
    return np.minimum(d_now, d_pred)


def coast_reference(state: np.ndarray, model: str, dt_s: float, h: int) -> np.ndarray:
    """(H+1, 2) positions of the robot keeping its current velocity (straight line)."""
    if model == "unicycle":
        vel = state[3] * np.array([np.cos(state[2]), np.sin(state[2])])
    else:
        vel = state[2:4]
    return state[:2] + dt_s * np.arange(h + 1)[:, None] * vel


def heading_direction(state: np.ndarray, model: str, goal: np.ndarray) -> np.ndarray:
    """Unit direction (2,) the robot faces: unicycle heading; holonomic velocity, or the goal if at rest."""
    if model == "unicycle":
        return np.array([np.cos(state[2]), np.sin(state[2])])
    d = state[2:4] if np.linalg.norm(state[2:4]) > 1e-3 else goal - state[:2]
    n = np.linalg.norm(d)
    return d / n if n > 1e-9 else np.array([1.0, 0.0])


def speed_cap(state: np.ndarray, goal: np.ndarray, mean_stage: np.ndarray, now: np.ndarray, radii: np.ndarray,
              cfg: MPCConfig) -> np.ndarray:
    """Per-stage speed bound (H,) m/s for the robot (see the module doc); mean_stage (H, N, 2) are the
    pedestrians' predicted mean positions at the plan times, now (N, 2), radii (N,), all real."""
    rc, h = cfg.robot, cfg.horizon_steps
    cap = rc.max_speed_mps
    if now.shape[0] and np.isfinite(cfg.speed_cap_gain_per_s):
        rel = now - state[:2]
        dist = np.linalg.norm(rel, axis=1)
        facing = heading_direction(state, rc.model, goal)
        cos_b = (rel @ facing) / np.maximum(dist, 1e-9)
        ahead = cos_b >= np.cos(np.radians(cfg.speed_cap_half_angle_deg))
        if ahead.any():
            n_look = int(np.floor(cfg.speed_cap_lookahead_s / cfg.dt_s + 1e-9))
            pts = np.concatenate([now[None], mean_stage[:n_look]], axis=0)[:, ahead]  # (1+n_look, A, 2)
            gap = np.linalg.norm(pts - state[:2], axis=-1).min(axis=0) - rc.radius_m - radii[ahead]
            cap = min(cap, cfg.speed_cap_min_mps + cfg.speed_cap_gain_per_s * max(float(gap.min()), 0.0))
    v0 = abs(state[3]) if rc.model == "unicycle" else float(np.linalg.norm(state[2:4]))
    brake = v0 - rc.max_accel_mps2 * cfg.dt_s * np.arange(1, h + 1)
    return np.maximum(cap, brake)
