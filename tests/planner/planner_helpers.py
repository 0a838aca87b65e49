"""Shared helpers for the planner tests (a plain module, imported by name)."""

from __future__ import annotations

import numpy as np

from planner import MPCConfig, PlanResult, step_robot

# The prediction grid the tests use (the project's ETH/UCY protocol; the planner takes it as a parameter).
STEP_S = 0.4
PRED = {"n_steps": 12, "step_s": STEP_S}
# Behaviour tests must not depend on machine load: timing is benchmarked (bench/), not tested here.
TEST_BUDGET_S = 10.0


def make_config(**kwargs) -> MPCConfig:
    """MPCConfig with a wall-time budget generous enough for a loaded CI machine."""
    return MPCConfig(**{"time_budget_s": TEST_BUDGET_S, **kwargs})


def drive(planner, state, goal, prediction_fn, steps: int, obstacles=None):
    """Closed loop: plan, apply the first control for dt, repeat. Returns states (steps+1, dim) and results.

    ``prediction_fn(step, robot_state)`` gives the PedPrediction of a step (or None).
    """
    dt, model = planner.config.dt_s, planner.config.robot.model
    states, results = [np.asarray(state, float)], []
    for step in range(steps):
        result: PlanResult = planner.plan(states[-1], goal, prediction_fn(step, states[-1]), obstacles)
        results.append(result)
        states.append(step_robot(states[-1], result.control, dt, model))
    return np.array(states), results
