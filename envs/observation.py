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
        robot, in the robot frame, m; padding rows are 0. With `prediction_source` "oracle": the true future (K copies).
    prediction_error (P, 12), only with `prediction_calibration`: per row, how wrong this person's predictions have
        been so far in the episode at each step +0.4 ... +4.8 s: the conformal (1 - calibration_alpha) quantile of the
        displacement errors (to the nearest sample) of the predictions whose time has come, m (`envs.calibration`;
        0 where none has, and for padding rows).
    prediction_error_count (P,), only with `prediction_calibration`: how many step-1 (+0.4 s) errors that rests on,
        0..calibration_window (0 for padding rows).
    walls (R,), only if `wall_rays` > 0: range readings to the scene's walls, ray k at 360 k / R degrees left of
        the heading (holonomic: of +x), m, wall_range_m where no wall is within range.
Every value is clipped to its Box, so nothing is ever out of bounds.

The flattened layout: which index holds which field (`field_names`, `layout_table`), a flat vector back to named
fields, and the layout signature a trained agent is checked against (`signature`).

Gymnasium's `Dict` space sorts its keys, and `gymnasium.spaces.flatten` (and SB3's `MultiInputPolicy`, which
concatenates the keys in the same order) lays them out one after the other, each in C order:

    group_ids (P,) | pedestrian_mask (P,) | pedestrians (P, 5) | prediction_error (P, 12), if observed
    | prediction_error_count (P,), if observed | predictions (K, 12, P, 2), if observed | robot (7,)

and, with `wall_rays` R > 0, `walls` (R,) last. With the defaults (P = 20, no predictions, no wall rays) that is
20 + 20 + 100 + 7 = 147 values: group_ids 0-19,
pedestrian_mask 20-39, pedestrians 40-139 (row i at 40 + 5 i: x, y, vx, vy, radius) and robot 140-146.
`field_names(config)` names every index; `layout_table(config)` prints them as a table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from envs.config import CrowdNavConfig
from envs.scoring.geometry import ray_distances
from envs.scoring.kernels import observation_arrays
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
    if obs.prediction_calibration:
        items["prediction_error"] = spaces.Box(0.0, pb, (p, PRED_LEN), np.float32)
        items["prediction_error_count"] = spaces.Box(0.0, float(obs.calibration_window), (p,), np.float32)
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
                      group_id: np.ndarray, samples: np.ndarray | None, walls: np.ndarray | None = None,
                      calibration: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """The observation dict from the robot state (state_dim,), goal (2,), time left as a fraction, the
    pedestrians pos/vel (n, 2), radius (n,), group ids (n,), predicted samples (K, 12, n, 2) or None, the wall
    segments (S, 2, 2) m (read only when the space has `walls`) and the pedestrians' calibration, quantiles (n, 12) m
    and counts (n,) (`envs.calibration.PredictionCalibration.features`; read only when the space has
    `prediction_error`)."""
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
    if "prediction_error" in space.spaces:
        out.update(_calibration_rows(p, rows, calibration, bounds))
    if "walls" in space.spaces:
        r = cfg.observation.wall_rays
        heading = float(robot_state[2]) if unicycle else 0.0
        segs = np.zeros((0, 2, 2)) if walls is None else np.asarray(walls, float).reshape(-1, 2, 2)
        rays = ray_distances(here, heading + 2.0 * np.pi * np.arange(r) / r, segs, cfg.observation.wall_range_m)
        out["walls"] = np.clip(rays, *bounds["walls"]).astype(np.float32)
    return out


def _calibration_rows(p: int, rows: np.ndarray, calibration: tuple[np.ndarray, np.ndarray] | None,
                      bounds: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, np.ndarray]:
    """`prediction_error` (p, 12) and `prediction_error_count` (p,) of the observed rows (indices into the
    calibration's people), padding rows 0, clipped to their Boxes."""
    err, count = np.zeros((p, PRED_LEN), np.float32), np.zeros(p, np.float32)
    if calibration is not None and len(rows):  # errors and counts are >= 0: only the upper bounds can clip
        err[:len(rows)] = np.minimum(calibration[0][rows], bounds["prediction_error"][1][0, 0])
        count[:len(rows)] = np.minimum(calibration[1][rows], bounds["prediction_error_count"][1][0])
    return {"prediction_error": err, "prediction_error_count": count}


PED_FIELDS = ("x_m", "y_m", "vx_mps", "vy_mps", "radius_m")
ROBOT_FIELDS = {
    "unicycle": ("goal_x_m", "goal_y_m", "goal_distance_m", "speed_mps", "yaw_rate_radps", "radius_m",
                 "time_left_fraction"),
    "holonomic": ("goal_x_m", "goal_y_m", "goal_distance_m", "vx_mps", "vy_mps", "radius_m",
                  "time_left_fraction"),
}


@dataclass(frozen=True)
class Block:
    """One key of the observation in the flat vector: indices [start, stop), shape of the key's array."""

    key: str
    start: int
    stop: int
    shape: tuple[int, ...]


def blocks(config: CrowdNavConfig) -> list[Block]:
    """The keys in flattening order with their index ranges."""
    out, at = [], 0
    for key, box in observation_space(config).spaces.items():  # gymnasium sorts the keys
        size = int(np.prod(box.shape))
        out.append(Block(key, at, at + size, tuple(box.shape)))
        at += size
    return out


def flat_size(config: CrowdNavConfig) -> int:
    """Length of the flattened observation."""
    return blocks(config)[-1].stop


def field_names(config: CrowdNavConfig) -> list[str]:
    """The name of every index of the flat vector, e.g. "pedestrians[3].vx_mps", "robot.goal_distance_m"."""
    names: list[str] = []
    for b in blocks(config):
        if b.key == "robot":
            names += [f"robot.{f}" for f in ROBOT_FIELDS[config.robot.model]]
        elif b.key == "pedestrians":
            names += [f"pedestrians[{i}].{f}" for i in range(b.shape[0]) for f in PED_FIELDS]
        elif b.key == "walls":
            names += [f"walls[{k}].range_m" for k in range(b.shape[0])]
        elif b.key == "predictions":
            k, t, p, _ = b.shape
            names += [f"predictions[{s}][t={j}][{i}].{c}_m" for s in range(k) for j in range(t) for i in range(p)
                      for c in "xy"]
        elif b.key == "prediction_error":
            names += [f"prediction_error[{i}][t={j}].quantile_m" for i in range(b.shape[0]) for j in range(b.shape[1])]
        else:
            names += [f"{b.key}[{i}]" for i in range(b.shape[0])]
    return names


def unflatten(vector: np.ndarray, config: CrowdNavConfig) -> dict[str, np.ndarray]:
    """The observation dict of a flat vector (flat_size,) or a batch (B, flat_size): each key's array, shaped
    as in the observation (a batch keeps its leading axis). ValueError when the length does not match."""
    v = np.asarray(vector)
    if v.ndim not in (1, 2) or v.shape[-1] != flat_size(config):
        raise ValueError(f"expected a flat observation of length {flat_size(config)} (or a batch of them), "
                         f"got shape {v.shape}")
    lead = v.shape[:-1]
    return {b.key: v[..., b.start:b.stop].reshape(*lead, *b.shape) for b in blocks(config)}


def layout_table(config: CrowdNavConfig) -> str:
    """A markdown table of the layout: key, flat indices, shape and the fields of one row."""
    rows = ["| key | flat indices | shape | fields |", "|---|---|---|---|"]
    per_key = {"robot": ", ".join(ROBOT_FIELDS[config.robot.model]), "pedestrians": ", ".join(PED_FIELDS),
               "pedestrian_mask": "1 real row, 0 padding", "group_ids": "0..G-1 by first appearance, -1 padding",
               "predictions": "x_m, y_m (robot frame)", "walls": "range_m of ray k at 360 k / R deg",
               "prediction_error": "quantile_m of step t (t = 0..11: +0.4 ... +4.8 s)",
               "prediction_error_count": "step-1 errors behind the row's quantiles"}
    for b in blocks(config):
        rows.append(f"| {b.key} | {b.start}-{b.stop - 1} | {b.shape} | {per_key[b.key]} |")
    return "\n".join(rows)


def signature(config: CrowdNavConfig) -> dict[str, Any]:
    """What a trained agent depends on: the keys and their shapes, the robot model and P (JSON-ready)."""
    obs = config.observation
    out = {"keys": {b.key: list(b.shape) for b in blocks(config)}, "robot_model": config.robot.model,
           "max_pedestrians": obs.max_pedestrians, "group_source": obs.group_source}
    if obs.predictions:  # what the observed predictions mean (absent without them, as in agents saved before)
        out["prediction_source"] = obs.prediction_source
    if obs.prediction_calibration:
        out["calibration_alpha"] = obs.calibration_alpha
    return out


def mismatches(saved: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """Human-readable differences between a saved signature and the env's (empty when they fit)."""
    out = []
    for name in ("robot_model", "max_pedestrians", "group_source", "prediction_source", "calibration_alpha"):
        if name in saved and name in current and saved[name] != current[name]:
            out.append(f"{name} {saved[name]!r} (agent) vs {current[name]!r} (env)")
    keys_s, keys_c = saved.get("keys", {}), current["keys"]
    for key in sorted(set(keys_s) | set(keys_c)):
        if key not in keys_c:
            out.append(f"key {key!r} only in the agent's observation")
        elif key not in keys_s:
            out.append(f"key {key!r} only in the env's observation")
        elif list(keys_s[key]) != list(keys_c[key]):
            out.append(f"{key} shape {tuple(keys_s[key])} (agent) vs {tuple(keys_c[key])} (env)")
    return out
