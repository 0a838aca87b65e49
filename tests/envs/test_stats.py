"""`envs.evaluation.stats`: Wilson intervals, the per-policy summary of typed records, and paired tests."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats as sps

from envs.evaluation.records import EpisodeRecord
from envs.evaluation.stats import aggregate, mcnemar_exact, paired_bootstrap, paired_comparison, wilson_interval


def _rec(seed, outcome, ttg=None, path=10.0, mind=0.5, disc=0.0, intr=False, plans=10, fallbacks=0, times=(),
         kind=None, policy="p", cell="c", coll_t=None):
    if outcome == "collision" and kind is None:
        kind = "robot"
    return EpisodeRecord(policy=policy, seed=seed, outcome=outcome, cell=cell,
                         collision_with="pedestrian" if outcome == "collision" else None, at_fault=kind,
                         collision_time_s=coll_t, steps=100, time_s=10.0, time_to_goal_s=ttg, path_length_m=path,
                         min_distance_m=mind, discomfort_frequency=disc, group_intrusion=intr,
                         intrusion_fraction=None if intr is None else 0.1 * intr, plans=plans, fallbacks=fallbacks,
                         ret=1.0,
                         solve_times_ms=tuple(float(t) for t in times))


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(5, 10)
    assert lo == pytest.approx(0.2366, abs=1e-4) and hi == pytest.approx(0.7634, abs=1e-4)
    z2 = 1.959963984540054**2
    assert wilson_interval(0, 4) == pytest.approx([0.0, z2 / (4 + z2)])
    assert wilson_interval(4, 4) == pytest.approx([4 / (4 + z2), 1.0])
    assert wilson_interval(0, 0) is None


def test_aggregate_hand_made_records():
    records = [
        _rec(0, "success", ttg=10.0, path=12.0, mind=0.4, disc=0.1, intr=True, plans=10, fallbacks=1,
             times=range(1, 51)),
        _rec(1, "success", ttg=20.0, path=14.0, mind=0.2, disc=0.3, intr=False, plans=10, fallbacks=0,
             times=range(51, 101)),
        _rec(2, "success", ttg=60.0, path=22.0, mind=0.6, disc=0.2, intr=False, plans=10),
        _rec(3, "collision", path=5.0, mind=-0.1, disc=0.4, intr=True, plans=5, fallbacks=3, coll_t=4.0),
        _rec(4, "timeout", path=99.0, mind=None, disc=0.0, intr=True, plans=5),  # nobody ever in the scene
    ]
    r = aggregate(records)
    assert r["episodes"] == 5 and r["completed"] == 5 and r["errors"] == 0
    assert (r["success_rate"], r["collision_rate"], r["timeout_rate"]) == (0.6, 0.2, 0.2)
    assert r["group_intrusion_rate"] == pytest.approx(0.6)
    assert r["group_intrusion_rate_success"] == pytest.approx(1 / 3)
    assert r["success_rate_ci95"] == pytest.approx(wilson_interval(3, 5))
    assert r["collision_rate_ci95"] == pytest.approx(wilson_interval(1, 5))
    assert r["collisions"] == 1 and r["collisions_at_fault_robot"] == 1 and r["time_to_first_collision_s"] == 4.0
    assert r["time_to_goal_s"] == pytest.approx(30.0) and r["time_to_goal_median_s"] == pytest.approx(20.0)
    assert r["path_length_m"] == pytest.approx(16.0)
    assert r["min_distance_m"] == pytest.approx((0.4 + 0.2 + 0.6 - 0.1) / 4)
    assert r["min_distance_overall_m"] == pytest.approx(-0.1)
    assert r["discomfort_frequency"] == pytest.approx(0.2)
    assert r["solve_time_p50_ms"] == pytest.approx(50.5) and r["solve_time_p95_ms"] == pytest.approx(95.05)
    assert r["solver_calls"] == 100
    assert r["fallback_rate"] == pytest.approx(4 / 40)
    json.dumps(r, allow_nan=False)  # strict JSON


def test_collisions_by_fault_and_errors_are_counted_apart():
    records = [_rec(0, "collision", kind="robot"), _rec(1, "collision", kind="pedestrian"),
               _rec(2, "collision", kind="spawn"), _rec(3, "success", ttg=5.0),
               EpisodeRecord(policy="p", seed=4, outcome="error", cell="c", error="RuntimeError: boom")]
    r = aggregate(records)
    assert r["episodes"] == 5 and r["completed"] == 4 and r["errors"] == 1
    assert r["collision_rate"] == 0.75  # over completed episodes
    assert r["avoidable_collision_rate"] == 0.5  # the spawn contact is not the robot's doing
    assert (r["collisions_at_fault_robot"], r["collisions_at_fault_pedestrian"],
            r["collisions_at_fault_spawn"]) == (1, 1, 1)


def test_aggregate_without_successes_solver_or_plans():
    r = aggregate([_rec(0, "collision", plans=0), _rec(1, "timeout", plans=0)])
    assert r["success_rate"] == 0.0 and r["group_intrusion_rate_success"] is None
    assert r["time_to_goal_s"] is None and r["path_length_m"] is None
    assert r["solve_time_p50_ms"] is None and r["fallback_rate"] is None
    with pytest.raises(ValueError, match="no episodes"):
        aggregate([])
    with pytest.raises(ValueError, match="outcome"):
        _rec(0, "running")


@pytest.mark.parametrize(("b", "c"), [(0, 0), (0, 5), (3, 9), (10, 10), (1, 12), (25, 7)])
def test_mcnemar_exact_matches_a_binomial_test(b, c):
    expected = 1.0 if b + c == 0 else sps.binomtest(b, b + c, 0.5).pvalue
    assert mcnemar_exact(b, c) == pytest.approx(expected, rel=1e-9)


def test_paired_comparison_uses_the_same_episodes_and_calls_significance_by_the_test():
    # a collides in 12 of 40 episodes, b in 2 of them, on the same seeds; b also has an extra seed (unpaired)
    a = [_rec(s, "collision" if s < 12 else "success", ttg=5.0, path=10.0, policy="a") for s in range(40)]
    b = [_rec(s, "collision" if s < 2 else "success", ttg=5.0, path=11.0, policy="b") for s in range(41)]
    b.append(EpisodeRecord(policy="b", seed=99, outcome="error", cell="c"))
    c = paired_comparison(a, b)
    assert c["pairs"] == 40
    assert (c["collision"]["a_only"], c["collision"]["b_only"]) == (10, 0)
    assert c["collision"]["p_value"] == pytest.approx(2 * 0.5**10) and c["collision"]["significant"]
    assert c["path_length_m"]["mean_diff"] == pytest.approx(-1.0) and c["path_length_m"]["significant"]
    # a small difference is not called significant
    d = paired_comparison(a[:14], [_rec(s, "collision" if s < 10 else "success", ttg=5.0, policy="b")
                                   for s in range(14)])
    assert not d["collision"]["significant"]


def test_paired_group_intrusions_count_episodes_that_entered_a_group():
    # a enters a group in 9 of 30 successful episodes, b in 1 of them (and in one a did not)
    a = [_rec(s, "success", ttg=5.0, intr=s < 9, policy="a") for s in range(30)]
    b = [_rec(s, "success", ttg=5.0, intr=s in (0, 20), policy="b") for s in range(30)]
    c = paired_comparison(a, b)["group_intrusion"]
    assert (c["a"], c["b"], c["a_only"], c["b_only"]) == (9, 2, 8, 1)
    assert c["p_value"] == pytest.approx(mcnemar_exact(8, 1)) and c["significant"] == (c["p_value"] < 0.05)


def test_paired_bootstrap_covers_the_mean():
    rng = np.random.default_rng(0)
    diff = rng.normal(0.3, 1.0, 200)
    mean, (lo, hi) = paired_bootstrap(diff, np.random.default_rng(1))
    assert lo < mean < hi and math.isclose(mean, diff.mean())
    half = 1.96 * diff.std(ddof=1) / math.sqrt(diff.size)
    assert hi - lo == pytest.approx(2 * half, rel=0.15)


def test_aggregate_does_not_depend_on_the_order_records_arrive_in():
    """Workers finish in any order (process pool, Ray); the summary must be bit-identical either way."""
    import random

    from envs.evaluation.records import EpisodeRecord
    from envs.evaluation.stats import aggregate

    rng = np.random.default_rng(0)
    recs = [EpisodeRecord(policy="p", seed=s, outcome="success", cell="c", ret=float(rng.normal()) * 1e3 + 0.1,
                          discomfort_frequency=float(rng.uniform()) / 3.0, path_length_m=float(rng.uniform(5, 20)),
                          time_to_goal_s=float(rng.uniform(5, 20)), min_distance_m=float(rng.uniform()))
            for s in range(40)]
    shuffled = recs[:]
    random.Random(1).shuffle(shuffled)
    assert aggregate(shuffled) == aggregate(recs)


def test_paired_min_distance_is_a_graded_margin_over_episodes_where_both_met_somebody():
    # a keeps 0.1 m more than b (plus noise) in every episode, b met nobody in one (None: left out)
    rng = np.random.default_rng(4)
    base = rng.uniform(0.2, 1.0, 60)
    a = [_rec(s, "success", ttg=5.0, mind=float(base[s] + 0.1 + rng.normal(0, 0.02)), policy="a") for s in range(60)]
    b = [_rec(s, "success", ttg=5.0, mind=None if s == 7 else float(base[s]), policy="b") for s in range(60)]
    c = paired_comparison(a, b)["min_distance_m"]
    assert c["pairs"] == 59 and c["mean_diff"] == pytest.approx(0.1, abs=0.01) and c["significant"]
    assert c["ci95"][0] < c["mean_diff"] < c["ci95"][1]
    same = paired_comparison(b, [_rec(r.seed, "success", ttg=5.0, mind=r.min_distance_m, policy="c") for r in b])
    assert same["min_distance_m"]["mean_diff"] == 0.0 and not same["min_distance_m"]["significant"]


def test_two_pairs_are_not_tested_and_never_starred():
    """The smoke suite's case: 2 paired episodes, b keeps 0.01 m more than a in both. A percentile bootstrap of two
    equal differences is the interval [-0.01, -0.01], which 'excludes 0': it must not be called significant."""
    a = [_rec(s, "success", ttg=5.0, mind=0.30, path=10.0, policy="a") for s in range(2)]
    b = [_rec(s, "success", ttg=5.0, mind=0.31, path=10.5, policy="b") for s in range(2)]
    c = paired_comparison(a, b)
    for name in ("min_distance_m", "path_length_m"):
        assert c[name]["pairs"] == 2 and c[name]["tested"] is False and c[name]["ci95"] is None
        assert not c[name]["significant"]
    assert c["min_distance_m"]["mean_diff"] == pytest.approx(-0.01)
    json.dumps(c, allow_nan=False)


def test_the_bootstrap_is_tested_from_min_bootstrap_pairs_on():
    from envs.evaluation.stats import MIN_BOOTSTRAP_PAIRS

    assert MIN_BOOTSTRAP_PAIRS == 20
    rng = np.random.default_rng(2)
    noise = rng.normal(0.0, 0.01, MIN_BOOTSTRAP_PAIRS)

    def compare(n):
        a = [_rec(s, "success", ttg=5.0, mind=0.5 + float(noise[s]), policy="a") for s in range(n)]
        b = [_rec(s, "success", ttg=5.0, mind=0.6, policy="b") for s in range(n)]
        return paired_comparison(a, b)["min_distance_m"]

    below, at = compare(MIN_BOOTSTRAP_PAIRS - 1), compare(MIN_BOOTSTRAP_PAIRS)
    assert not below["tested"] and not below["significant"] and below["ci95"] is None
    assert at["tested"] and at["significant"] and at["ci95"][1] < 0  # a clear 0.1 m, tested, is starred


def test_mcnemar_needs_six_discordant_pairs_at_alpha_005():
    from envs.evaluation.stats import min_discordant_pairs

    assert min_discordant_pairs(0.05) == 6 and mcnemar_exact(5, 0) > 0.05 > mcnemar_exact(6, 0)
    for d, tested in ((5, False), (6, True)):
        a = [_rec(s, "collision" if s < d else "success", ttg=5.0, policy="a") for s in range(30)]
        b = [_rec(s, "success", ttg=5.0, policy="b") for s in range(30)]
        c = paired_comparison(a, b)["collision"]
        assert c["tested"] is tested and c["significant"] is tested


def test_the_leaderboard_says_why_a_small_comparison_is_not_starred():
    from envs.evaluation.leaderboard import leaderboard, leaderboard_markdown
    from envs.evaluation.suite import parse_suite
    from envs.policies import PolicyConfig

    suite = parse_suite({"name": "s", "version": 1, "cells": [
        {"name": "c", "scenario": "corridor", "n_pedestrians": 4, "robot_visible": True, "episodes": 2, "seed0": 0}]})
    records = [_rec(s, "success", ttg=5.0, mind=0.30, policy="random") for s in range(2)]
    records += [_rec(s, "success", ttg=5.0, mind=0.31, policy="social-force") for s in range(2)]
    board = leaderboard(suite, list(suite.cells), [PolicyConfig("random"), PolicyConfig("social-force")], records)
    md = leaderboard_markdown(board)
    rows = [ln for ln in md.splitlines() if ln.startswith("| synthetic | random vs social-force")]
    assert len(rows) == 1 and "*" not in rows[0] and "-0.01 (2 pairs) n.t." in rows[0]
    assert "n.t.: not tested, too few pairs" in md and "at least 20 pairs" in md and "at least 6 discordant" in md


def test_group_intrusion_is_measured_only_where_the_crowd_had_labels():
    """A recording without a group file has no labels: its episodes neither count as intrusion-free nor enter the
    paired intrusion test, and a summary of such episodes alone says n/a, not 0."""
    from envs.evaluation.report import intrusion_text, rate_text

    labelled = [_rec(s, "success", ttg=5.0, intr=s < 2) for s in range(4)]
    unlabelled = [_rec(s, "success", ttg=5.0, intr=None, cell="real") for s in range(4, 10)]
    agg = aggregate(labelled + unlabelled)
    assert agg["labelled"] == 4 and agg["group_intrusion_rate"] == 0.5
    assert agg["group_intrusion_rate_success"] == 0.5 and agg["success_rate"] == 1.0  # successes: all 10
    none = aggregate(unlabelled)
    assert none["labelled"] == 0 and none["group_intrusion_rate"] is None
    assert intrusion_text(none, "group_intrusion_rate") == "n/a" == rate_text(none, "group_intrusion_rate")
    assert intrusion_text(agg, "group_intrusion_rate") == "0.50"
    a = [_rec(s, "success", intr=True, policy="a") for s in range(4)] + \
        [_rec(s, "success", intr=None, policy="a", cell="real") for s in range(4, 10)]
    b = [_rec(s, "success", intr=False, policy="b") for s in range(4)] + \
        [_rec(s, "success", intr=None, policy="b", cell="real") for s in range(4, 10)]
    paired = paired_comparison(a, b)
    assert paired["pairs"] == 10 and paired["group_intrusion"]["pairs"] == 4
    assert (paired["group_intrusion"]["a_only"], paired["group_intrusion"]["b_only"]) == (4, 0)
    assert paired["success"]["pairs"] == 10


def test_an_unlabelled_record_round_trips_as_none():
    rec = replace(_rec(0, "success", intr=None), intrusion_fraction=None)
    back = EpisodeRecord.from_json(json.loads(json.dumps(rec.to_json())))
    assert back.group_intrusion is None and back.intrusion_fraction is None and back == rec


def test_the_rates_figure_labels_an_unmeasured_intrusion_rate_n_a_not_zero():
    from envs.evaluation.report import _rates_panel, pyplot

    plt = pyplot()
    fig, ax = plt.subplots()
    none = {**aggregate([_rec(s, "success", ttg=5.0, intr=None, cell="real") for s in range(4)]), "policy": "p"}
    _rates_panel(ax, [none])
    labels = [t.get_text() for t in ax.texts]
    plt.close(fig)
    assert labels == ["1.00", "0.00", "0.00", "n/a"]  # success, collision, timeout, group intrusion
