"""Every planner handles degenerate but valid scenes without raising, and still rejects bad input."""

from __future__ import annotations

import numpy as np
import pytest
from planner_helpers import PRED, STEP_S, make_config

from planner import PLANNERS, PedPrediction, constant_velocity_prediction, empty_prediction, make_planner

GOAL = np.array([8.0, 0.0])
ROBOT = np.zeros(5)


def _empty_with_history() -> PedPrediction:
    return PedPrediction(np.zeros((1, 12, 0, 2)), np.zeros(0), np.zeros(0, int), np.zeros(0, bool),
                         current=np.zeros((0, 2)), history=np.zeros((8, 0, 2)), step_s=STEP_S)


def _padding_only() -> PedPrediction:
    """One pedestrian row that is padding (mask False) full of NaN: an empty scene in disguise."""
    nan = np.full((1, 12, 1, 2), np.nan)
    return PedPrediction(nan, np.full(1, np.nan), np.zeros(1, int), np.zeros(1, bool),
                         history=np.full((8, 1, 2), np.nan), step_s=STEP_S)


EMPTY_SCENES = {
    "none": lambda: None,
    "empty_prediction": lambda: empty_prediction(**PRED),
    "empty_with_history": _empty_with_history,
    "padding_only": _padding_only,
}


@pytest.mark.parametrize("scene", sorted(EMPTY_SCENES))
@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_plan_never_raises_on_an_empty_scene(name, scene):
    planner = make_planner(name, make_config())
    result = planner.plan(ROBOT, GOAL, EMPTY_SCENES[scene]())
    assert result.control.shape == (2,)
    assert np.all(np.isfinite(result.control))
    assert result.control[0] > 0.0  # heads off towards the goal
    assert not any(key.startswith("fallback_") for key in planner.stats.counts)


@pytest.mark.parametrize("rows", [1, 8])
@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_pedestrian_seen_for_one_tick_is_standing_still(name, rows):
    """A pedestrian just appeared: its history is one row, or padded backwards with that row."""
    hist = np.tile(np.array([[[4.0, 0.2]]]), (rows, 1, 1))
    pred = PedPrediction(np.full((1, 12, 1, 2), [4.0, 0.2]), np.full(1, 0.3), np.zeros(1, int),
                         np.ones(1, bool), current=hist[-1], history=hist, step_s=STEP_S)
    planner = make_planner(name, make_config())
    result = planner.plan(ROBOT, GOAL, pred)
    assert np.all(np.isfinite(result.control))
    assert not any(key.startswith("fallback_") for key in planner.stats.counts)


def test_constant_velocity_of_a_one_row_history_is_zero():
    pred = constant_velocity_prediction(np.array([[[4.0, 0.2]]]), n_steps=5, step_s=STEP_S)
    assert np.allclose(pred.positions, [4.0, 0.2])


def test_cv_mpc_without_history_freezes_pedestrians_and_counts_the_fallback():
    pred = PedPrediction(np.full((1, 12, 1, 2), [3.0, 0.0]), np.full(1, 0.3), np.zeros(1, int),
                         np.ones(1, bool), current=np.array([[3.0, 0.0]]), step_s=STEP_S)
    planner = make_planner("mpc-cv", make_config())
    result = planner.plan(ROBOT, GOAL, pred)
    assert planner.stats.counts["fallback_no_history"] == 1
    assert result.status == "solved"
    # Planned around the frozen pedestrian: clearance >= robot + ped radius at every knot.
    gaps = np.linalg.norm(result.states[:, :2] - [3.0, 0.0], axis=1)
    assert gaps.min() > 0.6 - 0.05


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_bad_input_still_raises(name):
    planner = make_planner(name, make_config())
    nan_hist = np.full((8, 1, 2), np.nan)
    with pytest.raises(ValueError):
        planner.plan(ROBOT, GOAL, PedPrediction(np.zeros((1, 12, 1, 2)), np.full(1, 0.3), np.zeros(1, int),
                                                np.ones(1, bool), history=nan_hist, step_s=STEP_S))
    with pytest.raises(ValueError):
        planner.plan(ROBOT, GOAL, PedPrediction(np.zeros((1, 12, 1, 2)), np.full(1, 0.3), np.zeros(1, int),
                                                np.ones(1, bool), history=np.zeros((8, 2, 2)), step_s=STEP_S))
    with pytest.raises(ValueError):
        planner.plan(np.zeros(3), GOAL, None)
    with pytest.raises(ValueError):
        planner.plan(ROBOT, np.array([np.nan, 0.0]), None)
