"""Collision attribution: who moved into whom at the moment of contact.

The answer goes into the episode's `at_fault` field (`EpisodeMetrics`, `EpisodeRecord`; beside `collision_with`,
which says what was touched). Three values (`envs.evaluation.records.AT_FAULT`), decided from the step on which
contact is first detected:

    spawn       the pedestrian was not in the scene at the step's start (its track began within contact
                distance of the robot), or its replayed track began less than `SPAWN_WINDOW_S` before the
                contact: before one 0.4 s prediction step nobody has observed its velocity, and in that time
                the robot can move sideways by about 0.1 m, so no planner could avoid it;
    pedestrian  the pedestrian walked into a stopped or retreating robot: the robot's speed was under
                `STOPPED_MPS` (whatever the pedestrian did: a stopped robot moved into nobody), or the
                robot's velocity did not close the gap (component towards the pedestrian <= 0) while the
                pedestrian's did (component towards the robot > 0);
    robot       every other contact: the robot moved into the pedestrian (walls: always "robot").

Velocities are those of the step (robot: its displacement / dt; pedestrian: the crowd's velocity), directions
along the line of centres at the step's end.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

STOPPED_MPS = 0.1  # a robot slower than this counts as stopped, m/s
SPAWN_WINDOW_S = 0.4  # a replayed track younger than this at contact is a spawn (one prediction step), s


def collision_kind(robot_pos: np.ndarray, robot_vel: np.ndarray, ped_pos: np.ndarray, ped_vel: np.ndarray,
                   ped_is_new: bool) -> str:
    """Who is at fault for a robot-pedestrian contact: "robot", "pedestrian" or "spawn" (the `at_fault` value;
    see the module docstring). Positions (2,) m, velocities (2,) m/s."""
    if ped_is_new:
        return "spawn"
    gap = np.asarray(ped_pos, float) - np.asarray(robot_pos, float)
    dist = float(np.hypot(*gap))
    if dist < 1e-9:  # centres coincide: no line of centres, the faster body moved in
        return "robot" if np.hypot(*robot_vel) >= np.hypot(*ped_vel) else "pedestrian"
    n = gap / dist
    robot_closing = float(np.dot(robot_vel, n))
    ped_closing = float(-np.dot(ped_vel, n))
    if float(np.hypot(*robot_vel)) < STOPPED_MPS:
        return "pedestrian"
    return "pedestrian" if robot_closing <= 0.0 and ped_closing > 0.0 else "robot"


class SpawnContacts:
    """Contacts that began as spawns (at fault: "spawn"), kept out of the episode when they must not end it
    (`CrowdNavConfig.spawn_contact_ends_episode` False): such a pedestrian is ignored for contact, discomfort
    and reward until it is clear of the robot again by `clear_m` (m; the env passes its discomfort distance,
    0.2 m by default: without that margin a non-reactive replayed walker who has just slid off the robot's side
    touches it again a step later, the same encounter), and each such contact is counted once. A pedestrian
    seen for longer than the spawn window who then touches the robot is an ordinary contact."""

    def __init__(self, clear_m: float) -> None:
        self.clear_m = clear_m
        self.ids: set[int] = set()
        self.count = 0

    def reset(self) -> None:
        self.ids.clear()
        self.count = 0

    def filter(self, surface: np.ndarray, ped_ids: np.ndarray, is_new: Callable[[int], bool]) -> np.ndarray:
        """`surface` (n,) m, surface distances to the pedestrians `ped_ids` (n,), with those in a spawn contact
        set to +inf. `is_new(k)`: whether the contact with row k began as a spawn (called for contacts only)."""
        ghost = np.array([int(i) in self.ids for i in ped_ids], bool) if self.ids else np.zeros(len(ped_ids), bool)
        self.ids -= {int(i) for i in ped_ids[ghost & (surface >= self.clear_m)]}  # from now on it counts
        ghost &= surface < self.clear_m
        for k in np.flatnonzero((surface < 0.0) & ~ghost):
            if is_new(int(k)):
                self.ids.add(int(ped_ids[k]))
                self.count += 1
                ghost[k] = True
        return np.where(ghost, np.inf, surface)
