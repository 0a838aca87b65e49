"""Failures classed against the reference mpc-oracle on the same episodes, and the success headroom."""

from __future__ import annotations

import pytest

from envs.evaluation.leaderboard import leaderboard, leaderboard_markdown
from envs.evaluation.records import EpisodeRecord
from envs.evaluation.reference import against_reference
from envs.evaluation.suite import parse_suite
from envs.policies import PolicyConfig

SUITE = parse_suite({"name": "t", "version": 1, "description": "test", "defaults": {},
                     "cells": [{"name": "c", "scenario": "corridor", "n_pedestrians": 4, "robot_visible": True,
                                "episodes": 30, "seed0": 0}]})


def _rec(policy: str, seed: int, outcome: str) -> EpisodeRecord:
    return EpisodeRecord(policy=policy, seed=seed, outcome=outcome, cell="c",
                         collision_with="pedestrian" if outcome == "collision" else None,
                         at_fault="robot" if outcome == "collision" else None)


def test_each_failure_is_the_oracles_or_the_predictions():
    oracle = [_rec("mpc-oracle", s, o) for s, o in enumerate(["success", "timeout", "collision", "success", "success"])]
    policy = [_rec("p", s, o) for s, o in enumerate(["collision", "timeout", "collision", "timeout", "success"])]
    c = against_reference(policy, oracle)
    assert (c["pairs"], c["failures"], c["reference_also_fails"], c["reference_succeeds"]) == (5, 4, 2, 2)
    assert c["success_headroom"] == pytest.approx(1 / 5 - 3 / 5) and not c["tested"] and c["ci95"] is None
    errored = [*policy[:4], _rec("p", 4, "error")]  # an error is not a failure of the policy's: left out
    assert against_reference(errored, oracle)["pairs"] == 4


def test_from_enough_pairs_the_headroom_has_an_interval_and_the_leaderboard_a_reference_table():
    oracle = [_rec("mpc-oracle", s, "success") for s in range(30)]
    policy = [_rec("p", s, "collision" if s % 3 == 0 else "success") for s in range(30)]
    c = against_reference(policy, oracle)
    assert c["tested"] and c["success_headroom"] == pytest.approx(-10 / 30)
    assert c["ci95"][0] < -10 / 30 < c["ci95"][1] < 0  # the oracle is significantly better here
    assert (c["reference_also_fails"], c["reference_succeeds"]) == (0, 10)
    cells = SUITE.cells
    with_ref = leaderboard(SUITE, list(cells), [PolicyConfig("mpc-oracle"), PolicyConfig("random")],
                           [*oracle, *(_rec("random", r.seed, r.outcome) for r in policy)])
    assert with_ref["reference"]["pooled"]["synthetic"]["random"]["reference_succeeds"] == 10
    assert "### Against the reference (mpc-oracle" in leaderboard_markdown(with_ref)
    without = leaderboard(SUITE, list(cells), [PolicyConfig("random")], [_rec("random", r.seed, r.outcome)
                                                                        for r in policy])
    assert "reference" not in without and "Against the reference" not in leaderboard_markdown(without)
