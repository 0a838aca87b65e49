"""`SceneFrame`: everything the renderers and the rerun observer draw at one env step.

The env builds one with `CrowdNavEnv.frame()`; policies attach their plan and predictions through
`CrowdNavEnv.annotate(...)`, so the drawing code never reaches into the simulator or the planner.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class SceneFrame:
    """One instant of an episode, world frame (x right, y up), metres and seconds.

    Attributes:
        step: env step index (0 after reset).
        time_s: simulated time since reset, s.
        robot_state: (state_dim,) robot state; (x, y, heading, v, omega) for the unicycle,
            (x, y, vx, vy) for the holonomic model.
        robot_radius_m: robot body radius, m.
        goal: (2,) robot goal, m.
        ped_pos: (N, 2) positions of the pedestrians in the scene, m.
        ped_vel: (N, 2) their velocities, m/s.
        ped_radius: (N,) body radii, m.
        group_id: (N,) ground-truth group ids, 0..G-1 (a pedestrian alone is a group of one).
        ped_id: (N,) identities, stable over the episode.
        walls: (W, 2, 2) wall segments, m.
        bounds: (x_min, y_min, x_max, y_max) of the scene, m.
        plan: (H + 1, 2) the robot's planned positions (row 0 = now), or None.
        predictions: (K, T, N, 2) predicted pedestrian positions at +0.4 s ... (rows match ped_pos), or None.
        predicted_group_id: (N,) the predictor's group ids, or None.
        scalars: named per-step numbers (reward terms, distances) to plot over time.
        options: (O, H + 1, 2) the planner's other passing options (planned positions), or None.
    """

    step: int
    time_s: float
    robot_state: np.ndarray
    robot_radius_m: float
    goal: np.ndarray
    ped_pos: np.ndarray
    ped_vel: np.ndarray
    ped_radius: np.ndarray
    group_id: np.ndarray
    ped_id: np.ndarray
    walls: np.ndarray
    bounds: tuple[float, float, float, float]
    plan: np.ndarray | None = None
    predictions: np.ndarray | None = None
    predicted_group_id: np.ndarray | None = None
    scalars: dict[str, float] = field(default_factory=dict)
    options: np.ndarray | None = None

    @property
    def robot_pos(self) -> np.ndarray:
        """(2,) robot position, m."""
        return self.robot_state[:2]

    @property
    def n_peds(self) -> int:
        return len(self.ped_pos)
