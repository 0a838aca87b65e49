"""The sampling arbiter (planner/sampling.py): its futures go on past the prediction, its check points are the plan's
own motion, its clearances are the brute-force ones, and it keeps the MPC's plan unless another candidate avoids a
contact or a group that the plan meets."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from planner import MPCConfig, MPCPlanner, PedPrediction, PlanResult, RobotConfig, RouteConfig, Router, SamplingConfig
from planner.dynamics import step_numpy
from planner.kernels import capsule_clearance, person_clearance
from planner.sampling import arbitrate, check_points, futures_at, make_candidates, view_steps
from planner.scene import point_segment_distances

RADIUS = 0.3
CFG = MPCConfig(safety_margin_m=0.3, time_budget_s=10.0, sampling=SamplingConfig())


def _people(start: np.ndarray, velocity: np.ndarray, groups: np.ndarray | None = None, k: int = 1,
            steps: int = 12) -> PedPrediction:
    """People at start (N, 2) m walking at velocity (N, 2) m/s: k identical samples of `steps` 0.4 s steps, with a
    history of the same walk."""
    t = 0.4 * np.arange(1, steps + 1)
    pos = np.repeat((start[None] + t[:, None, None] * velocity[None])[None], k, axis=0)
    hist = start[None] + 0.4 * np.arange(-7, 1)[:, None, None] * velocity[None]
    n = len(start)
    return PedPrediction(pos, np.full(n, RADIUS), np.arange(n) if groups is None else groups, np.ones(n, bool),
                         current=start, history=hist, step_s=0.4)


def _straight(speed: float, steps: int) -> np.ndarray:
    """(steps, 2) unicycle controls: straight ahead at `speed` m/s."""
    return np.tile([speed, 0.0], (steps, 1))


def test_futures_are_the_prediction_then_each_sample_at_its_last_velocity() -> None:
    pred = _people(np.array([[2.0, 1.0]]), np.array([[0.5, -0.25]]), steps=12)
    times = np.array([0.2, 0.4, 4.6, 4.8, 6.0, 8.0])
    fut, radii, has_cv = futures_at(pred, times, with_cv=True)
    assert fut.shape == (2, 6, 1, 2) and has_cv and radii.tolist() == [RADIUS]
    want = np.array([2.0, 1.0]) + times[:, None] * np.array([0.5, -0.25])
    assert np.allclose(fut[0, :, 0], want)  # linear inside, the same walk continued beyond 4.8 s
    assert np.allclose(fut[1, :, 0], want)  # the constant-velocity future of the history
    turning = replace(pred, positions=pred.positions.copy())
    turning.positions[0, -1, 0] = turning.positions[0, -2, 0] + np.array([0.0, 0.4])  # its last step goes north
    beyond = futures_at(turning, np.array([4.8, 5.8]), with_cv=False)[0][0, :, 0]
    assert np.allclose(beyond[1] - beyond[0], [0.0, 1.0])  # 1 m/s north for the second past the end


def test_check_points_are_the_knots_and_the_exact_half_way_points() -> None:
    cands = make_candidates(np.array([0.0, 0.0, 0.3, 0.5, 0.2]), np.array([8.0, 2.0]), None, CFG)
    pts = check_points(cands.states, cands.controls, CFG.dt_s, "unicycle")
    assert pts.shape == (len(cands.states), 2 * view_steps(CFG), 2)
    assert np.array_equal(pts[:, 1::2], cands.states[:, 1:, :2])
    half = step_numpy(cands.states[:, 3], cands.controls[:, 3], CFG.dt_s / 2, "unicycle")[:, :2]
    assert np.array_equal(pts[:, 6], half)
    # every step is the model's own (the rollout is the MPC's dynamics, acceleration-clipped)
    assert np.allclose(step_numpy(cands.states[:, :-1], cands.controls, CFG.dt_s, "unicycle"), cands.states[:, 1:])
    dv = np.abs(np.diff(cands.controls[..., 0], axis=1))
    assert dv.max() <= CFG.robot.max_accel_mps2 * CFG.dt_s + 1e-9


def test_candidate_zero_is_the_mpc_plan_continued_and_the_view_is_the_configured_one() -> None:
    plan = _straight(1.0, CFG.horizon_steps)
    cands = make_candidates(np.array([0.0, 0.0, 0.0, 1.0, 0.0]), np.array([20.0, 0.0]), plan, CFG)
    assert view_steps(CFG) == 15 and cands.controls.shape[1] == 15
    assert np.array_equal(cands.controls[0, :10], plan) and np.array_equal(cands.first[0], plan[0])
    assert cands.states[0, -1, 0] == pytest.approx(6.0, abs=0.5)  # 4 m of plan, then on towards the goal
    speeds = {round(float(v), 3) for v in cands.first[1:, 0]}
    assert 0.0 in speeds and len(speeds) == CFG.sampling.n_speeds  # waiting is among the candidates


def test_the_clearance_kernels_are_the_brute_force_distances() -> None:
    rng = np.random.default_rng(3)
    pts, fut, radii = rng.normal(size=(4, 5, 2)), rng.normal(size=(3, 5, 6, 2)), rng.uniform(0.2, 0.4, 6)
    want = (np.linalg.norm(pts[:, None, :, None] - fut[None], axis=-1) - radii).min(-1)
    assert np.allclose(person_clearance(pts, fut, radii), want)
    seg, rad = rng.normal(size=(3, 5, 2, 4)), rng.uniform(0.2, 0.5, (3, 5, 2))
    got = capsule_clearance(pts, seg, rad)
    for b in range(3):
        for s in range(5):
            d = point_segment_distances(pts[:, s], seg[b, s]) - rad[b, s]
            assert np.allclose(got[:, b, s], d.min(-1))
    assert np.isinf(person_clearance(pts, fut[:, :, :0], radii[:0])).all()


def _verdict(plan: np.ndarray, pred: PedPrediction | None, goal=(10.0, 0.0), cfg: MPCConfig = CFG):
    state = np.array([0.0, 0.0, 0.0, float(plan[0, 0]), 0.0])
    cands = make_candidates(state, np.array(goal), plan, cfg)
    togo = np.linalg.norm(cands.states[:, -1, :2] - np.array(goal), axis=1)
    empty = PedPrediction(np.zeros((1, 12, 0, 2)), np.zeros(0), np.zeros(0, int), np.zeros(0, bool),
                          current=np.zeros((0, 2)), step_s=0.4)
    return cands, arbitrate(cands, togo, empty if pred is None else pred, None, cfg)


def test_an_empty_scene_keeps_the_mpc_plan() -> None:
    _, verdict = _verdict(_straight(1.2, 10), None)
    assert verdict.chosen == 0


def test_a_plan_into_a_standing_person_is_replaced_by_one_that_passes_clear() -> None:
    person = _people(np.array([[3.0, 0.0]]), np.zeros((1, 2)), k=20)
    cands, verdict = _verdict(_straight(1.2, 10), person)
    assert verdict.chosen != 0 and verdict.costs[verdict.chosen] < verdict.costs[0] - CFG.sampling.keep_plan_s
    path = check_points(cands.states[verdict.chosen: verdict.chosen + 1], cands.controls[verdict.chosen:
                                                                                         verdict.chosen + 1], 0.4,
                        "unicycle")[0]
    assert (np.linalg.norm(path - [3.0, 0.0], axis=-1) - 2 * RADIUS).min() > 0.0
    assert len(verdict.options) == CFG.sampling.n_options
    assert all(np.abs(cands.first[i] - cands.first[verdict.chosen]).max() > 0 for i in verdict.options)


def test_the_way_round_a_group_is_preferred_to_the_gap_between_its_members() -> None:
    """Two people standing 1.8 m apart across the robot's way: as a group the gap between them is closed (the
    chosen path goes round both); as two strangers the robot may take the gap."""
    start = np.array([[4.0, 0.9], [4.0, -0.9]])
    as_group = _people(start, np.zeros((2, 2)), groups=np.array([7, 7]), k=20)
    cands, verdict = _verdict(_straight(1.2, 10), as_group)
    y = cands.states[verdict.chosen, :, 1][np.abs(cands.states[verdict.chosen, :, 0] - 4.0) < 0.3]
    assert y.size and np.all(np.abs(y) > 0.9)  # beside the pair, not between its members
    _, apart = _verdict(_straight(1.2, 10), replace(as_group, group_ids=np.array([1, 2])))
    assert apart.chosen == 0  # the straight plan through the 1.2 m gap keeps its 0.3 m clearances


def test_the_planner_applies_and_stores_the_arbiters_choice_and_counts_it() -> None:
    planner = MPCPlanner(CFG)
    state = np.array([0.0, 0.0, 0.0, 1.2, 0.0])
    person = _people(np.array([[3.0, 0.0]]), np.zeros((1, 2)), k=20)
    into = PlanResult(np.array([1.2, 0.0]), np.zeros((11, 5)), _straight(1.2, 10), "solved")
    out = planner._arbitrate(into, state, np.array([10.0, 0.0]), np.array([10.0, 0.0]), person, None)
    assert out.arbitrated and not np.array_equal(out.controls, into.controls)
    assert np.array_equal(out.control, out.controls[0]) and out.states.shape == (11, 5)
    assert np.array_equal(planner._plan.controls, out.controls)  # the next solve's warm start
    assert len(planner._options) == CFG.sampling.n_options
    planner.stats.record(out)
    assert planner.stats.counts["arbitrated"] == 1
    result = planner.plan(state, np.array([10.0, 0.0]), person)  # the whole call: never raises, shield after it
    assert result.status == "solved" and np.isfinite(result.control).all()


def test_the_holonomic_robot_gets_direction_candidates() -> None:
    cfg = replace(CFG, robot=RobotConfig(model="holonomic"))
    state = np.array([0.0, 0.0, 1.0, 0.0])
    cands = make_candidates(state, np.array([10.0, 0.0]), np.tile([1.0, 0.0], (10, 1)), cfg)
    assert cands.states.shape[2] == 4 and (np.linalg.norm(cands.controls, axis=-1) <= 1.2 + 1e-9).all()
    person = _people(np.array([[2.5, 0.0]]), np.zeros((1, 2)), k=5)
    togo = np.linalg.norm(cands.states[:, -1, :2] - [10.0, 0.0], axis=1)
    assert arbitrate(cands, togo, person, None, cfg).chosen != 0


def test_the_way_left_follows_the_route_round_a_wall() -> None:
    router = Router(RouteConfig(), clearance_m=0.35)
    wall = np.array([[5.0, -3.0, 5.0, 3.0]])  # a wall across the way, open beyond y = +-3
    goal = np.array([10.0, 0.0])
    router.subgoal(np.zeros(2), goal, wall)
    left = router.cost_to_go(np.array([[0.0, 0.0], [10.0, 0.5]]), goal)
    assert left[0] > 12.0  # round the wall's end (2 x 6 m at least), not through it
    assert left[1] == pytest.approx(0.5, abs=0.35)  # the grid path zigzags near its end
    assert np.allclose(router.cost_to_go(np.array([[0.0, 0.0]]), np.array([1.0, 0.0])), 1.0)  # another goal


@pytest.mark.parametrize("bad", [{"horizon_s": 0.0}, {"n_speeds": 1}, {"first_steps": ()}, {"first_steps": (0,)},
                                 {"tail_speeds": (1.5,)}, {"cv_weight": 2.0}, {"margin_m": float("nan")},
                                 {"contact_cost_s": -1.0}])
def test_bad_sampling_settings_are_refused(bad: dict) -> None:
    with pytest.raises(ValueError, match="SamplingConfig"):
        SamplingConfig(**bad)


def test_leaving_out_the_people_out_of_reach_changes_no_cost() -> None:
    """The reach filter is exact: the costs with everyone and with only those within reach are the same."""
    import planner.sampling as sampling

    rng = np.random.default_rng(5)
    start = rng.uniform(-12.0, 12.0, (40, 2))
    crowd = _people(start, rng.normal(0.0, 1.0, (40, 2)), groups=np.repeat(np.arange(20), 2), k=6)
    crowd = replace(crowd, positions=crowd.positions + rng.normal(0.0, 0.2, crowd.positions.shape))
    cands = make_candidates(np.array([0.0, 0.0, 0.0, 1.0, 0.0]), np.array([10.0, 0.0]), _straight(1.0, 10), CFG)
    pts = check_points(cands.states, cands.controls, CFG.dt_s, "unicycle")
    times = CFG.dt_s / 2 * np.arange(1, pts.shape[1] + 1)
    fut, radii, _ = futures_at(crowd, times, True)
    kept = sampling.within_reach(fut, radii, crowd.group_ids, np.zeros(2), times, CFG)
    assert 0 < kept.sum() < 40
    everyone = sampling.within_reach
    try:
        sampling.within_reach = lambda fut, *a: np.ones(fut.shape[2], bool)
        full = sampling.risk_costs(pts, crowd, CFG, np.zeros(2))
    finally:
        sampling.within_reach = everyone
    assert np.allclose(sampling.risk_costs(pts, crowd, CFG, np.zeros(2)), full)
