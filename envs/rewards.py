"""Named reward terms. Each term is a plain number with a unit; the reward is the weighted sum.

progress: goal distance gained this step, m (negative when moving away).
success: 1 on the step the robot reaches its goal.
collision: 1 on the step the robot touches a pedestrian or a wall.
discomfort: dt x depth into the comfort zone as a fraction (0 at `discomfort_distance_m` surface
    distance or more, 1 at contact), s.
group_intrusion: dt if the robot's body overlaps a ground-truth group's region this step, s.
time: dt, s.
"""

from __future__ import annotations

from dataclasses import dataclass

from envs.config import CrowdNavConfig
from envs.scoring.metrics import SocialStep

TERMS = ("progress", "success", "collision", "discomfort", "group_intrusion", "time")


@dataclass(frozen=True)
class StepFacts:
    """What happened in one step. Distances in m."""

    goal_distance_before_m: float
    goal_distance_after_m: float
    reached_goal: bool
    hit_wall: bool
    min_surface_distance_m: float  # to the nearest pedestrian (inf with nobody around)
    intruding: bool
    social: SocialStep | None = None  # the metrics' social facts (`envs.scoring.metrics.social_step`); no reward reads

    @property
    def collided(self) -> bool:
        """Contact with a pedestrian (negative surface distance) or a wall."""
        return self.min_surface_distance_m < 0.0 or self.hit_wall


def comfort_depth(min_surface_distance_m: float, comfort_m: float) -> float:
    """How deep the robot is inside the comfort zone of width comfort_m (m) as a fraction: 0 at comfort_m surface
    distance or more, 1 at contact or overlap."""
    return min(max(comfort_m - min_surface_distance_m, 0.0), comfort_m) / comfort_m


def reward_terms(facts: StepFacts, cfg: CrowdNavConfig) -> dict[str, float]:
    """The unweighted terms of one step (see the module docstring)."""
    depth = comfort_depth(facts.min_surface_distance_m, cfg.discomfort_distance_m)
    return {
        "progress": facts.goal_distance_before_m - facts.goal_distance_after_m,
        "success": float(facts.reached_goal),
        "collision": float(facts.collided),
        "discomfort": cfg.dt_s * depth,
        "group_intrusion": cfg.dt_s * float(facts.intruding),
        "time": cfg.dt_s,
    }


def weighted(terms: dict[str, float], cfg: CrowdNavConfig) -> dict[str, float]:
    """Each term times its weight; their sum is the step reward."""
    weights = cfg.rewards.as_dict()
    return {name: weights[name] * terms[name] for name in TERMS}
