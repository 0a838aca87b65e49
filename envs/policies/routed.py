"""`NAME+route`: a policy that heads for the global route's subgoal through the walls instead of the goal.

A learned agent sees walls only through its range rays and the goal as a vector: with the goal behind a wall it
drives at the wall (the doors of crowdnav-v1). The MPC has the same problem and solves it with a global route
(`planner.route.Router`: a shortest path on a grid over the free space, and a subgoal on it that the robot can see).
This wrapper gives the wrapped policy that subgoal in place of the goal, every step:

- `view.goal` becomes the subgoal (planner policies, plug-ins);
- in the observation, the robot's goal features (`robot[0:3]`: the goal in the robot frame, x ahead and y left, m,
  and its distance, m) are recomputed for the subgoal, as `envs.observation` computes them, and clipped to the box.

Where the goal is in sight, or no wall stands in the scene, the subgoal is the goal and the view passes unchanged.
Settings: `PolicyConfig.mpc.route` (`RouteConfig`) and the MPC's wall clearance (robot radius + wall margin), the ones
`mpc-gpgraph` routes with. The episode still ends at the real goal.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from envs.observation import rotation
from envs.policies.wrappers import ROUTE_SUFFIX
from envs.view import Decision, PolicyView
from planner import MPCConfig, Router


class RoutedPolicy:
    """`inner` heading for the route's subgoal (see the module docstring); `env` gives the observation's bounds."""

    def __init__(self, inner: Any, config: MPCConfig, env: Any) -> None:
        if config.route is None:
            raise ValueError("+route needs MPCConfig.route (a RouteConfig; None turns the route off)")
        self.inner, self.name = inner, f"{inner.name}{ROUTE_SUFFIX}"
        self.reads_history = getattr(inner, "reads_history", True)
        self.reads_track = getattr(inner, "reads_track", False)
        self.router = Router(config.route, config.wall_clearance_m)
        self._unicycle = config.robot.model == "unicycle"
        box = env.observation_space["robot"]
        self._low, self._high = box.low[:3], box.high[:3]

    @property
    def stats(self) -> Any:
        return getattr(self.inner, "stats", None)

    def reset(self, seed: int | None = None) -> None:
        self.inner.reset(seed)
        self.router.reset()

    def act(self, view: PolicyView) -> Decision:
        if view.walls is None or len(view.walls) == 0:
            return self.inner.act(view)
        here = view.robot_state[:2]
        subgoal = self.router.subgoal(here, view.goal, view.walls)
        if np.array_equal(subgoal, view.goal):
            return self.inner.act(view)
        return self.inner.act(replace(view, goal=subgoal, obs=self._observed(view, subgoal)))

    def _observed(self, view: PolicyView, subgoal: np.ndarray) -> dict[str, np.ndarray]:
        """view.obs with the robot's goal features (robot[0:3]) those of `subgoal`."""
        rot = rotation(float(view.robot_state[2])) if self._unicycle else np.eye(2)
        rel = rot @ (np.asarray(subgoal, float) - view.robot_state[:2])
        robot = np.array(view.obs["robot"], np.float32)
        robot[:3] = np.clip([rel[0], rel[1], np.hypot(*rel)], self._low, self._high)
        return {**view.obs, "robot": robot}
