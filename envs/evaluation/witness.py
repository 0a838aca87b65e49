"""Drive the benchmark's own robot along a space-time witness path, in the env: a constructive proof that an episode
can be won by that robot, acceleration and turn-rate limits included.

`envs.evaluation.reachability` proves an episode feasible for a holonomic robot. The benchmark's robot is usually a
unicycle (1.2 m/s, 1.5 m/s^2, 2 rad/s). `track` follows a timed path (one point per env step, from
`reachability.roomy_path`: slower than the robot and with extra clearance, so tracking errors have room) with a
look-ahead controller, in the very episode (same config and seed), and returns the env's outcome. A success there
is an episode the benchmark's robot can win knowing the future; a failure proves nothing (the tracker is simple).
"""

from __future__ import annotations

import math

import numpy as np

from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv

LOOKAHEAD_STEPS = 4  # the tracked point is this many env steps ahead on the path (0.4 s at dt 0.1 s)
HEADING_GAIN = 3.0  # yaw rate per rad of heading error, 1/s


def track(config: CrowdNavConfig, seed: int, path: np.ndarray) -> str:
    """Run episode `seed` of `config`, the robot tracking `path` (K + 1, 2) m (path[k]: where to be after k env
    steps; path[0] the start). Returns "success", "collision" or "timeout" (the env's outcome)."""
    env = CrowdNavEnv(config)
    env.reset(seed=seed)
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != 2 or not np.allclose(path[0], env.robot_state[:2], atol=1e-9):
        raise ValueError("path must be (K + 1, 2) and start at the episode's start")
    k, done, info = 0, False, {}
    while not done:
        _, _, terminated, truncated, info = env.step_control(_control(env, path, k))
        k += 1
        done = terminated or truncated
    m = info["episode_metrics"]
    return "success" if m["success"] else "collision" if m["collision"] else "timeout"


def _control(env: CrowdNavEnv, path: np.ndarray, k: int) -> np.ndarray:
    """The command (2,) that steers towards the path point LOOKAHEAD_STEPS ahead of step k (the goal past its
    end), at the speed that would reach it on time."""
    robot, dt, state = env.config.robot, env.config.dt_s, env.robot_state
    last = len(path) - 1
    target = env.goal if k + 1 > last else path[min(k + LOOKAHEAD_STEPS, last)]
    steps = max(1, min(k + LOOKAHEAD_STEPS, last) - k)
    e = np.asarray(target, float) - state[:2]
    dist = float(np.hypot(*e))
    if robot.model != "unicycle":
        v = e / (steps * dt)
        n = float(np.hypot(*v))
        return v if n <= robot.max_speed_mps else v * (robot.max_speed_mps / n)
    alpha = math.remainder(math.atan2(e[1], e[0]) - float(state[2]), 2.0 * math.pi)
    speed = min(robot.max_speed_mps, dist / (steps * dt)) * max(0.0, math.cos(alpha))
    return np.array([speed, max(-robot.max_yaw_rate_radps, min(robot.max_yaw_rate_radps, HEADING_GAIN * alpha))])
