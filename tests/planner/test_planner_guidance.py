"""The guidance layer (planner/guidance.py): passing options that differ, half-planes that hold a side, a guided
problem that is the free one with its switches off, and a shield that tries the other options first."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from planner_helpers import make_config

from planner import GuidanceConfig, MPCPlanner, PedPrediction
from planner.guidance import (
    checked_points,
    contradicts,
    keeps_sides,
    passing_sides,
    ped_gaps,
    pick_options,
)
from planner.ocp import build_ocp, pack_params, param_slices
from planner.scene import build_scene
from planner.shield import shield_futures

GOAL = np.array([8.0, 0.0])


def _oncoming(n: int = 1, y0: float = 0.0) -> PedPrediction:
    """n people in a file on the x axis from x = 4 m, walking at 1 m/s towards the robot (3 identical samples)."""
    cur = np.array([[4.0 + 0.8 * i, y0] for i in range(n)])
    pos = cur[None, None] + np.array([-1.0, 0.0]) * 0.4 * np.arange(1, 13)[None, :, None, None]
    return PedPrediction(np.repeat(pos, 3, axis=0), np.full(n, 0.3), np.arange(n), np.ones(n, bool), current=cur,
                         step_s=0.4)


def _straight(y_end: float, h: int = 10) -> np.ndarray:
    """States (1, h+1, 5) of a path from the origin to (8, y_end) m, bending out at mid-course."""
    x = np.linspace(0.0, 8.0, h + 1)
    y = y_end * np.sin(np.linspace(0.0, np.pi / 2, h + 1))
    states = np.zeros((1, h + 1, 5))
    states[0, :, 0], states[0, :, 1] = x, y
    return states


def test_paths_passing_a_person_on_opposite_sides_get_opposite_signs_and_a_far_path_none():
    cfg = make_config(guidance=GuidanceConfig())
    pred = _oncoming()
    scene = build_scene(np.zeros(5), pred, None, cfg)
    paths = np.concatenate([_straight(1.5), _straight(-1.5), _straight(1.5) + np.array([0.0, 30.0, 0.0, 0.0, 0.0])])
    gaps = ped_gaps(checked_points(paths, 1), scene)
    now = np.full((cfg.max_peds, 2), 1e3)
    now[0] = pred.current[0]
    sides = passing_sides(paths, now, scene, gaps, cfg)[:, 0]
    assert sides[0] == -sides[1] and sides[0] != 0
    assert sides[2] == 0  # 30 m away: never within relevance_m


def test_options_each_pass_someone_on_the_other_side_cheapest_first():
    sides = np.array([[1, 1], [1, 0], [-1, 1], [1, -1], [-1, -1], [0, 0]])
    costs = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    picks = pick_options(costs, sides, [np.array([1, 1])], 3)
    assert picks == [2, 3, 4]  # [1, 0] contradicts nothing; [0, 0] never would
    for i, a in enumerate(picks):
        assert contradicts(sides[a], np.array([1, 1]))
        assert all(contradicts(sides[a], sides[b]) for b in picks[:i])
    assert pick_options(costs, sides, [], 1) == [0]
    walled = np.where(np.arange(6) == 2, np.inf, costs)  # the path into a wall is never an option
    assert pick_options(walled, sides, [np.array([1, 1])], 3) == [3, 4]


def test_keeping_sides_means_contradicting_none():
    assert keeps_sides({1: 1, 2: -1}, {1: 1, 5: 1})
    assert not keeps_sides({1: 1, 2: -1}, {2: 1})
    assert keeps_sides({1: -1}, {})


def test_a_guided_problem_with_its_switches_off_is_the_free_problem():
    """Same objective and slacks to the last bit on random plans: guidance changes nothing until a switch is on."""
    free_cfg = make_config(max_peds=3, max_walls=0)
    free, guided = build_ocp(free_cfg), build_ocp(replace(free_cfg, guidance=GuidanceConfig()))
    assert "ped_normal" not in param_slices(free.sizes) and "ped_side" in param_slices(guided.sizes)
    state = np.array([0.0, 0.0, 0.1, 0.5, 0.0])
    scene = build_scene(state, _oncoming(3, 0.2), None, free_cfg)
    p_free, p_guided = (pack_params(o.sizes, state, GOAL, scene) for o in (free, guided))
    rng = np.random.default_rng(0)
    for _ in range(5):
        w = rng.normal(size=free.layout.n)
        assert float(free.cost_fn(w, p_free)) == float(guided.cost_fn(w, p_guided))
        assert np.array_equal(free.slack_fn(w, p_free).full(), guided.slack_fn(w, p_guided).full())


def test_a_half_plane_holds_the_side_a_disc_does_not():
    """At a point on the far side of the person the half-plane is violated, the disc is not."""
    cfg = make_config(max_peds=1, max_walls=0, max_groups=0, guidance=GuidanceConfig())
    ocp = build_ocp(cfg)
    state = np.zeros(5)
    scene = build_scene(state, _oncoming(), None, cfg)
    p = pack_params(ocp.sizes, state, GOAL, scene)
    sl = param_slices(ocp.sizes)
    normal = np.zeros((ocp.sizes.nt, 1, ocp.sizes.k, 2))
    normal[..., 1] = 1.0  # pass above the person (+y)
    guided = p.copy()
    guided[sl["ped_normal"]], guided[sl["ped_side"]] = normal.ravel(), 1.0
    w = np.zeros(ocp.layout.n)
    w[ocp.layout.z[1:, 0]] = scene.ped_pos[:, 0, 0, 0]  # every knot at the person's x, 2 m below them
    w[ocp.layout.z[1:, 1]] = -2.0
    assert ocp.slack_fn(w, p).full().max() == 0.0  # far from the disc
    assert ocp.slack_fn(w, guided).full().max() > 1.0  # on the wrong side of the half-plane


@pytest.mark.parametrize("y0", [0.0, 0.15])
def test_guidance_offers_both_sides_of_an_oncoming_file(y0):
    planner = MPCPlanner(make_config(guidance=GuidanceConfig()))
    result = planner.plan(np.array([0.0, 0.0, 0.0, 1.0, 0.0]), GOAL, _oncoming(4, y0))
    assert result.status == "solved" and len(result.options) >= 2
    assert np.array_equal(result.options[0], result.states)
    ys = [opt[5, 1] for opt in result.options]  # where each option is 2 s from now, the file passing by
    assert min(ys) < y0 - 0.3 and max(ys) > y0 + 0.3


def test_without_guidance_there_are_no_options():
    result = MPCPlanner(make_config()).plan(np.array([0.0, 0.0, 0.0, 1.0, 0.0]), GOAL, _oncoming(2))
    assert result.options == ()


def test_the_shield_takes_a_safe_alternative_plan_before_its_own_commands():
    """Straight ahead at 1 m/s hits a person standing 1.6 m in front within the look-ahead; the second alternative
    (stop) does not, and is taken before any of the shield's own commands."""
    cfg = make_config(shield_horizon_s=1.6)
    futures = np.tile(np.array([1.6, 0.0]), (1, 16, 1, 1))  # (K=1, T, n=1, 2)
    plan = np.tile([1.0, 0.0], (10, 1))
    stop = np.zeros((10, 2))
    state = np.array([0.0, 0.0, 0.0, 1.0, 0.0])
    verdict = shield_futures(state, plan, futures, np.array([0.3]), None, cfg, alternatives=np.stack([plan, stop]))
    assert verdict.replaced and verdict.option == 1 and np.array_equal(verdict.control, stop[0])
    assert verdict.chosen_risk <= cfg.shield_max_risk < verdict.risk
    alone = shield_futures(state, plan, futures, np.array([0.3]), None, cfg)
    assert alone.option == -1


def test_guidance_config_is_validated():
    with pytest.raises(ValueError, match="n_paths"):
        GuidanceConfig(n_paths=0)
    with pytest.raises(ValueError, match="speed_fractions"):
        GuidanceConfig(speed_fractions=(0.0,))
    with pytest.raises(ValueError, match="hold_discount"):
        GuidanceConfig(hold_discount=1.0)
