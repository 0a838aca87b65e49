"""Robot models: discrete dynamics as one ``casadi.Function`` for the MPC, and its scalar numpy twin for the env.

Unicycle: state (x m, y m, heading rad, v m/s, omega rad/s), control (v m/s, omega rad/s).
The pose is integrated exactly along the arc driven by the commanded (v, omega) for dt seconds;
the velocity part of the next state is the commanded control.

Holonomic: state (x m, y m, vx m/s, vy m/s), control (vx m/s, vy m/s); the position moves by
control * dt, the velocity part of the next state is the control.

Bounds are not applied by the dynamics: clip a command with :func:`clip_control` first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import casadi as ca
import numpy as np

from planner.config import ROBOT_MODELS, RobotConfig


@dataclass(frozen=True)
class ModelDims:
    """Sizes of a robot model: state and control dimensions, and where the velocity sits in the state."""

    state_dim: int
    control_dim: int
    vel_slice: slice


MODEL_DIMS: dict[str, ModelDims] = {
    "unicycle": ModelDims(state_dim=5, control_dim=2, vel_slice=slice(3, 5)),
    "holonomic": ModelDims(state_dim=4, control_dim=2, vel_slice=slice(2, 4)),
}


def model_dims(model: str) -> ModelDims:
    """Return the dimensions of ``model``; raise ValueError listing the valid names if unknown."""
    if model not in MODEL_DIMS:
        raise ValueError(f"unknown robot model {model!r}; valid names: {', '.join(ROBOT_MODELS)}")
    return MODEL_DIMS[model]


def _sinc(a: ca.SX) -> ca.SX:
    """sin(a)/a by its Taylor series up to a⁸ (relative error < 3e-8 for |a| <= 1), smooth at 0."""
    a2 = a * a
    return 1 - a2 / 6 * (1 - a2 / 20 * (1 - a2 / 42 * (1 - a2 / 72)))


def _unicycle_step(x: ca.SX, u: ca.SX, dt: ca.SX) -> ca.SX:
    half = u[1] * dt / 2
    dist = u[0] * dt * _sinc(half)
    heading = x[2] + half
    return ca.vertcat(x[0] + dist * ca.cos(heading), x[1] + dist * ca.sin(heading),
                      x[2] + u[1] * dt, u[0], u[1])


def _holonomic_step(x: ca.SX, u: ca.SX, dt: ca.SX) -> ca.SX:
    return ca.vertcat(x[0] + u[0] * dt, x[1] + u[1] * dt, u[0], u[1])


_STEPS = {"unicycle": _unicycle_step, "holonomic": _holonomic_step}


@cache
def robot_dynamics(model: str = "unicycle") -> ca.Function:
    """The discrete dynamics ``robot_step(state, control, dt) -> next_state`` of ``model``.

    Shapes: state (state_dim,), control (2,), dt scalar in s. Valid for |omega * dt| <= 2 rad.
    """
    dims = model_dims(model)
    x = ca.SX.sym("state", dims.state_dim)
    u = ca.SX.sym("control", dims.control_dim)
    dt = ca.SX.sym("dt")
    return ca.Function("robot_step", [x, u, dt], [_STEPS[model](x, u, dt)],
                       ["state", "control", "dt"], ["next_state"])


def step_robot(state: np.ndarray, control: np.ndarray, dt: float, model: str = "unicycle") -> np.ndarray:
    """Next state (state_dim,) float64 after dt seconds: :func:`robot_dynamics` evaluated with Python floats.

    The same operations in the same order as the CasADi graph (its Taylor ``_sinc`` included, libm cos/sin),
    so the result equals ``robot_dynamics(model)(state, control, dt)`` (bit for bit in the tests); ~30x
    cheaper than a ``casadi.Function`` call per env step. state (state_dim,), control (2,), dt s.
    """
    x, u = np.asarray(state, float), np.asarray(control, float)
    dims = model_dims(model)
    if x.shape != (dims.state_dim,) or u.shape != (dims.control_dim,):
        raise ValueError(f"{model}: state must have shape ({dims.state_dim},) and control (2,), "
                         f"got {x.shape} and {u.shape}")
    dt = float(dt)
    u0, u1 = float(u[0]), float(u[1])
    if dims.state_dim == 4:
        return np.array([float(x[0]) + u0 * dt, float(x[1]) + u1 * dt, u0, u1])
    half = u1 * dt / 2
    a2 = half * half
    sinc = 1 - a2 / 6 * (1 - a2 / 20 * (1 - a2 / 42 * (1 - a2 / 72)))
    dist = u0 * dt * sinc
    heading = float(x[2]) + half
    return np.array([float(x[0]) + dist * math.cos(heading), float(x[1]) + dist * math.sin(heading),
                     float(x[2]) + u1 * dt, u0, u1])


def step_robot_casadi(state: np.ndarray, control: np.ndarray, dt: float, model: str = "unicycle") -> np.ndarray:
    """numpy wrapper of :func:`robot_dynamics` (one ``casadi.Function`` call): next state (state_dim,) float64."""
    out = robot_dynamics(model)(np.asarray(state, float), np.asarray(control, float), float(dt))
    return out.full().reshape(-1)


def step_numpy(state: np.ndarray, control: np.ndarray, dt: float, model: str = "unicycle") -> np.ndarray:
    """Batched numpy copy of :func:`robot_dynamics` (same equations, exact arc for the unicycle):
    state (..., state_dim), control (..., 2) -> next state (..., state_dim). Used for cheap rollouts
    inside the planner; the env should step with :func:`step_robot`."""
    x, u = np.asarray(state, float), np.asarray(control, float)
    if model_dims(model).state_dim == 4:
        return np.concatenate([x[..., :2] + u * dt, u], axis=-1)
    half = u[..., 1] * dt / 2
    dist = u[..., 0] * dt * np.sinc(half / np.pi)
    heading = x[..., 2] + half
    pose = np.stack([x[..., 0] + dist * np.cos(heading), x[..., 1] + dist * np.sin(heading),
                     x[..., 2] + u[..., 1] * dt], axis=-1)
    return np.concatenate([pose, u], axis=-1)


def rollout(state: np.ndarray, controls: np.ndarray, dt: float, model: str = "unicycle") -> np.ndarray:
    """States (n + 1, state_dim) from applying ``controls`` (n, 2) in turn, dt s each (numpy dynamics)."""
    states = [np.asarray(state, float)]
    for u in np.asarray(controls, float):
        states.append(step_numpy(states[-1], u, dt, model))
    return np.stack(states)


def _clip_norm(vec: np.ndarray, limit: float) -> np.ndarray:
    norm = np.linalg.norm(vec, axis=-1, keepdims=True)
    return vec * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


def _clip1(x: float, lo: float, hi: float) -> float:
    """``np.clip`` of one float, ties resolved as numpy does (the bound wins; matters for the sign of zero)."""
    t = x if x > lo else lo
    return t if t < hi else hi


def _clip_norm_one(x: float, y: float, limit: float) -> tuple[float, float]:
    """:func:`_clip_norm` of one vector (x, y), with the same float operations and tie rules."""
    norm = math.sqrt(x * x + y * y)
    q = limit / (norm if norm > 1e-12 else 1e-12)
    scale = 1.0 if 1.0 < q else q
    return x * scale, y * scale


def _clip_one(v0: float, v1: float, u0: float, u1: float, dt: float, robot: RobotConfig) -> tuple[float, float]:
    """:func:`clip_control` of one finite command (u0, u1) from velocity (v0, v1) on Python floats, bit-identical
    to the array code."""
    if robot.model == "unicycle":
        a0, a1 = robot.max_accel_mps2 * dt, robot.max_yaw_accel_radps2 * dt
        w0, w1 = v0 + _clip1(u0 - v0, -a0, a0), v1 + _clip1(u1 - v1, -a1, a1)
        return (_clip1(w0, -robot.min_speed_mps, robot.max_speed_mps),
                _clip1(w1, -robot.max_yaw_rate_radps, robot.max_yaw_rate_radps))
    d0, d1 = _clip_norm_one(u0 - v0, u1 - v1, robot.max_accel_mps2 * dt)
    return _clip_norm_one(v0 + d0, v1 + d1, robot.max_speed_mps)


def clip_control(state: np.ndarray, control: np.ndarray, dt: float, robot: RobotConfig) -> np.ndarray:
    """Clip ``control`` (..., 2) to the velocity bounds and to the accelerations reachable in dt s
    from the velocity part of ``state`` (..., state_dim). Returns a new float64 array."""
    dims = model_dims(robot.model)
    vel = np.asarray(state, float)[..., dims.vel_slice]
    u = np.asarray(control, float)
    if u.shape == (2,) and vel.shape == (2,):  # one command (the env's step): the same operations on floats
        f = (float(vel[0]), float(vel[1]), float(u[0]), float(u[1]))
        if all(map(math.isfinite, f)):
            return np.array(_clip_one(*f, float(dt), robot))
    if robot.model == "unicycle":
        accel = np.array([robot.max_accel_mps2, robot.max_yaw_accel_radps2]) * dt
        u = vel + np.clip(u - vel, -accel, accel)
        lo = np.array([-robot.min_speed_mps, -robot.max_yaw_rate_radps])
        hi = np.array([robot.max_speed_mps, robot.max_yaw_rate_radps])
        return np.clip(u, lo, hi)
    u = vel + _clip_norm(u - vel, robot.max_accel_mps2 * dt)
    return _clip_norm(u, robot.max_speed_mps)


def brake_control(state: np.ndarray, dt: float, robot: RobotConfig) -> np.ndarray:
    """The control (..., 2) that slows the robot towards rest as fast as the acceleration bounds allow."""
    state = np.asarray(state, float)
    return clip_control(state, np.zeros((*state.shape[:-1], model_dims(robot.model).control_dim)), dt, robot)
