"""The observation: a flat Dict of float32 Boxes with finite bounds (SB3's MultiInputPolicy accepts it).

Keys (P = max_pedestrians, K = n_prediction_samples):
    robot (7,): goal position in the robot frame (x ahead, y left) m (2), goal distance m, velocity
        (unicycle: forward speed m/s and yaw rate rad/s; holonomic: vx, vy in the robot's world-aligned
        frame, m/s), robot radius m, fraction of the time limit left.
    pedestrians (P, 5): the nearest observed pedestrians, nearest first: position relative to the robot
        in the robot frame m (2), velocity in the robot frame m/s (2), body radius m. Padding rows are 0.
    pedestrian_mask (P,): 1 for a real row, 0 for padding.
    group_ids (P,): group ids renumbered 0..G-1 in order of first appearance among the rows (truth or
        predicted, by config); -1 for padding.
    predictions (K, 12, P, 2), only if configured: sampled futures at +0.4 ... +4.8 s relative to the
        robot, in the robot frame, m; padding rows are 0.
    walls (R,), only if `wall_rays` > 0: range readings to the scene's walls, ray k at 360 k / R degrees left of
        the heading (holonomic: of +x), m, wall_range_m where no wall is within range.
Every value is clipped to its Box, so nothing is ever out of bounds.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from envs.config import CrowdNavConfig
from envs.geometry import ray_distances
from envs.kernels import observation_arrays
from envs.timing import DEFAULT_TIMING

PRED_LEN = DEFAULT_TIMING.pred_len


def observation_space(cfg: CrowdNavConfig) -> spaces.Dict:
    obs, p = cfg.observation, cfg.observation.max_pedestrians
    pb, vb = obs.position_bound_m, obs.speed_bound_mps
    robot_hi = np.array([pb, pb, pb, vb, max(vb, cfg.robot.max_yaw_rate_radps), 5.0, 1.0], np.float32)
    robot_lo = -robot_hi
    robot_lo[[2, 5, 6]] = 0.0
    ped_hi = np.broadcast_to(np.array([pb, pb, vb, vb, 5.0], np.float32), (p, 5))
    ped_lo = ped_hi * np.array([-1, -1, -1, -1, 0], np.float32)
    items = {
        "robot": spaces.Box(robot_lo, robot_hi, dtype=np.float32),
        "pedestrians": spaces.Box(ped_lo, ped_hi.copy(), dtype=np.float32),
        "pedestrian_mask": spaces.Box(0.0, 1.0, (p,), np.float32),
        "group_ids": spaces.Box(-1.0, float(p - 1), (p,), np.float32),
    }
    if obs.predictions:
        items["predictions"] = spaces.Box(-pb, pb, (obs.n_prediction_samples, PRED_LEN, p, 2), np.float32)
    if obs.wall_rays:
        items["walls"] = spaces.Box(0.0, obs.wall_range_m, (obs.wall_rays,), np.float32)
    return spaces.Dict(items)


def rotation(heading: float) -> np.ndarray:
    """(2, 2) matrix taking world vectors into the frame of a robot with this heading (rad)."""
    c, s = np.cos(heading), np.sin(heading)
    return np.array([[c, s], [-s, c]])


def _bounds(space: spaces.Dict) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(low, high) of each Box of an observation space, cached on the space (its Boxes do not change)."""
    cached = getattr(space, "_crowdnav_bounds", None)
    if cached is None:
        cached = {key: (box.low, box.high) for key, box in space.spaces.items()}
        space._crowdnav_bounds = cached
    return cached


def build_observation(cfg: CrowdNavConfig, space: spaces.Dict, robot_state: np.ndarray, goal: np.ndarray,
                      time_left: float, pos: np.ndarray, vel: np.ndarray, radius: np.ndarray,
                      group_id: np.ndarray, samples: np.ndarray | None,
                      walls: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The observation dict from the robot state (state_dim,), goal (2,), time left as a fraction, the
    pedestrians pos/vel (n, 2), radius (n,), group ids (n,), predicted samples (K, 12, n, 2) or None, and
    the wall segments (S, 2, 2) m (read only when the space has `walls`)."""
    p = cfg.observation.max_pedestrians
    unicycle = cfg.robot.model == "unicycle"
    rot = rotation(float(robot_state[2])) if unicycle else np.eye(2)
    here = robot_state[:2]
    bounds = _bounds(space)
    robot, peds, mask, groups, rows = observation_arrays(
        robot_state, goal, rot, unicycle, cfg.robot.radius_m, time_left, pos, vel, radius, group_id, p,
        cfg.observation.sensor_range_m, bounds["robot"], bounds["pedestrians"])
    out = {"robot": robot, "pedestrians": peds, "pedestrian_mask": mask, "group_ids": groups}
    n = len(rows)
    if "predictions" in space.spaces:
        k = cfg.observation.n_prediction_samples
        pred = np.zeros((k, PRED_LEN, p, 2))
        if samples is not None and n:
            pred[:, :, :n] = (samples[:k, :, rows] - here) @ rot.T
        out["predictions"] = np.clip(pred, *bounds["predictions"]).astype(np.float32)
    if "walls" in space.spaces:
        r = cfg.observation.wall_rays
        heading = float(robot_state[2]) if unicycle else 0.0
        segs = np.zeros((0, 2, 2)) if walls is None else np.asarray(walls, float).reshape(-1, 2, 2)
        rays = ray_distances(here, heading + 2.0 * np.pi * np.arange(r) / r, segs, cfg.observation.wall_range_m)
        out["walls"] = np.clip(rays, *bounds["walls"]).astype(np.float32)
    return out
