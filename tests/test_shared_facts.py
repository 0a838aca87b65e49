"""Facts the packages share, with one owner each; where the no-cross-import rule makes a package keep its own copy
(a declared twin), the copy is checked against the owner here, in the one place that may import them all.

- ETH/UCY timing (0.4 s, 8 observed + 12 predicted steps): owner `predictor.ethucy`; twin: crowdsim's
  `SimConfig.record_dt_s` default.
- constant-velocity extrapolation: owner `planner.constant_velocity_prediction`; twin: the mean of predictor's
  `ConstantVelocityPredictor`.
- point-to-segment projection: owner `planner.segment_projection`; twins: `crowdsim.forces.closest_points_on_segments`,
  and the env's scalar (`envs.scoring.geometry._segment_distance`) and compiled (`envs.scoring.kernels`) hull-test
  copies.
- without twins: the default predictor name (`envs.config.DEFAULT_PREDICTOR`), the robot's body and limits
  (`planner.RobotConfig`; crowdsim's robot slot is `RobotSlot`), the planner names (`planner.PLANNERS`, which the
  env's policies use).
- atomic file writes and the writable-folder check: owner `crowdsim.files` (crowdsim and envs use it); twin:
  `predictor.files.write_atomic`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crowdsim import SimConfig
from crowdsim.files import write_atomic as crowdsim_write_atomic
from crowdsim.forces import closest_points_on_segments
from envs.scoring.geometry import _segment_distance
from envs.timing import DEFAULT_TIMING
from planner import constant_velocity_prediction, point_segment_distances, segment_projection
from predictor.ethucy import OBS_LEN, PRED_LEN, STEP_S
from predictor.files import write_atomic as predictor_write_atomic


def test_the_timing_has_one_definition_and_crowdsims_twin_matches_it():
    assert (DEFAULT_TIMING.step_s, DEFAULT_TIMING.obs_len, DEFAULT_TIMING.pred_len) == (STEP_S, OBS_LEN, PRED_LEN)
    assert SimConfig().record_dt_s == STEP_S  # crowdsim records datasets on the predictor's grid


def test_constant_velocity_is_the_same_extrapolation_in_the_planner_and_the_predictor():
    from predictor import load_predictor

    rng = np.random.default_rng(0)
    history = np.cumsum(rng.normal(0.0, 0.3, (OBS_LEN, 6, 2)), axis=0)  # (8, N, 2) m, 0.4 s apart
    planner_cv = constant_velocity_prediction(history, n_steps=PRED_LEN, step_s=STEP_S).positions[0]
    predictor_cv = load_predictor("constant-velocity").predict(history, n_samples=1, rng=0).mean
    np.testing.assert_allclose(planner_cv, predictor_cv, rtol=0, atol=1e-12)
    history[-1, 0] += 1.0  # the twins move together: a different last step changes both the same way
    moved = constant_velocity_prediction(history, n_steps=PRED_LEN, step_s=STEP_S).positions[0]
    np.testing.assert_allclose(moved, load_predictor("cv").predict(history, n_samples=1, rng=0).mean, atol=1e-12)
    assert not np.allclose(moved, planner_cv)


@pytest.mark.parametrize("seed", range(3))
def test_every_point_to_segment_twin_agrees_with_the_planners(seed):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-5.0, 5.0, (40, 2))
    segs = rng.uniform(-5.0, 5.0, (7, 4))
    segs[0, 2:] = segs[0, :2]  # a degenerate (zero-length) wall
    rel, t, ab = segment_projection(points, segs)
    owner = points[:, None, :] - rel + t[..., None] * ab  # the closest points, (40, 7, 2)
    np.testing.assert_allclose(closest_points_on_segments(points, segs.reshape(-1, 2, 2)), owner, atol=1e-12)
    dist = point_segment_distances(points, segs)
    for i, (px, py) in enumerate(points):
        for w, s in enumerate(segs):
            assert _segment_distance(px, py, (s[0], s[1]), (s[2], s[3])) == pytest.approx(dist[i, w], abs=1e-12)


@pytest.mark.parametrize("write_atomic", [crowdsim_write_atomic, predictor_write_atomic], ids=["crowdsim", "predictor"])
def test_both_atomic_writers_keep_the_old_file_on_failure_and_leave_nothing_behind(write_atomic, tmp_path):
    target = tmp_path / "sub" / "out.txt"
    write_atomic(target, lambda tmp: Path(tmp).write_text("old"))
    assert target.read_text() == "old" and target.stat().st_mode & 0o777 == 0o644

    def half_then_fail(tmp: str) -> None:
        Path(tmp).write_text("half")
        raise KeyboardInterrupt  # Ctrl-C in the middle of a write

    with pytest.raises(KeyboardInterrupt):
        write_atomic(target, half_then_fail)
    assert target.read_text() == "old" and sorted(p.name for p in target.parent.iterdir()) == ["out.txt"]
    write_atomic(target, lambda tmp: Path(tmp).write_text("new"))
    assert target.read_text() == "new" and sorted(p.name for p in target.parent.iterdir()) == ["out.txt"]
