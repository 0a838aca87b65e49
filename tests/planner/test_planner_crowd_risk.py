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


def _stage_slack(cfg: MPCConfig, pred: PedPrediction, offset: np.ndarray, stage: int) -> float:
    """The pedestrians' smallest feasible slack (m) at `stage` (1..H) of a plan whose knots all sit at `offset` (2,) m
    from the one pedestrian's predicted position at that knot (the OCP's own slack function)."""
    from planner.ocp import pack_params

    planner = MPCPlanner(cfg)
    ocp, layout = planner.ocp, planner.ocp.layout
    scene = build_scene(np.zeros(5), pred, None, cfg)
    p = pack_params(ocp.sizes, np.zeros(5), GOAL, scene)
    states = np.zeros((cfg.horizon_steps + 1, 5))
    states[1:, :2] = scene.ped_pos[:, 0, 0] + offset
    w = np.zeros(layout.n)
    w[layout.z] = states
    return float(ocp.slack_fn(w, p).full().reshape(layout.s.shape)[stage, 0])


def test_lateral_inflation_makes_a_walkers_clearance_an_ellipse():
    """With lateral_inflation 0.5 a walker's 4 s clearance (inflation 0.5 m) is 0.9 + 0.5 m ahead of and behind them
    and 0.9 + 0.25 m beside them; at 1.0 a disc of 1.4 m, as before."""
    walker = _scene(0.0, [([3.0, 0.0], [-1.2, 0.0])])  # walking -x, constant velocity (one sample: no spread)
    base = R_SUM + 0.3
    ellipse = MPCConfig(safety_margin_m=0.3, clearance_growth_mps=0.2, max_clearance_inflation_m=0.5,
                        lateral_inflation=0.5, max_groups=0, max_walls=0, time_budget_s=10.0)
    disc = replace(ellipse, lateral_inflation=1.0)
    h = ellipse.horizon_steps
    beside, ahead = np.array([0.0, 1.0]), np.array([1.0, 0.0])
    assert _stage_slack(ellipse, walker, (base + 0.25 - 0.05) * beside, h) == pytest.approx(0.05, abs=2e-3)
    assert _stage_slack(ellipse, walker, (base + 0.25 + 0.02) * beside, h) == 0.0
    assert _stage_slack(disc, walker, (base + 0.25 + 0.02) * beside, h) == pytest.approx(0.23, abs=2e-3)
    # along the walk the margin is measured in the across axis's metres: zero at base + 0.5, positive inside
    assert _stage_slack(ellipse, walker, (base + 0.5 + 0.02) * ahead, h) == 0.0
    assert _stage_slack(ellipse, walker, -(base + 0.5 + 0.02) * ahead, h) == 0.0
    assert _stage_slack(ellipse, walker, (base + 0.5 - 0.1) * ahead, h) > 0.05
    assert _stage_slack(disc, walker, (base + 0.5 - 0.1) * ahead, h) == pytest.approx(0.1, abs=2e-3)


def test_a_standing_person_keeps_a_round_clearance_and_the_default_adds_no_parameter():
    cfg = replace(CROWD_MPC, lateral_inflation=0.5)
    still = build_scene(np.zeros(5), _scene(0.0, [([3.0, 0.0], [0.0, 0.0])]), None, cfg)
    assert np.all(still.ped_axis == 0.0)
    assert np.allclose(still.ped_clear[:, 0], build_scene(np.zeros(5), _scene(0.0, [([3.0, 0.0], [0.0, 0.0])]),
                                                          None, CROWD_MPC).ped_clear[:, 0])
    assert build_scene(np.zeros(5), _scene(0.0, [([3.0, 0.0], [1.0, 0.0])]), None, CROWD_MPC).ped_axis is None
    assert not MPCPlanner(make_config()).ocp.sizes.aniso


@pytest.mark.parametrize("share", [0.0, 1.5, float("nan")])
def test_lateral_inflation_outside_its_range_is_refused(share):
    with pytest.raises(ValueError, match="lateral_inflation"):
        MPCConfig(lateral_inflation=share)
