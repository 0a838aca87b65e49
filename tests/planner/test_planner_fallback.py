"""Failure handling: every failure falls back (previous plan, then brake) and is counted."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
from planner_helpers import PRED, STEP_S, make_config

from planner import MPCConfig, MPCPlanner, PedPrediction, brake_control, clip_control, frozen_prediction

GOAL = np.array([8.0, 0.0])


class _FakeSolver:
    """Stands in for the nlpsol Function: raises, or returns NaN, as told."""

    def __init__(self, mode: str, n: int) -> None:
        self.mode, self.n = mode, n

    def __call__(self, **_):
        if self.mode == "raise":
            raise RuntimeError("boom")
        return {"x": ca.DM(np.full(self.n, np.nan))}

    def stats(self):
        return {"success": True, "return_status": "Solve_Succeeded", "iter_count": 3}


def _break_solver(planner: MPCPlanner, mode: str) -> None:
    planner.ocp = dataclasses.replace(planner.ocp, solver=_FakeSolver(mode, planner.ocp.layout.n))


def test_solver_failure_replays_previous_plan_then_brakes():
    cfg = make_config(max_plan_reuse_steps=2)
    planner = MPCPlanner(cfg)
    state = np.zeros(5)
    good = planner.plan(state, GOAL, None)
    assert good.status == "solved"
    _break_solver(planner, "raise")
    state = good.states[1]
    kinds = []
    for step in range(1, 5):
        result = planner.plan(state, GOAL, None)
        assert result.status == "solver_error" and "boom" in result.solver_status
        kinds.append(result.fallback)
        if result.fallback == "previous_plan":
            assert np.allclose(result.control, clip_control(state, good.controls[step], cfg.dt_s, cfg.robot))
        else:
            assert np.allclose(result.control, brake_control(state, cfg.dt_s, cfg.robot))
        state = result.states[1]
    assert kinds == ["previous_plan", "previous_plan", "brake", "brake"]
    counts = planner.stats.counts
    assert counts["calls"] == 5 and counts["solved"] == 1 and counts["solver_error"] == 4
    assert counts["fallback_previous_plan"] == 2 and counts["fallback_brake"] == 2


def test_nan_solution_falls_back():
    planner = MPCPlanner(make_config())
    _break_solver(planner, "nan")
    result = planner.plan(np.array([0.0, 0.0, 0.0, 0.8, 0.0]), GOAL, None)
    assert result.status == "nan" and result.fallback == "brake"
    assert np.all(np.isfinite(result.control)) and np.all(np.isfinite(result.states))
    # Braking from 0.8 m/s within the acceleration bound.
    assert np.isclose(result.control[0], 0.8 - planner.config.robot.max_accel_mps2 * planner.config.dt_s)


def test_wall_time_budget_exceeded_counts_as_timeout():
    planner = MPCPlanner(MPCConfig(solver="ipopt", time_budget_s=1e-6))
    pred = frozen_prediction(np.array([[4.0, 0.0]]), **PRED)
    result = planner.plan(np.zeros(5), GOAL, pred)
    assert result.status == "timeout" and result.fallback_used
    assert planner.stats.counts["timeout"] == 1


def test_stats_summary_reports_percentiles_and_fallback_rate():
    planner = MPCPlanner(make_config())
    for _ in range(3):
        planner.plan(np.zeros(5), GOAL, None)
    summary = planner.stats.summary()
    assert summary["calls"] == 3 and summary["fallback_rate"] == 0.0
    assert 0 < summary["p50_ms"] <= summary["p95_ms"] <= summary["max_ms"]


def test_random_scenes_never_raise_and_respect_bounds():
    rng = np.random.default_rng(7)
    planner = MPCPlanner(make_config(max_peds=4, max_groups=2, max_walls=3))
    robot = planner.config.robot
    for _ in range(25):
        n = int(rng.integers(0, 9))
        pose = np.r_[rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi)]
        state = np.r_[pose, rng.uniform(0, 1.2), rng.uniform(-2, 2)]
        positions = rng.uniform(-4, 4, (20, 12, n, 2))
        mask = rng.random(n) < 0.8
        positions[:, :, ~mask] = np.nan
        pred = PedPrediction(positions, np.full(n, 0.3), rng.integers(0, 3, n), mask, step_s=STEP_S)
        walls = rng.uniform(-5, 5, (int(rng.integers(0, 4)), 4))
        result = planner.plan(state, rng.uniform(-6, 6, 2), pred, walls)
        assert np.all(np.isfinite(result.control)) and np.all(np.isfinite(result.states))
        assert -robot.min_speed_mps - 1e-6 <= result.control[0] <= robot.max_speed_mps + 1e-6
        assert abs(result.control[1]) <= robot.max_yaw_rate_radps + 1e-6
        assert abs(result.control[0] - state[3]) <= robot.max_accel_mps2 * planner.config.dt_s + 1e-6
    assert planner.stats.counts["calls"] == 25
