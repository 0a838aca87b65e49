"""Crowd-risk options of the MPC (planner/risk.py): clearance inflation; the nearest pedestrians constrained."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from planner_helpers import PRED, STEP_S, make_config

from planner import CROWD_MPC, MPCConfig, MPCPlanner, PedPrediction, constant_velocity_prediction, step_robot
from planner.scene import build_scene

GOAL = np.array([10.0, 0.0])
R_SUM = 0.3 + 0.3  # robot radius + pedestrian radius (defaults), m


def _walker(start: np.ndarray, vel: np.ndarray, t_now: float) -> np.ndarray:
    """History (8, 1, 2) of a pedestrian walking at vel (2,) m/s through start at t=0, observed until t_now."""
    times = t_now + 0.4 * np.arange(-7, 1)
    return (start + times[:, None] * vel)[:, None, :]


def _scene(t_now: float, walkers: list[tuple[np.ndarray, np.ndarray]]) -> PedPrediction:
    hist = np.concatenate([_walker(np.asarray(p, float), np.asarray(v, float), t_now) for p, v in walkers], axis=1)
    return constant_velocity_prediction(hist, **PRED)


@pytest.mark.parametrize("bad", [{"clearance_growth_mps": -0.1}, {"spread_inflation": float("nan")}])
def test_invalid_crowd_options_raise(bad):
    with pytest.raises(ValueError):
        MPCConfig(**bad)


def test_defaults_keep_the_plain_mpc():
    cfg = MPCConfig()
    scene = build_scene(np.array([0, 0, 0, 1.2, 0]), _scene(0.0, [([2.0, 0.5], [0.0, 0.0])]), None, cfg)
    assert np.allclose(scene.ped_clear[:, 0], R_SUM + cfg.safety_margin_m)  # no growth with time


def test_clearance_grows_with_time_and_spread_up_to_the_cap():
    cfg = MPCConfig(clearance_growth_mps=0.1, spread_inflation=1.0, max_clearance_inflation_m=0.45)
    base = R_SUM + cfg.safety_margin_m
    still = build_scene(np.zeros(2), _scene(0.0, [([3.0, 0.0], [0.0, 0.0])]), None, cfg)
    assert np.allclose(still.ped_clear[:, 0] - base, np.minimum(0.1 * 0.4 * np.arange(1, 11), 0.45))
    # Two samples 1 m apart from 0.4 s on: spread 0.5 m, so the clearance is at the cap throughout.
    pos = np.full((2, 12, 1, 2), [3.0, 0.0])
    pos[1, :, 0, 1] += 1.0
    wide = PedPrediction(pos, np.full(1, 0.3), np.zeros(1, int), np.ones(1, bool), current=np.array([[3.0, 0.5]]),
                         step_s=STEP_S)
    assert np.allclose(build_scene(np.zeros(2), wide, None, cfg).ped_clear[:, 0], base + 0.45)


def _closed_loop(cfg: MPCConfig, walkers, steps: int = 25) -> tuple[float, float]:
    """Smallest centre distance (m) from the robot, starting at 0.8 m/s towards +x, to the walkers, and the
    largest sideways offset |y| (m) it took."""
    planner, state, gap, side = MPCPlanner(cfg), np.array([0.0, 0.0, 0.0, 0.8, 0.0]), np.inf, 0.0
    for step in range(steps):
        t = step * cfg.dt_s
        result = planner.plan(state, GOAL, _scene(t, walkers))
        state = step_robot(state, result.control, cfg.dt_s, cfg.robot.model)
        peds = np.array([np.asarray(p) + (t + cfg.dt_s) * np.asarray(v) for p, v in walkers])
        gap = min(gap, float(np.linalg.norm(peds - state[:2], axis=1).min()))
        side = max(side, abs(float(state[1])))
    return gap, side


@pytest.mark.slow
def test_robot_steps_aside_for_a_pedestrian_from_behind():
    """A fast walker (2 m/s) comes up behind the robot (0.8 m/s) on its line, bystanders stand in a row 1.3 m
    to its left and max_peds = 2: the robot leaves the walker's line in time and is never touched."""
    walkers = [([-3.0, 0.0], [2.0, 0.0])] + [([x, 1.3], [0.0, 0.0]) for x in range(-1, 6)]
    cfg = replace(CROWD_MPC, max_peds=2, time_budget_s=make_config().time_budget_s)
    gap, side = _closed_loop(cfg, walkers)
    assert gap > R_SUM
    assert side > R_SUM  # stepped out of the walker's way rather than trying to outrun it
