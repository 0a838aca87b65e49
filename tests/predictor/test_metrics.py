"""Metrics against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from predictor.metrics import GroupScores, ade_fde, col, f1, interpolate, mitre_counts, pw_counts, ratio, tcc
from predictor.report import nan_to_none


def _mitre(truth: list[int], pred: list[int]) -> tuple[float, float]:
    r_num, r_den, p_num, p_den = mitre_counts(np.array(truth), np.array(pred))
    return ratio(r_num, r_den), ratio(p_num, p_den)


def test_ade_fde_is_min_per_pedestrian() -> None:
    gt = np.zeros((12, 2, 2))
    samples = np.zeros((2, 12, 2, 2))
    samples[0, :, 0, 0] = 1.0  # ped 0 off by 1 m in sample 0, exact in sample 1
    samples[1, :, 1, 1] = 2.0  # ped 1 off by 2 m in sample 1, exact in sample 0
    samples[1, -1, 0, 0] = 3.0  # ped 0 sample 1: only the last step is off by 3 m
    ade, fde = ade_fde(samples, gt)
    np.testing.assert_allclose(ade, [0.25, 0.0])  # ped 0: min(1.0, 3/12) ; ped 1: sample 0
    np.testing.assert_allclose(fde, [1.0, 0.0])


def test_col_counts_near_pairs_per_sample() -> None:
    t = np.arange(12, dtype=float)
    samples = np.zeros((2, 12, 3, 2))
    samples[:, :, 0, 0] = t
    samples[:, :, 1, 0] = t
    samples[:, :, 1, 1] = 1.0  # 1 m apart: never collide
    samples[0, :, 2, 0] = t
    samples[0, :, 2, 1] = 0.1  # sample 0: ped 2 is 0.1 m from ped 0
    samples[1, :, 2, 1] = -5.0
    np.testing.assert_allclose(col(samples), [50.0, 0.0, 50.0])
    # a collision only after the 14 checked interpolated points (step 4+) is not counted
    late = samples[1:].copy()
    late[0, 5:, 2] = late[0, 5:, 0] + [0.0, 0.05]
    np.testing.assert_allclose(col(late), [0.0, 0.0, 0.0])
    assert interpolate(samples).shape == (2, 45, 3, 2)


def test_tcc_perfect_and_anti_correlated() -> None:
    t = np.linspace(0, 1, 12)
    gt = np.stack([np.stack([t, t**2], -1)], axis=1)  # (12, 1, 2)
    same = gt[None] * 2.0 + 1.0
    assert tcc(same, gt)[0] == pytest.approx(1.0)
    anti = -gt[None]
    assert tcc(anti, gt)[0] == pytest.approx(-1.0)
    flat = np.zeros((1, 12, 1, 2))
    assert tcc(flat, gt)[0] == 0.0


def test_pw_counts() -> None:
    # truth {0,1,2},{3}; pred {0,1},{2,3}
    tp, n_pred, n_true = pw_counts(np.array([0, 0, 0, 1]), np.array([0, 0, 1, 1]))
    assert (tp, n_pred, n_true) == (1, 2, 3)


def test_mitre_alternating_membership() -> None:
    recall, precision = _mitre([0, 0, 0, 0, 0], [0, 1, 0, 1, 0])
    assert recall == pytest.approx(0.75)  # (5 - 2) / (5 - 1)
    assert precision == pytest.approx(1.0)  # each predicted cluster lies inside one true cluster


def test_mitre_singletons_get_fake_partners() -> None:
    # all singletons on both sides: perfect, not undefined
    assert _mitre([0, 1, 2], [0, 1, 2]) == (1.0, 1.0)
    # truth: all alone -> {0,f0},{1,f1},{2,f2}; pred {0,1},{2} -> {0,1},{f0},{f1},{2,f2}.
    # Recall: {0,f0} and {1,f1} each touch 2 pred clusters (0 of 1 link kept), {2,f2} touches 1: 1/3.
    # Precision: {0,1} touches 2 true clusters (0 of 1), {2,f2} touches 1 (1 of 1), fakes alone: 1/2.
    recall, precision = _mitre([0, 1, 2], [0, 0, 1])
    assert recall == pytest.approx(1 / 3)
    assert precision == pytest.approx(1 / 2)


def test_group_scores_sum_counts_over_windows() -> None:
    scores = GroupScores()
    scores.add(np.array([0, 0, 0, 0, 0]), np.array([0, 1, 0, 1, 0]))
    scores.add(np.array([0, 0]), np.array([0, 0]))
    res = scores.result()
    assert res["gmitre_recall"] == pytest.approx((3 + 1) / (4 + 1))
    assert res["pw_precision"] == pytest.approx(1.0)
    assert res["pw_recall"] == pytest.approx((4 + 1) / (10 + 1))


def test_report_table_averages_scenes(tmp_path) -> None:
    import json

    from predictor.report import load_results, table

    for i, scene in enumerate(("eth", "hotel", "univ", "zara1", "zara2")):
        res = {"ade": 0.1 * (i + 1), "fde": 0.2, "col": 1.0, "tcc": 0.5, "seed": 0, "trials": 3}
        (tmp_path / f"gpgraph-stgcnn-{scene}-iid.json").write_text(json.dumps(res))
    text = table(load_results(tmp_path), "iid")
    assert "| gpgraph-stgcnn | 0.10/0.20 |" in text and "0.300/0.200" in text


@pytest.mark.parametrize("precision, recall, expected", [
    (0.5, 1.0, 2 / 3), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), (None, 0.5, float("nan")), (float("nan"), 0.5, float("nan")),
])
def test_f1_is_the_harmonic_mean_and_nan_when_undefined(precision, recall, expected) -> None:
    np.testing.assert_equal(f1(precision, recall), expected)


def test_nan_to_none_reaches_nested_dicts_only_for_nan() -> None:
    assert nan_to_none({"a": float("nan"), "b": {"c": float("nan"), "d": 1.5}, "e": "x", "f": 0.0}) == {
        "a": None, "b": {"c": None, "d": 1.5}, "e": "x", "f": 0.0}


def test_constant_velocity_evaluation_is_exact_on_straight_walkers() -> None:
    """Pedestrians walking straight at constant speed: the noise-free extrapolation is exact (ADE/FDE k1 = 0),
    the noisy samples are not, and the all-singletons grouping scores PW precision NaN (no predicted pairs)."""
    from predictor.evaluate import evaluate_constant_velocity
    from predictor.windows import Window

    t = np.arange(20)[:, None] * 0.4
    traj = np.stack([np.hstack([t * 1.2, np.full_like(t, k * 3.0)]) for k in range(3)], axis=1)  # (20, 3, 2)
    w = Window(obs=traj[:8], pred=traj[8:], ped_ids=np.arange(3), group_id=np.array([0, 0, 1]))
    r = evaluate_constant_velocity([w], seed=0, trials=2, n_samples=20)
    assert r["ade_k1"] == pytest.approx(0.0, abs=1e-9) and r["fde_k1"] == pytest.approx(0.0, abs=1e-9)
    assert 0 < r["ade"] < r["fde"] < 1.0
    assert (r["pedestrians"], r["windows"], r["trials"], r["protocol"]) == (3, 1, 2, "constant-velocity")
    assert r["pw_recall"] == 0.0 and r["pw_precision"] != r["pw_precision"]
    assert nan_to_none(evaluate_constant_velocity([w], seed=0, trials=2, n_samples=20)) == nan_to_none(r)  # seeded
