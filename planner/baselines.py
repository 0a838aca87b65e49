"""Baselines behind the MPC's interface ``plan(robot_state, goal, prediction, obstacles) -> PlanResult``.

* ``mpc-cv``: the MPC fed constant-velocity predictions built from ``prediction.history``;
* ``mpc-none``: the MPC with pedestrians frozen at their current positions;
* ``social_force``: a reactive social-force controller (no optimisation, no prediction).

All take the same :class:`~planner.prediction.PedPrediction` as the MPC and ignore what they do not use.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planner.config import MPCConfig
from planner.dynamics import clip_control, model_dims, rollout
from planner.mpc import MPCPlanner, check_inputs
from planner.prediction import (
    PedPrediction,
    constant_velocity_prediction,
    current_positions,
    frozen_prediction,
)
from planner.result import PlanResult, PlanStats
from planner.scene import segment_projection


class _PredictionSwapMPC:
    """The MPC fed a replacement for the predictor's samples; subclasses define `_replace`."""

    def __init__(self, config: MPCConfig | None = None) -> None:
        self.mpc = MPCPlanner(config)
        self.config = self.mpc.config

    @property
    def stats(self) -> PlanStats:
        return self.mpc.stats

    def reset(self) -> None:
        self.mpc.reset()

    def _replace(self, prediction: PedPrediction) -> PedPrediction:
        raise NotImplementedError

    def plan(self, robot_state, goal, prediction: PedPrediction | None = None, obstacles=None) -> PlanResult:
        """As :meth:`MPCPlanner.plan`, with the prediction replaced first. An empty scene (N = 0 or no real
        pedestrian) is passed through unchanged; bad input raises ValueError before any work."""
        if prediction is not None:
            check_inputs(robot_state, goal, prediction, obstacles, self.mpc.dims.state_dim,
                         self.mpc.config.dt_s)
            if np.asarray(prediction.mask, bool).any():
                prediction = self._replace(prediction)
        return self.mpc.plan(robot_state, goal, prediction, obstacles)


class ConstantVelocityMPC(_PredictionSwapMPC):
    """The MPC with constant-velocity predictions (K=1) from ``prediction.history`` (rows
    ``prediction.step_s`` apart; a single row, or a pedestrian padded with its first position, has zero
    velocity); the prediction's own samples are ignored. Without a history the pedestrians are frozen at
    their current positions and the call is counted in ``stats.counts["fallback_no_history"]``."""

    def _replace(self, prediction: PedPrediction) -> PedPrediction:
        if prediction.history is None:
            self.mpc.stats.counts["fallback_no_history"] += 1
            return _frozen(prediction)
        return constant_velocity_prediction(
            prediction.history, prediction.radii, prediction.group_ids, prediction.mask,
            n_steps=np.shape(prediction.positions)[1], step_s=prediction.step_s)


class FrozenMPC(_PredictionSwapMPC):
    """The MPC with every pedestrian frozen at its current position (no prediction)."""

    def _replace(self, prediction: PedPrediction) -> PedPrediction:
        return _frozen(prediction)


def _frozen(prediction: PedPrediction) -> PedPrediction:
    """``prediction`` with every pedestrian frozen at its current position (same T, step and attributes)."""
    return frozen_prediction(
        current_positions(prediction), prediction.radii, prediction.group_ids, prediction.mask,
        n_steps=np.shape(prediction.positions)[1], step_s=prediction.step_s)


@dataclass(frozen=True)
class ReactiveForceParams:
    """Reactive social-force controller parameters (Helbing-style exponential repulsion)."""

    desired_speed_mps: float = 1.0
    relax_time_s: float = 0.5
    slow_radius_m: float = 1.0  # the desired speed falls linearly inside this distance to the goal
    ped_strength_mps2: float = 3.0
    ped_range_m: float = 0.4
    wall_strength_mps2: float = 3.0
    wall_range_m: float = 0.2
    heading_gain: float = 2.0  # yaw rate (rad/s) per rad of heading error, unicycle only

    def __post_init__(self) -> None:
        for name in ("desired_speed_mps", "relax_time_s", "slow_radius_m", "ped_range_m", "wall_range_m",
                     "heading_gain"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ReactiveForceParams.{name} must be > 0, got {getattr(self, name)!r}")


@dataclass
class SocialForcePlanner:
    """Reactive controller: goal attraction plus exponential repulsion from pedestrians' current
    positions and from walls, turned into a bounded control. Uses the MPC config's robot, dt_s and
    horizon_steps; the returned plan is the control held over the horizon."""

    config: MPCConfig = field(default_factory=MPCConfig)
    params: ReactiveForceParams = field(default_factory=ReactiveForceParams)
    stats: PlanStats = field(default_factory=PlanStats)

    def reset(self) -> None:
        """Stateless; present for interface parity."""

    def plan(self, robot_state, goal, prediction: PedPrediction | None = None, obstacles=None) -> PlanResult:
        dims = model_dims(self.config.robot.model)
        state, goal, prediction, obstacles = check_inputs(robot_state, goal, prediction, obstacles,
                                                          dims.state_dim, self.config.dt_s)
        vel = self._velocity(state)
        force = self._goal_force(state[:2], goal, vel) + self._ped_force(state[:2], prediction)
        force = force + self._wall_force(state[:2], obstacles)
        control = self._to_control(state, vel + force * self.config.dt_s)
        controls = np.tile(control, (self.config.horizon_steps, 1))
        states = rollout(state, controls, self.config.dt_s, self.config.robot.model)
        result = PlanResult(control, states, controls, "reactive")
        self.stats.record(result)
        return result

    def _velocity(self, state: np.ndarray) -> np.ndarray:
        if self.config.robot.model == "unicycle":
            return state[3] * np.array([np.cos(state[2]), np.sin(state[2])])
        return state[2:4].copy()

    def _goal_force(self, pos: np.ndarray, goal: np.ndarray, vel: np.ndarray) -> np.ndarray:
        prm = self.params
        delta = goal - pos
        dist = float(np.linalg.norm(delta))
        speed = prm.desired_speed_mps * min(1.0, dist / prm.slow_radius_m)
        desired = delta / dist * speed if dist > 1e-9 else np.zeros(2)
        return (desired - vel) / prm.relax_time_s

    def _ped_force(self, pos: np.ndarray, pred: PedPrediction) -> np.ndarray:
        mask = np.asarray(pred.mask, bool)
        if not mask.any():
            return np.zeros(2)
        diff = pos - current_positions(pred)[mask]
        dist = np.maximum(np.linalg.norm(diff, axis=1), 1e-6)
        reach = self.config.robot.radius_m + np.asarray(pred.radii, float)[mask]
        mag = self.params.ped_strength_mps2 * np.exp((reach - dist) / self.params.ped_range_m)
        return (mag[:, None] * diff / dist[:, None]).sum(axis=0)

    def _wall_force(self, pos: np.ndarray, obstacles: np.ndarray | None) -> np.ndarray:
        if obstacles is None or len(obstacles) == 0:
            return np.zeros(2)
        _, t, ab = segment_projection(pos, obstacles)
        diff = pos - (obstacles[:, :2] + t[:, None] * ab)
        dist = np.maximum(np.linalg.norm(diff, axis=1), 1e-6)
        mag = self.params.wall_strength_mps2 * np.exp((self.config.robot.radius_m - dist)
                                                      / self.params.wall_range_m)
        return (mag[:, None] * diff / dist[:, None]).sum(axis=0)

    def _to_control(self, state: np.ndarray, want_vel: np.ndarray) -> np.ndarray:
        rc, dt = self.config.robot, self.config.dt_s
        if rc.model == "holonomic":
            return clip_control(state, want_vel, dt, rc)
        speed = float(np.linalg.norm(want_vel))
        if speed < 1e-9:
            return clip_control(state, np.zeros(2), dt, rc)
        err = (np.arctan2(want_vel[1], want_vel[0]) - state[2] + np.pi) % (2 * np.pi) - np.pi
        return clip_control(state, np.array([speed * max(np.cos(err), 0.0), self.params.heading_gain * err]),
                            dt, rc)


PLANNERS = {
    "mpc": MPCPlanner,
    "mpc-cv": ConstantVelocityMPC,
    "mpc-none": FrozenMPC,
    "social-force": SocialForcePlanner,
}


def make_planner(name: str, config: MPCConfig | None = None):
    """Build a planner by name; raise ValueError listing the valid names if unknown. The names are the env's policy
    names for the same planners (`envs.policies` builds its planner policies from this registry)."""
    if name not in PLANNERS:
        raise ValueError(f"unknown planner {name!r}; valid names: {', '.join(PLANNERS)}")
    return PLANNERS[name](config) if config is not None else PLANNERS[name]()
