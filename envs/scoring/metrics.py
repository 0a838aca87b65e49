"""Per-episode navigation metrics (definitions: docs/envs.md, "Evaluation metrics (envs)")."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from envs.scoring.kernels import min_time_to_collision
from envs.scoring.social_metrics import (
    ITR_OFFSETS_S,
    ZONES,
    FutureIntrusions,
    future_intrusions,
    group_contact,
    mean_jerk,
    path_irregularity,
    spl,
    zone_of,
)


class Pedestrians(Protocol):
    """The people at a state as the metrics read them (`envs.view.Pedestrians` is one; scoring imports no core
    module): ped_id (N,), pos (N, 2) m, radius (N,) m."""

    ped_id: np.ndarray
    pos: np.ndarray
    radius: np.ndarray


@dataclass
class PeopleTrack:
    """The people of each state of an episode, appended state by state: per state their ids (n,), positions (n, 2) m
    and radii (n,) m."""

    states: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)

    def add(self, ped_id: np.ndarray, pos: np.ndarray, radius: np.ndarray) -> None:
        self.states.append((np.array(ped_id, np.int64), np.array(pos, float).reshape(-1, 2),
                            np.array(radius, float).reshape(-1)))

    def dense(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(S, U, 2) positions m (NaN where absent), (S, U) bool presence and (S, U) radii m (NaN where absent):
        one column per person (U distinct ids, ascending), one row per state."""
        ids = [s[0] for s in self.states]
        counts = np.array([len(i) for i in ids])
        flat = np.concatenate(ids) if ids else np.zeros(0, np.int64)
        unique = np.unique(flat)
        rows, cols = np.repeat(np.arange(len(ids)), counts), np.searchsorted(unique, flat)
        pos = np.full((len(ids), len(unique), 2), np.nan)
        radius = np.full((len(ids), len(unique)), np.nan)
        present = np.zeros((len(ids), len(unique)), bool)
        if len(flat):
            pos[rows, cols] = np.concatenate([s[1] for s in self.states])
            radius[rows, cols] = np.concatenate([s[2] for s in self.states])
            present[rows, cols] = True
        return pos, present, radius


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
        `envs.scoring.collisions`. "" without a collision.
    collision_time_s: time of the collision, s (NaN without one).
    group_intrusion: whether the robot's body overlapped a ground-truth group's region on any step; None when the
        crowd has no group labels (`labelled` False: a recording without a group file).
    intrusion_fraction: fraction of steps with such an overlap (None without labels).
    spawn_contacts: contacts of kind "spawn" that did not end the episode
        (`CrowdNavConfig.spawn_contact_ends_episode` False; `envs.scoring.collisions.SpawnContacts`).

    The social-navigation metrics (`envs.scoring.social_metrics`; fed by `observe` once per step):
    time_<zone>_s / <zone>_fraction: seconds / fraction of the steps with the nearest person in that Hall zone
        (intimate, personal, social; exclusive bands, robot edge to person centre).
    group_collision: whether the robot touched a member of a group of >= 2 (None without group labels).
    path_irregularity_rad, jerk_mps3: None when undefined (no moving step; fewer than 3 steps).
    min_ttc_s: the smallest constant-velocity time to collision over the episode, s (inf: never on a course).
    spl: success weighted by path length (start, goal, goal_tolerance_m: the route; None before any `observe`).
    itr, itr_states, itr_sd_m: CrowdNav++'s intrusion ratio (fraction of the T + 1 states), its intruding states
        and the social distance during intrusions (m; None without any), from the robot's positions and `people`
        (`observe_people` at reset and every step, `continue_people` at the end; None when people were not observed).
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
    start: tuple[float, float] = (0.0, 0.0)  # the route, m, and the step, s (set by the env at reset)
    goal: tuple[float, float] = (0.0, 0.0)
    goal_tolerance_m: float = 0.0
    dt_s: float = 0.0
    zone_steps: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ZONES, 0))
    min_ttc_s: float = math.inf
    group_contact: bool = False
    robot_radius_m: float = 0.0
    positions: list[tuple[float, float]] = field(default_factory=list, repr=False)
    people: PeopleTrack = field(default_factory=PeopleTrack, repr=False)

    def update(self, dt_s: float, moved_m: float, min_surface_m: float, comfort_m: float, intruding: bool) -> None:
        self.steps += 1
        self.time_s += dt_s
        self.path_length_m += moved_m
        self.min_distance_m = min(self.min_distance_m, min_surface_m)
        self.discomfort_steps += int(min_surface_m < comfort_m)
        self.intrusion_steps += int(intruding)

    def observe(self, position: np.ndarray, social: SocialStep) -> None:
        """The step's end position (2,) m and social facts (`social_step`)."""
        if not self.positions:
            self.positions.append(self.start)
        self.positions.append((float(position[0]), float(position[1])))
        zone = zone_of(social.nearest_m)
        if zone < len(ZONES):
            self.zone_steps[ZONES[zone]] += 1
        self.min_ttc_s = min(self.min_ttc_s, social.ttc_s)
        self.group_contact |= social.group_contact

    def observe_people(self, peds: Pedestrians) -> None:
        """The people in the scene at a state (at reset, then after every step): `envs.view.Pedestrians`."""
        self.people.add(peds.ped_id, peds.pos, peds.radius)

    def continue_people(self, peds: Pedestrians, future: Callable[[np.ndarray, np.ndarray], np.ndarray] | None) -> None:
        """At the episode's end: where the people present now (`peds`) go next, as far as ITR's horizon needs past
        the last checked state, from `future(ped_ids, times_s)` ((K, N, 2) m, NaN once gone: `Crowd.future`); a
        crowd that cannot tell (None) leaves the horizon of the last states short."""
        k = math.ceil(max(ITR_OFFSETS_S) / self.dt_s - 1.0 - 1e-9) if self.dt_s > 0 else 0
        if future is None or k <= 0 or not self.people.states:
            return
        ahead = future(peds.ped_id, self.dt_s * np.arange(1, k + 1))
        if ahead is None:  # (a crowd class that declares `Crowd.future` without implementing it)
            return
        for rows in np.asarray(ahead, float).reshape(k, len(peds.ped_id), 2):
            here = ~np.isnan(rows).any(axis=1)
            self.people.add(peds.ped_id[here], rows[here], peds.radius[here])

    def intrusions(self) -> FutureIntrusions | None:
        """CrowdNav++'s intrusions of the episode so far (`future_intrusions`); None before the people of every
        robot state were observed."""
        xy = np.array(self.positions, float).reshape(-1, 2)
        if not len(xy) or len(self.people.states) < len(xy) or self.dt_s <= 0:
            return None
        pos, present, radius = self.people.dense()
        return future_intrusions(xy, pos, radius, self.robot_radius_m, self.dt_s, present)

    def social_dict(self) -> dict[str, float | bool | None]:
        """The social-navigation metrics (see the class docstring)."""
        out: dict[str, float | bool | None] = {}
        for zone, n in self.zone_steps.items():
            out[f"time_{zone}_s"] = n * self.dt_s
            out[f"{zone}_fraction"] = n / self.steps if self.steps else None
        xy = np.array(self.positions, float).reshape(-1, 2)
        out.update(group_collision=self.group_contact if self.labelled else None,
                   path_irregularity_rad=path_irregularity(xy, self.goal) if len(xy) else None,
                   jerk_mps3=mean_jerk(xy, self.dt_s) if self.dt_s > 0 else None, min_ttc_s=self.min_ttc_s,
                   spl=spl(self.success, self.start, self.goal, self.path_length_m, self.goal_tolerance_m)
                   if self.positions else None)  # (no observed step: no route to measure against)
        itr = self.intrusions()
        out.update(itr=None if itr is None else itr.ratio, itr_states=None if itr is None else itr.count,
                   itr_sd_m=None if itr is None else itr.social_distance_m)
        return out

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
            **self.social_dict(),
        }


@dataclass(frozen=True)
class SocialStep:
    """One step's social facts: nearest_m, the robot edge to the nearest person's centre at the step's end (m, inf
    with nobody); ttc_s, the smallest time to collision at the step's start (s, inf: no course); group_contact,
    whether the robot touched a member of a group of >= 2."""

    nearest_m: float
    ttc_s: float
    group_contact: bool


def social_step(start: np.ndarray, end: np.ndarray, dt_s: float, robot_radius_m: float, centre_m: np.ndarray,
                surface_m: np.ndarray, group_id: np.ndarray, before_pos: np.ndarray, before_vel: np.ndarray,
                before_radius: np.ndarray, before_active: np.ndarray | None = None) -> SocialStep:
    """The env's step as `SocialStep`: start, end (2,) m the robot's positions; centre_m, surface_m (n,) m the
    distances to the n people present at the end (`envs.scoring.kernels.step_distances`, contacts that do not count
    already +inf), group_id (n,) their groups; before_pos (m, 2) m, before_vel (m, 2) m/s, before_radius (m,) m
    the crowd's rows at the start, of which the `before_active` (m,) bool ones are present (None: all)."""
    nearest = float(centre_m.min()) - robot_radius_m if len(centre_m) else math.inf
    active = np.ones(len(before_pos), bool) if before_active is None else before_active
    ttc = min_time_to_collision(start, (end - start) / dt_s, before_pos, before_vel, before_radius, active,
                                robot_radius_m)
    touching = len(surface_m) and bool(surface_m.min() < 0.0)  # (a contact ends the episode: rare)
    contact = touching and bool(group_contact(surface_m[None], np.asarray(group_id, int)[None])[0])
    return SocialStep(nearest, ttc, bool(contact))
