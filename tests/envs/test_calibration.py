"""The observation's prediction sources and the running conformal calibration of its predictions
(`envs.calibration`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv, ObservationConfig
from envs.calibration import PredictionCalibration, conformal_quantile, nearest_errors
from envs.observation import field_names, layout_table, mismatches, signature

STEP = 0.4  # s between planning ticks
ERRORS = np.array([0.5, 0.1, 0.9, 0.3, 0.7, 0.2, 0.8, 0.4, 0.6, 1.0])  # sorted: 0.1 ... 1.0


def _q(errors: np.ndarray, alpha: float) -> float:
    return float(conformal_quantile(np.asarray(errors, float), np.int64(len(errors)), alpha))


# ----------------------------------------------------------------------------------------- the quantile
def test_conformal_quantile_is_the_corrected_order_statistic():
    # n = 10: k = ceil(11 (1 - alpha)); the k-th smallest of 0.1 ... 1.0 is k / 10
    assert _q(ERRORS, 0.5) == 0.6  # ceil(5.5) = 6 (the plain median would be the 5th)
    assert _q(ERRORS, 0.2) == 0.9  # ceil(8.8) = 9
    assert _q(ERRORS, 0.3) == 0.8  # ceil(7.7) = 8
    assert _q(ERRORS, 0.1) == 1.0  # ceil(9.9) = 10: the largest
    assert _q(ERRORS[:9], 0.2) == 0.8  # n = 9: (n + 1)(1 - alpha) = 8 exactly: the 8th smallest of the nine
    # the level ceil((n + 1)(1 - alpha)) / n of the corrected empirical quantile (numpy's inverted CDF)
    n = len(ERRORS)
    assert _q(ERRORS, 0.3) == np.quantile(ERRORS, math.ceil((n + 1) * 0.7) / n, method="inverted_cdf")
    # (n + 1)(1 - alpha) that rounds to just above a whole number: 25 x 0.56 = 14.000000000000002 -> k = 14, not 15
    many = np.arange(1, 25) / 100.0
    assert 25 * (1 - 0.44) > 14 and _q(many, 0.44) == 0.14


def test_few_or_no_errors_give_the_largest_or_the_prior_and_nan_slots_are_empty():
    assert _q(ERRORS[:5], 0.1) == 0.9  # k = ceil(6 x 0.9) = 6 > 5: capped at the largest of 0.5, 0.1, 0.9, 0.3, 0.7
    padded = np.array([[0.3, np.nan, 0.1, np.nan], [np.nan] * 4])  # rows of 2 and 0 errors in a window of 4
    out = conformal_quantile(padded, np.array([2, 0]), 0.5)
    np.testing.assert_array_equal(out, [0.3, 0.0])  # k = ceil(1.5) = 2 of (0.1, 0.3); no error: the prior 0 m
    assert np.isfinite(out).all()


def test_the_error_of_k_samples_is_the_distance_to_the_nearest():
    points = np.array([[[0.0, 0.0], [1.0, 1.0]], [[3.0, 4.0], [3.0, 0.0]], [[np.nan, np.nan], [2.0, 0.0]]])  # (n, K, 2)
    truth = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(nearest_errors(points, truth), [1.0, 3.0, 2.0])  # a NaN sample (padding) is ignored


# ----------------------------------------------------------------------------------- the running state
def _walker(tick: int, turn_at: int | None = None) -> np.ndarray:
    """Where a person walking +x at 1 m/s is on `tick` ((2,) m); from tick `turn_at` on they walk +y instead."""
    if turn_at is None or tick <= turn_at:
        return np.array([STEP * tick, 0.0])
    return np.array([STEP * turn_at, STEP * (tick - turn_at)])


def _constant_velocity(tick: int, turn_at: int | None = None) -> np.ndarray:
    """The constant-velocity prediction (1, 12, 1, 2) m made on `tick` from the last 0.4 s."""
    now, before = _walker(tick, turn_at), _walker(tick - 1, turn_at)
    return (now + np.arange(1, 13)[:, None] * (now - before))[None, :, None]


def test_errors_count_only_when_their_time_has_come():
    """A walker at 1 m/s predicted to stand still: the prediction made on tick i misses step h by 0.4 h m, and is
    scored on tick i + h, not before."""
    cal, pid = PredictionCalibration(alpha=0.1, window=20), np.array([7])
    for tick in range(14):
        stand = np.broadcast_to(_walker(tick), (1, 12, 1, 2))
        cal.update(tick, pid, _walker(tick)[None], stand)
        q, count = cal.features(pid)
        due = np.arange(1, 13) <= tick  # steps that some earlier prediction has reached by now
        np.testing.assert_allclose(q[0], np.where(due, STEP * np.arange(1, 13), 0.0), atol=1e-12)
        assert count[0] == min(tick, 20)


def test_a_straight_walker_has_no_error_and_a_turning_one_the_hand_value():
    straight, turning, pid = PredictionCalibration(0.1, 20), PredictionCalibration(0.1, 20), np.array([3])
    for tick in range(1, 30):
        straight.update(tick, pid, _walker(tick)[None], _constant_velocity(tick))
        samples = _constant_velocity(tick, turn_at=4) if tick == 3 else None  # one prediction, just before the turn
        turning.update(tick, pid, _walker(tick, turn_at=4)[None], samples)
    np.testing.assert_allclose(straight.features(pid)[0], 0.0, atol=1e-12)
    assert straight.features(pid)[1][0] == 20  # the window is full
    # predicted on tick 3 at (0.4 (3 + h), 0); truly at (1.6, 0.4 (h - 1)) on tick 3 + h: 0.4 sqrt(2) (h - 1) m
    h = np.arange(1, 13)
    np.testing.assert_allclose(turning.features(pid)[0][0], STEP * math.sqrt(2) * (h - 1), atol=1e-12)


def test_the_window_keeps_the_last_errors_and_people_are_known_by_id():
    """Step-1 errors grow by 0.01 m a tick; a window of 5 keeps the last five. Person 9 leaves after tick 0 and
    comes back on tick 3: their prediction of tick 0 is scored at step 3 only; a stranger gets the prior."""
    cal = PredictionCalibration(alpha=0.5, window=5)
    for tick in range(1, 31):
        miss = np.zeros((1, 12, 1, 2))
        miss[0, 0, 0, 0] = 0.01 * tick  # the next tick's position is 0 in truth
        cal.update(tick, np.array([1]), np.zeros((1, 2)), miss)
    q, count = cal.features(np.array([1]))
    assert count[0] == 5 and q[0, 0] == pytest.approx(0.27)  # errors 0.25 ... 0.29; k = ceil(6 x 0.5) = 3
    assert cal._errors.shape[-1] == 5

    back = PredictionCalibration(alpha=0.1, window=20)
    back.update(0, np.array([9, 4]), np.zeros((2, 2)), np.ones((1, 12, 2, 2)))  # everyone predicted at (1, 1)
    back.update(1, np.array([4]), np.zeros((1, 2)), None)
    back.update(2, np.array([4]), np.zeros((1, 2)), None)
    back.update(3, np.array([9]), np.zeros((1, 2)), None)
    q, count = back.features(np.array([9, 4, 55]))
    np.testing.assert_allclose(q[0, :4], [0.0, 0.0, math.sqrt(2), 0.0])
    np.testing.assert_allclose(q[1, :4], [math.sqrt(2), math.sqrt(2), 0.0, 0.0])
    np.testing.assert_array_equal(count, [0, 1, 0])
    np.testing.assert_array_equal(q[2], 0.0)


def test_ticks_with_different_sample_counts_are_scored_alike():
    """One sample on tick 0, three on tick 1 (the nearest exact): each is scored against its own samples."""
    cal, pid = PredictionCalibration(alpha=0.1, window=4), np.array([2])
    cal.update(0, pid, np.zeros((1, 2)), np.full((1, 12, 1, 2), 3.0))
    three = np.stack([np.full((12, 1, 2), 5.0), np.zeros((12, 1, 2)), np.full((12, 1, 2), -1.0)])
    cal.update(1, pid, np.zeros((1, 2)), three)
    cal.update(2, pid, np.zeros((1, 2)), None)
    q, count = cal.features(pid)
    assert count[0] == 2  # step 1 of ticks 0 and 1
    np.testing.assert_allclose(q[0, :3], [3 * math.sqrt(2), 3 * math.sqrt(2), 0.0])  # step 1: max(3 sqrt 2, 0)


# ------------------------------------------------------------------------------------------ settings
def test_settings_are_validated_and_an_unknown_source_lists_the_valid_ones():
    unknown = r"unknown prediction_source 'orcale'; did you mean 'oracle'\? valid names: predictor, oracle"
    with pytest.raises(ValueError, match=unknown):
        ObservationConfig(predictions=True, prediction_source="orcale")
    with pytest.raises(ValueError, match="needs predictions=True"):
        ObservationConfig(prediction_calibration=True)
    for alpha in (0.0, 1.0, -0.1, float("nan"), True):
        with pytest.raises(ValueError, match="calibration_alpha"):
            ObservationConfig(predictions=True, prediction_calibration=True, calibration_alpha=alpha)
    with pytest.raises(ValueError, match="calibration_window"):
        ObservationConfig(calibration_window=0)
    with pytest.raises(ValueError, match="alpha must be in"):
        PredictionCalibration(alpha=1.0, window=3)


# ------------------------------------------------------------------------------------- in the env
CV = dict(predictions=True, predictor="constant-velocity", n_prediction_samples=2)


def _config(**obs) -> CrowdNavConfig:
    return CrowdNavConfig(scenario="circle_crossing", n_pedestrians=5, time_limit_s=8.0, robot_visible=False,
                          observation=ObservationConfig(**obs))


def _roll(env: CrowdNavEnv, steps: int, seed: int = 0) -> list[dict[str, np.ndarray]]:
    out, rng = [env.reset(seed=seed)[0]], np.random.default_rng(seed)
    for _ in range(steps):
        obs, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        out.append(obs)
        if term or trunc:
            break
    return out


def test_calibration_adds_its_keys_and_changes_nothing_else():
    off, on = (_roll(CrowdNavEnv(_config(**CV, prediction_calibration=c)), 40) for c in (False, True))
    assert len(off) == len(on) > 30
    assert set(on[0]) - set(off[0]) == {"prediction_error", "prediction_error_count"}
    space = CrowdNavEnv(_config(**CV, prediction_calibration=True)).observation_space
    for a, b in zip(off, on, strict=True):
        assert all(np.array_equal(a[k], b[k]) for k in a)  # the same observation, bit for bit
        assert space.contains(b)
        pad = b["pedestrian_mask"] == 0
        assert not b["prediction_error"][pad].any() and not b["prediction_error_count"][pad].any()
    last = on[-1]
    real = last["pedestrian_mask"] == 1
    assert (last["prediction_error_count"][real] > 0).all() and (last["prediction_error"][real] > 0).any()


def test_the_oracle_source_predicts_the_truth_with_no_error():
    cfg = _config(predictions=True, prediction_source="oracle", prediction_calibration=True, n_prediction_samples=3)
    env = CrowdNavEnv(cfg)
    out = _roll(env, 40)
    assert env._predictor is None  # no predictor was loaded
    last = out[-1]
    real = last["pedestrian_mask"] == 1
    assert real.sum() == 5 and (last["prediction_error_count"][real] >= 9).all()
    assert np.abs(last["prediction_error"]).max() < 1e-6  # the predictions whose time came were right
    np.testing.assert_array_equal(last["predictions"][0], last["predictions"][2])  # K copies of the one future
    assert np.abs(last["predictions"][0][:, real]).sum() > 0
    truth, oracle = (CrowdNavEnv(_config(predictions=True, prediction_source="oracle", group_source=g)).reset(seed=4)[0]
                     for g in ("truth", "predicted"))
    np.testing.assert_array_equal(oracle["group_ids"], truth["group_ids"])  # the oracle's groups are the true ones


def test_the_layout_names_the_calibration_and_the_signature_records_its_meaning():
    cfg = _config(**CV, prediction_calibration=True, max_pedestrians=3)
    names = field_names(cfg)
    assert names[3 + 3 + 15] == "prediction_error[0][t=0].quantile_m"  # after group_ids, mask and pedestrians
    assert names[21 + 36:21 + 39] == [f"prediction_error_count[{i}]" for i in range(3)]
    assert "| prediction_error | 21-56 | (3, 12) |" in layout_table(cfg)
    sig = signature(cfg)
    assert (sig["prediction_source"], sig["calibration_alpha"]) == ("predictor", 0.1)
    assert "prediction_source" not in signature(_config())  # without predictions: as agents saved before
    other = signature(_config(**{**CV, "prediction_source": "oracle"}, prediction_calibration=True,
                              max_pedestrians=3, calibration_alpha=0.2))
    assert mismatches(sig, other) == ["prediction_source 'predictor' (agent) vs 'oracle' (env)",
                                      "calibration_alpha 0.1 (agent) vs 0.2 (env)"]


def test_a_rows_prediction_is_found_by_its_id_not_its_place():
    """People arrive and leave between the predictor's ticks: the observation matches each row to the tick's
    prediction by pedestrian id. Reordered predictions observe the same; a newcomer in place of someone who left (the
    head count unchanged) gets nobody's prediction instead of the leaver's."""
    env = CrowdNavEnv(_config(predictions=True, prediction_source="oracle"))
    obs = env.reset(seed=4)[0]
    real = obs["pedestrian_mask"] == 1
    assert np.abs(obs["predictions"][:, :, real]).sum() > 0
    order = np.arange(len(env._pred_ids))[::-1]
    env._pred_ids, env._pred_samples = env._pred_ids[order], env._pred_samples[:, :, order]
    env._pred_groups = env._pred_groups[order]
    np.testing.assert_array_equal(env._observe()["predictions"], obs["predictions"])
    env._pred_ids = env._pred_ids.copy()
    env._pred_ids[0] = 10**6  # the tick predicted someone who has left since; a newcomer is in the table instead
    assert np.abs(env._observe()["predictions"]).sum() == 0
