"""Per-episode navigation metrics (definitions: docs/envs.md, "Evaluation metrics (envs)")."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class EpisodeMetrics:
    """Accumulates one episode step by step.

    success / collision / timeout: how the episode ended (at most one is true; none while running).
    time_to_goal_s: time of arrival, s (NaN unless success).
    path_length_m: distance the robot travelled, m.
    min_distance_m: smallest surface distance (centre distance minus both radii) between the robot and
        any pedestrian over the episode, m (inf if nobody was ever in the scene; negative = overlap).
    discomfort_frequency: fraction of steps whose smallest surface distance is under the comfort distance.
    collision_with: what the robot touched: "pedestrian" or "wall".
    at_fault: who caused the contact: "robot" (the robot moved into the pedestrian; every wall contact),
        "pedestrian" (walked into a stopped or retreating robot) or "spawn" (a track that began in contact);
        `envs.collisions`. "" without a collision.
    collision_time_s: time of the collision, s (NaN without one).
    group_intrusion: whether the robot's body overlapped a ground-truth group's region on any step; None when the
        crowd has no group labels (`labelled` False: a recording without a group file).
    intrusion_fraction: fraction of steps with such an overlap (None without labels).
    spawn_contacts: contacts of kind "spawn" that did not end the episode
        (`CrowdNavConfig.spawn_contact_ends_episode` False; `envs.collisions.SpawnContacts`).
    """

    steps: int = 0
    time_s: float = 0.0
    success: bool = False
    collision: bool = False
    collision_with: str = ""
    at_fault: str = ""
    collision_time_s: float = math.nan
    timeout: bool = False
    time_to_goal_s: float = math.nan
    path_length_m: float = 0.0
    min_distance_m: float = math.inf
    discomfort_steps: int = 0
    intrusion_steps: int = 0
    spawn_contacts: int = 0
    labelled: bool = True

    def update(self, dt_s: float, moved_m: float, min_surface_m: float, comfort_m: float, intruding: bool) -> None:
        self.steps += 1
        self.time_s += dt_s
        self.path_length_m += moved_m
        self.min_distance_m = min(self.min_distance_m, min_surface_m)
        self.discomfort_steps += int(min_surface_m < comfort_m)
        self.intrusion_steps += int(intruding)

    @property
    def discomfort_frequency(self) -> float:
        return self.discomfort_steps / self.steps if self.steps else 0.0

    @property
    def intrusion_fraction(self) -> float | None:
        if not self.labelled:
            return None
        return self.intrusion_steps / self.steps if self.steps else 0.0

    @property
    def group_intrusion(self) -> bool | None:
        return self.intrusion_steps > 0 if self.labelled else None

    @property
    def outcome(self) -> str:
        return "success" if self.success else "collision" if self.collision else "timeout" if self.timeout else ""

    def as_dict(self) -> dict[str, float | bool | str | int | None]:
        return {
            "outcome": self.outcome, "success": self.success, "collision": self.collision,
            "collision_with": self.collision_with, "at_fault": self.at_fault,
            "collision_time_s": self.collision_time_s, "timeout": self.timeout, "steps": self.steps,
            "time_s": self.time_s, "time_to_goal_s": self.time_to_goal_s, "path_length_m": self.path_length_m,
            "min_distance_m": self.min_distance_m, "discomfort_frequency": self.discomfort_frequency,
            "group_intrusion": self.group_intrusion, "intrusion_fraction": self.intrusion_fraction,
            "spawn_contacts": self.spawn_contacts,
        }
