"""The flattened observation: which index holds which field, a flat vector back to named fields, and the
layout signature a trained agent is checked against.

Gymnasium's `Dict` space sorts its keys, and `gymnasium.spaces.flatten` (and SB3's `MultiInputPolicy`, which
concatenates the keys in the same order) lays them out one after the other, each in C order:

    group_ids (P,) | pedestrian_mask (P,) | pedestrians (P, 5) | predictions (K, 12, P, 2), if observed | robot (7,)

and, with `wall_rays` R > 0, `walls` (R,) last. With the defaults (P = 20, no predictions, no wall rays) that is
20 + 20 + 100 + 7 = 147 values: group_ids 0-19,
pedestrian_mask 20-39, pedestrians 40-139 (row i at 40 + 5 i: x, y, vx, vy, radius) and robot 140-146.
`field_names(config)` names every index; `layout_table(config)` prints them as a table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from envs.config import CrowdNavConfig
from envs.observation import observation_space

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
               "predictions": "x_m, y_m (robot frame)", "walls": "range_m of ray k at 360 k / R deg"}
    for b in blocks(config):
        rows.append(f"| {b.key} | {b.start}-{b.stop - 1} | {b.shape} | {per_key[b.key]} |")
    return "\n".join(rows)


def signature(config: CrowdNavConfig) -> dict[str, Any]:
    """What a trained agent depends on: the keys and their shapes, the robot model and P (JSON-ready)."""
    return {"keys": {b.key: list(b.shape) for b in blocks(config)}, "robot_model": config.robot.model,
            "max_pedestrians": config.observation.max_pedestrians,
            "group_source": config.observation.group_source}


def mismatches(saved: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """Human-readable differences between a saved signature and the env's (empty when they fit)."""
    out = []
    for name in ("robot_model", "max_pedestrians", "group_source"):
        if name in saved and saved[name] != current[name]:
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
