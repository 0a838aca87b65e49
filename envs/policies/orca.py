"""`orca`: ORCA driving the robot, as in the CrowdNav papers' ORCA baseline (vita-epfl/CrowdNav `policy/orca.py`).

Every `OrcaParams.time_step_s` (0.25 s, CrowdNav's step; the nearest whole number of env steps) the robot takes the
ORCA velocity towards its goal (preferred speed: its maximum speed, CrowdNav's v_pref 1 m/s in the classic suite),
treating every pedestrian in the scene as an ORCA agent that shares the avoidance and keeps its current velocity;
it holds that velocity in between. Its ORCA settings are the crowd's (`CrowdNavConfig.orca`: CrowdNav's humans),
radius the robot's. Holonomic robots take the velocity as it is; a unicycle turns towards it (yaw rate to close the
heading error over one ORCA step) at its speed times the cosine of the error, never reversing.
When the pedestrians do not see the robot, the reciprocity it assumes does not hold: that is the invisible
setting where ORCA fails (SARL paper, Table I).
"""

from __future__ import annotations

import math

import numpy as np

from envs.crowds.rvo import load_pyrvo, orca_velocities, pref_velocity
from envs.view import Decision, PolicyView
from planner import PlanStats


class OrcaPolicy:
    """See the module docstring. `params`: the env's `OrcaCrowdConfig` ORCA settings (`envs.crowds.rvo.OrcaParams`)."""

    name = "orca"
    reads_history = False

    def __init__(self, params: object) -> None:
        load_pyrvo()  # a missing package fails when the policy is built, before any episode
        self.params = params
        self.stats = PlanStats()
        self._velocity = np.zeros(2)
        self._age = 0

    def reset(self, seed: int | None = None) -> None:
        self._velocity, self._age = np.zeros(2), 0

    def act(self, view: PolicyView) -> Decision:
        every = max(1, round(self.params.time_step_s / view.dt_s))
        if self._age % every == 0:
            self._velocity = self._orca(view)
        self._age += 1
        if view.robot.model == "holonomic":
            return Decision(control=self._velocity.copy())
        return Decision(control=self._unicycle(view.robot_state, self._velocity))

    def _orca(self, view: PolicyView) -> np.ndarray:
        """The robot's ORCA velocity (2,) m/s now."""
        s, r, p = view.robot_state, view.robot, view.pedestrians
        if r.model == "holonomic":
            vel = s[2:4]
        else:
            vel = s[3] * np.array([math.cos(s[2]), math.sin(s[2])])
        pos = np.vstack([s[None, :2], p.pos])
        vels = np.vstack([vel[None], p.vel])
        pref = np.zeros_like(pos)  # the others' goals are unknown (CrowdNav): only the robot's row is used
        pref[0] = pref_velocity(s[None, :2], view.goal[None], np.array([r.max_speed_mps]))[0]
        radius = np.concatenate([[r.radius_m], p.radius])
        speed = np.concatenate([[r.max_speed_mps], np.full(len(p.pos), r.max_speed_mps)])
        return orca_velocities(pos, vels, pref, radius, speed, self.params)[0]

    def _unicycle(self, state: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """(v m/s, omega rad/s) towards `velocity` (2,) from the unicycle state (x, y, heading, v, omega)."""
        speed = float(np.linalg.norm(velocity))
        if speed < 1e-9:
            return np.zeros(2)
        err = math.atan2(velocity[1], velocity[0]) - float(state[2])
        err = (err + math.pi) % (2.0 * math.pi) - math.pi
        return np.array([max(0.0, speed * math.cos(err)), err / self.params.time_step_s])
