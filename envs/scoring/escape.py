"""Could the robot have escaped a contact from the moment the pedestrian first appeared? A check of at-fault calls.

`envs.scoring.collisions` calls a contact "spawn" (unavoidable) only when the pedestrian's track is younger than
`SPAWN_WINDOW_S` (0.4 s). In replayed recordings people also enter the annotated area a metre or two from the robot
and touch it 0.4-0.8 s later, which counts as the robot's (or the pedestrian's) fault. `escape_clearance` asks what
the robot could have done: from its state when the pedestrian first appeared, every constant command of a grid
(forward speed x yaw rate for the unicycle, speed x direction for the holonomic robot, each ramped by the robot's
acceleration limits as the env applies it) is held while the pedestrian walks the track it then walked; the answer is
the largest surface clearance (m) any of them kept over the whole track. Negative: none of these commands avoided the
contact, even knowing the pedestrian's future from its first frame. This is a lower bound on what any control could
do (a command that changes along the way might do better), so a negative value says "not escapable by a constant
command", not "unavoidable"; a positive one says "escapable, by this much". Only the one pedestrian is considered.

`scripts/escape_check.py` re-runs a benchmark run's collision episodes and prints it for each (docs/envs.md, "Who is
at fault"). Units: m, s.
"""

from __future__ import annotations

import numpy as np

from planner import RobotConfig
from planner.shield import command_grid, rollout_constant

ESCAPE_SPEEDS = 7  # forward speeds (unicycle: from the reverse limit to the top speed) / speed magnitudes (holonomic)
ESCAPE_TURNS = 11  # yaw rates (unicycle) / directions (holonomic: 2 * ESCAPE_TURNS)


def escape_commands(robot: RobotConfig) -> np.ndarray:
    """(C, 2) constant commands: the safety shield's grid (`planner.shield.command_grid`), finer."""
    return command_grid(robot, ESCAPE_SPEEDS, ESCAPE_TURNS)


def escape_clearance(robot_state: np.ndarray, robot: RobotConfig, dt_s: float, ped_track: np.ndarray,
                     ped_radius_m: float) -> float:
    """The largest surface clearance (m; negative: overlap) that a constant command (`escape_commands`), held from
    robot_state (state_dim,) at the pedestrian's first appearance, keeps from the pedestrian walking ped_track
    (T + 1, 2) m (its positions at 0, dt_s, ..., T dt_s; row 0 where it appeared). Raises ValueError on a malformed
    or non-finite input."""
    track = np.asarray(ped_track, float)
    state = np.asarray(robot_state, float)
    if track.ndim != 2 or track.shape[1] != 2 or len(track) < 2:
        raise ValueError(f"ped_track must be (T + 1, 2) with T >= 1, got shape {track.shape}")
    if not (np.all(np.isfinite(track)) and np.all(np.isfinite(state))):
        raise ValueError("robot_state and ped_track must be finite")
    if not (dt_s > 0 and ped_radius_m >= 0):
        raise ValueError(f"dt_s must be > 0 and ped_radius_m >= 0, got {dt_s}, {ped_radius_m}")
    robot_xy = rollout_constant(state, escape_commands(robot), len(track) - 1, dt_s, robot)  # (C, T, 2)
    robot_xy = np.concatenate([np.broadcast_to(state[:2], (len(robot_xy), 1, 2)), robot_xy], axis=1)
    gap = np.hypot(*(robot_xy - track[None]).transpose(2, 0, 1)) - robot.radius_m - ped_radius_m  # (C, T + 1)
    return float(gap.min(axis=1).max())
