"""Robot models, configs and the package boundary."""

from __future__ import annotations

import subprocess
import sys

import casadi as ca
import numpy as np
import pytest

from planner import (
    MPCConfig,
    RobotConfig,
    brake_control,
    clip_control,
    make_planner,
    robot_dynamics,
    step_robot,
)
from planner.dynamics import step_numpy


def _exact_unicycle(state, control, dt):
    x, y, th = state[:3]
    v, w = control
    if abs(w) < 1e-12:
        return np.array([x + v * dt * np.cos(th), y + v * dt * np.sin(th), th, v, w])
    return np.array([x + v / w * (np.sin(th + w * dt) - np.sin(th)),
                     y - v / w * (np.cos(th + w * dt) - np.cos(th)), th + w * dt, v, w])


@pytest.mark.parametrize("control", [(1.0, 0.0), (0.8, 1.5), (-0.2, -2.0), (0.0, 1.0)])
def test_unicycle_step_matches_exact_arc(control):
    state = np.array([1.0, -2.0, 0.7, 0.3, 0.1])
    got = step_robot(state, control, 0.4)
    assert np.allclose(got, _exact_unicycle(state, control, 0.4), atol=1e-7)


@pytest.mark.parametrize("model", ["unicycle", "holonomic"])
def test_numpy_rollout_copy_matches_the_casadi_function(model):
    rng = np.random.default_rng(3)
    dim = 5 if model == "unicycle" else 4
    for _ in range(20):
        state, control = rng.normal(size=dim), rng.normal(size=2)
        assert np.allclose(step_numpy(state, control, 0.4, model), step_robot(state, control, 0.4, model),
                           atol=1e-9)


def test_dynamics_is_one_casadi_function_for_both_models():
    uni = robot_dynamics("unicycle")
    assert isinstance(uni, ca.Function) and uni.name() == "robot_step"
    assert uni.size1_in(0) == 5 and uni.size1_in(1) == 2
    holo = robot_dynamics("holonomic")
    assert np.allclose(step_robot([1.0, 2.0, 0.0, 0.0], [0.5, -1.0], 0.4, "holonomic"), [1.2, 1.6, 0.5, -1.0])
    assert holo.size1_in(0) == 4


def test_clip_and_brake_respect_bounds():
    robot = RobotConfig()
    state = np.array([0.0, 0.0, 0.0, 0.5, 0.0])
    u = clip_control(state, [5.0, 9.0], 0.4, robot)
    assert np.isclose(u[0], 0.5 + robot.max_accel_mps2 * 0.4)
    assert np.isclose(u[1], robot.max_yaw_accel_radps2 * 0.4)
    assert np.allclose(brake_control(state, 0.4, robot), [0.0, 0.0])
    holo = RobotConfig(model="holonomic")
    u = clip_control(np.array([0.0, 0.0, 1.0, 0.0]), [-1.0, 0.0], 0.4, holo)
    assert np.isclose(np.linalg.norm(u - [1.0, 0.0]), holo.max_accel_mps2 * 0.4)


def test_unknown_names_list_valid_ones():
    with pytest.raises(ValueError, match="unicycle, holonomic"):
        RobotConfig(model="diffdrive")
    with pytest.raises(ValueError, match="ipopt, fatrop"):
        MPCConfig(solver="snopt")
    with pytest.raises(ValueError, match="mpc, mpc-cv, mpc-none, social-force"):
        make_planner("rrt")
    with pytest.raises(ValueError, match="unicycle, holonomic"):
        robot_dynamics("car")


@pytest.mark.parametrize("kwargs", [{"dt_s": 0.0}, {"horizon_steps": 1}, {"max_peds": 0},
                                    {"time_budget_s": -1.0}, {"safety_margin_m": -0.1}])
def test_config_validation(kwargs):
    with pytest.raises(ValueError, match="MPCConfig"):
        MPCConfig(**kwargs)
    with pytest.raises(ValueError, match=r"RobotConfig\.radius_m"):
        RobotConfig(radius_m=0.0)


def test_planner_imports_numpy_and_casadi_only():
    code = ("import sys, planner; bad = [m for m in ('torch', 'pymunk', 'crowdsim', 'predictor', 'envs', "
            "'scipy', 'numba', 'gymnasium') if m in sys.modules]; print(bad); sys.exit(1 if bad else 0)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
