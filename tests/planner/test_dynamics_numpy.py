"""The env's numpy robot step and single-command clip agree with the CasADi dynamics and the array code."""

from __future__ import annotations

import numpy as np
import pytest

from planner import RobotConfig, clip_control, step_robot
from planner.dynamics import model_dims, robot_dynamics, step_robot_casadi


@pytest.mark.parametrize("model", ["unicycle", "holonomic"])
def test_step_robot_matches_casadi(model: str) -> None:
    rng = np.random.default_rng(0)
    nz = model_dims(model).state_dim
    for _ in range(2000):
        x, u = rng.normal(0.0, 5.0, nz), rng.uniform(-3.0, 3.0, 2)
        dt = float(rng.choice([0.1, 0.05, 0.4, rng.uniform(0.01, 0.5)]))
        fast = step_robot(x, u, dt, model)
        ref = np.asarray(robot_dynamics(model)(x, u, dt)).reshape(-1)
        assert fast.shape == (nz,) and fast.dtype == np.float64
        np.testing.assert_allclose(fast, ref, rtol=0.0, atol=1e-12)
        assert np.array_equal(fast, step_robot_casadi(x, u, dt, model))  # bit for bit in practice


def test_step_robot_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError):
        step_robot(np.zeros(4), np.zeros(2), 0.1, "unicycle")


@pytest.mark.parametrize("model", ["unicycle", "holonomic"])
def test_clip_control_single_command_matches_array_path(model: str) -> None:
    """One (2,) command takes a float fast path; a (1, 2) batch takes the array path: same bits."""
    rng = np.random.default_rng(1)
    nz = model_dims(model).state_dim
    for robot in (RobotConfig(model=model), RobotConfig(model=model, min_speed_mps=0.3)):
        specials = [0.0, -0.0, robot.max_speed_mps, -robot.min_speed_mps, 5.0]
        for _ in range(2000):
            x, u = rng.normal(0.0, 1.0, nz), rng.uniform(-2.0, 2.0, 2)
            if rng.random() < 0.3:
                x[model_dims(model).vel_slice] = rng.choice(specials, 2)
            if rng.random() < 0.3:
                u = rng.choice(specials, 2)
            fast, ref = clip_control(x, u, 0.1, robot), clip_control(x[None], u[None], 0.1, robot)[0]
            assert np.array_equal(fast, ref) and np.array_equal(np.signbit(fast), np.signbit(ref))
