"""Collision attribution: who moved into whom at the moment of contact.

Three kinds (`envs.records.COLLISION_KINDS`), decided from the step on which contact is first detected:

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

import numpy as np

STOPPED_MPS = 0.1  # a robot slower than this counts as stopped, m/s
SPAWN_WINDOW_S = 0.4  # a replayed track younger than this at contact is a spawn (one prediction step), s


def collision_kind(robot_pos: np.ndarray, robot_vel: np.ndarray, ped_pos: np.ndarray, ped_vel: np.ndarray,
                   ped_is_new: bool) -> str:
    """The kind of a robot-pedestrian contact (see the module docstring). Positions (2,) m, velocities (2,) m/s."""
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
