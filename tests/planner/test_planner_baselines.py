"""Baselines behind the MPC's interface."""

from __future__ import annotations

import numpy as np
import pytest
from planner_helpers import PRED, drive, make_config

from planner import PLANNERS, PedPrediction, constant_velocity_prediction, make_planner

GOAL = np.array([8.0, 0.0])


def _crossing_walker(step: int, dt: float) -> PedPrediction:
    """A pedestrian walking up at 0.8 m/s across the robot's path at x = 4, observed over 8 steps."""
    t_now = step * dt
    times = t_now + 0.4 * np.arange(-7, 1)
    hist = np.stack([np.array([[4.0, -3.0 + 0.8 * t]]) for t in times])
    return constant_velocity_prediction(hist, **PRED)


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_every_baseline_reaches_goal_in_empty_space(name):
    planner = make_planner(name, make_config())
    states, results = drive(planner, np.zeros(5), GOAL, lambda *_: None, 35)
    assert np.linalg.norm(states[-1, :2] - GOAL) < 0.5
    assert all(r.control.shape == (2,) for r in results)
    assert planner.stats.counts["calls"] == 35


@pytest.mark.parametrize("name", ["mpc-cv", "mpc", "social-force"])
def test_baselines_avoid_a_crossing_walker(name):
    planner = make_planner(name, make_config())
    dt = planner.config.dt_s
    states, _ = drive(planner, np.zeros(5), GOAL, lambda step, _: _crossing_walker(step, dt), 35)
    walker = np.stack([[4.0, -3.0 + 0.8 * step * dt] for step in range(36)])
    gap = np.linalg.norm(states[:, :2] - walker, axis=1).min()
    assert gap > planner.config.robot.radius_m + 0.3
    assert np.linalg.norm(states[-1, :2] - GOAL) < 0.5


def test_frozen_mpc_uses_current_positions_only():
    planner = make_planner("mpc-none", make_config())
    pred = _crossing_walker(0, 0.4)
    result = planner.plan(np.zeros(5), GOAL, pred)
    assert result.status == "solved"
