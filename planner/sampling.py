"""The sampling arbiter: candidate plans rolled out and scored against every predicted sample over a longer view.

The MPC descends locally from one warm start against K representative samples over its 4 s horizon. Where every local
move looks unsafe (a dense two-way flow) the plan it returns is infeasible at its clearances and the shield drives.
The arbiter looks at many passing options at once, in numpy / numba, and lets the MPC keep its plan unless another
option is clearly better:

1. **Candidates** (C ~ 270): a first phase of a constant command (speed x yaw rate grid, or speed x direction for the
   holonomic robot) held for one of `first_steps` plan steps, then a second phase heading for the subgoal at one of
   `tail_speeds` (a proportional heading law); each rolled out with the MPC's own discrete dynamics
   (`planner.dynamics.step_numpy`, acceleration-clipped) on its 0.4 s steps over `horizon_s`. The MPC's own plan is
   candidate 0, continued by the same second phase past its horizon. Wait (speed 0) and turn-then-go are among them.
2. **Futures**: every predicted sample (K, T, N, 2), linear between its steps and continued past its last step at
   that step's velocity (each sample its own), plus the constant-velocity future of the last observed velocity when
   the prediction has a history; the robot is checked at the plan's knots and half-way between them.
3. **Cost** (seconds): the time the rest of the way would take from the candidate's end at top speed (along the
   global route when there is one), plus per future, averaged: `contact_cost_s` x exp(-t / tau_s) at its first
   contact with a person, and `shortfall_cost_sps` x the discounted shortfall below `margin_m` (people) and
   `group_margin_m` (the capsule of each predicted group of two or more, as the MPC's group regions, whose overlap
   costs as a contact does); a wall contact excludes a candidate unless every one has it.
4. **Choice**: the MPC's plan while its risk over its own horizon is at most `plan_risk_s` (the MPC is the better local
   optimiser where its plan is safe, and it plans again before its horizon ends); otherwise the cheapest candidate,
   unless the MPC's plan is within `keep_plan_s` of it. A chosen candidate's first `horizon_steps` steps become the
   plan (and the MPC's warm start at the next call); the next-best candidates with other first commands are handed to
   the safety shield as passing options.

Functions are pure: arrays in, arrays out; shapes and units in each docstring.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.config import MPCConfig, SamplingConfig
from planner.dynamics import clip_control, step_numpy
from planner.prediction import PedPrediction, current_positions
from planner.scene import group_capsules, wall_clearance
from planner.shield import command_grid

HEADING_GAIN = 2.5  # rad/s of yaw rate per rad of heading error in the second phase
WALL_COST_S = 1e6  # added to a candidate whose body touches a wall: chosen only if every one does


@dataclass(frozen=True)
class Candidates:
    """Rolled-out candidates: states (C, S + 1, state_dim) at the plan's knots, controls (C, S, 2) (each held dt_s),
    S = the view in plan steps; first (C, 2) the first-phase command (candidate 0: the MPC plan's first control)."""

    states: np.ndarray
    controls: np.ndarray
    first: np.ndarray


@dataclass(frozen=True)
class Verdict:
    """The arbiter's answer: index of the chosen candidate (0: the MPC's plan), costs (C,) s, and the indices of the
    next-best candidates with other first commands (for the safety shield), cheapest first."""

    chosen: int
    costs: np.ndarray
    options: np.ndarray


def view_steps(cfg: MPCConfig) -> int:
    """The arbiter's view in plan steps: at least the MPC's horizon."""
    assert cfg.sampling is not None
    return max(cfg.horizon_steps, int(round(cfg.sampling.horizon_s / cfg.dt_s)))


def first_commands(cfg: MPCConfig) -> np.ndarray:
    """(F, 2) the first-phase commands: the shield's command grid at the arbiter's resolution, without reversing."""
    sc, robot = cfg.sampling, cfg.robot
    assert sc is not None
    grid = command_grid(robot, sc.n_speeds, sc.n_turns)
    return grid[grid[:, 0] >= 0.0] if robot.model == "unicycle" else grid


def make_candidates(state: np.ndarray, target: np.ndarray, plan_controls: np.ndarray | None,
                    cfg: MPCConfig) -> Candidates:
    """All candidates from `state` (state_dim,) towards `target` (2,) m; `plan_controls` (H, 2): the MPC's plan
    (candidate 0; None: no plan, candidate 0 is then the plain second phase)."""
    sc, robot = cfg.sampling, cfg.robot
    assert sc is not None
    n = view_steps(cfg)
    cmds = first_commands(cfg)
    firsts, lengths, tails = [], [], []
    for k in sc.first_steps:
        for frac in sc.tail_speeds:
            firsts.append(cmds)
            lengths.append(np.full(len(cmds), min(k, n)))
            tails.append(np.full(len(cmds), frac))
    prefix = np.zeros((1 + sum(len(f) for f in firsts), n, 2))
    n_first = np.concatenate([[0], *lengths])
    tail = np.concatenate([[1.0], *tails]) * robot.max_speed_mps
    prefix[1:] = np.concatenate(firsts)[:, None, :]
    if plan_controls is not None:
        h = min(len(plan_controls), n)
        prefix[0, :h] = plan_controls[:h]
        n_first[0] = h
        last = np.asarray(plan_controls[h - 1], float)
        speed = float(last[0]) if robot.model == "unicycle" else float(np.hypot(*last))
        tail[0] = max(speed, 0.3 * robot.max_speed_mps)
    states, controls = rollout_two_phase(state, prefix, n_first, tail, target, cfg)
    first = controls[:, 0].copy() if plan_controls is None else np.vstack([plan_controls[:1], prefix[1:, 0]])
    return Candidates(states, controls, first)


def rollout_two_phase(state: np.ndarray, prefix: np.ndarray, n_first: np.ndarray, tail_mps: np.ndarray,
                      target: np.ndarray, cfg: MPCConfig) -> tuple[np.ndarray, np.ndarray]:
    """Roll out C candidates from `state` (state_dim,): commands prefix (C, S, 2) for their first n_first (C,) steps,
    then the heading law towards `target` (2,) m at tail_mps (C,) m/s; every command clipped to the acceleration
    bounds (`clip_control`) and stepped by `step_numpy` (dt_s). Returns states (C, S + 1, state_dim), the applied
    controls (C, S, 2)."""
    robot, dt = cfg.robot, cfg.dt_s
    c, n = prefix.shape[:2]
    x = np.tile(np.asarray(state, float), (c, 1))
    states, controls = np.empty((c, n + 1, x.shape[1])), np.empty((c, n, 2))
    states[:, 0] = x
    for k in range(n):
        u = np.where((k < n_first)[:, None], prefix[:, k], _heading_law(x, target, tail_mps, robot.model,
                                                                         robot.max_yaw_rate_radps))
        u = clip_control(x, u, dt, robot)
        x = step_numpy(x, u, dt, robot.model)
        states[:, k + 1], controls[:, k] = x, u
    return states, controls


def _heading_law(x: np.ndarray, target: np.ndarray, speed: np.ndarray, model: str, max_yaw: float) -> np.ndarray:
    """(C, 2) commands towards target (2,) from states x (C, state_dim) at speed (C,) m/s: unicycle, yaw rate
    proportional to the heading error and speed scaled by its cosine (no faster than the remaining distance allows in
    one second); holonomic, the velocity straight at it."""
    d = np.asarray(target, float) - x[:, :2]
    dist = np.hypot(d[:, 0], d[:, 1])
    v = np.minimum(speed, dist)
    if model != "unicycle":
        return d / np.maximum(dist, 1e-9)[:, None] * v[:, None]
    err = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - x[:, 2])))
    return np.stack([v * np.maximum(np.cos(err), 0.0), np.clip(HEADING_GAIN * err, -max_yaw, max_yaw)], axis=-1)


def check_points(states: np.ndarray, controls: np.ndarray, dt_s: float, model: str) -> np.ndarray:
    """Robot positions (C, 2 S, 2) at dt_s / 2, dt_s, ..., S dt_s: each knot and the exact half-way point of the step
    before it (the same control held half as long)."""
    half = step_numpy(states[:, :-1], controls, dt_s / 2, model)[..., :2]
    out = np.empty((states.shape[0], 2 * controls.shape[1], 2))
    out[:, 0::2], out[:, 1::2] = half, states[:, 1:, :2]
    return out


def futures_at(prediction: PedPrediction, times: np.ndarray, with_cv: bool) -> tuple[np.ndarray, np.ndarray, bool]:
    """Real people's futures (K [+1], T, n, 2) m at `times` (T,) s after now, their radii (n,) and whether the last
    future is the constant-velocity one (the last observed velocity held: `with_cv` and a history of >= 2 rows).
    Within the prediction linear between its steps; past its last step each sample goes on at its last step's
    velocity."""
    real = np.asarray(prediction.mask, bool)
    now = current_positions(prediction)[real]
    pos = np.asarray(prediction.positions, float)[:, :, real]
    k = pos.shape[0]
    known = np.concatenate([np.broadcast_to(now, (k, 1, *now.shape)), pos], axis=1)  # (K, T0 + 1, n, 2)
    step = prediction.step_s
    t_end = step * (known.shape[1] - 1)
    u = np.minimum(times, t_end) / step
    i = np.minimum(np.floor(u).astype(int), known.shape[1] - 2)
    w = (u - i)[None, :, None, None]
    inside = known[:, i] * (1.0 - w) + known[:, i + 1] * w
    velocity = (known[:, -1] - known[:, -2]) / step  # (K, n, 2)
    out = inside + np.maximum(times - t_end, 0.0)[None, :, None, None] * velocity[:, None]
    hist = prediction.history
    has_cv = with_cv and hist is not None and np.shape(hist)[0] >= 2
    if has_cv:
        hist = np.asarray(hist, float)[:, real]
        cv_vel = (hist[-1] - hist[-2]) / step
        out = np.concatenate([out, (now[None] + times[:, None, None] * cv_vel[None])[None]])
    return out, np.asarray(prediction.radii, float)[real], has_cv


def group_segments(futures: np.ndarray, radii: np.ndarray, group_ids: np.ndarray,
                   max_span_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Capsules of each group of >= 2 people: futures (F, T, n, 2), radii (n,), group ids (n,) -> axes (F, T, G, 4)
    and radii (F, T, G) m (`scene.group_capsules`); a capsule longer than max_span_m (members drifting apart) is
    dropped (radius -inf)."""
    ids, counts = np.unique(group_ids, return_counts=True)
    groups = [np.flatnonzero(group_ids == g) for g in ids[counts >= 2]]
    f, t = futures.shape[:2]
    seg, rad = np.zeros((f, t, len(groups), 4)), np.zeros((f, t, len(groups)))
    for j, members in enumerate(groups):
        a, b, r = group_capsules(futures[:, :, members], radii[members])
        seg[:, :, j, :2], seg[:, :, j, 2:] = a, b
        rad[:, :, j] = np.where(np.linalg.norm(b - a, axis=-1) > max_span_m, -np.inf, r)
    return seg, rad


def within_reach(fut: np.ndarray, radii: np.ndarray, gids: np.ndarray, robot_xy: np.ndarray, times: np.ndarray,
                 cfg: MPCConfig) -> np.ndarray:
    """(n,) bool: the people who can matter to some candidate: those some future (F, T, n, 2) m at times (T,) s brings
    within the larger margin of a point the robot (at robot_xy (2,) m now) could reach by then at top speed, with
    every member of a group of two or more of whom one can matter (a group's capsule reaches up to
    `max_group_span_m` beyond its members). The others cost nothing to any candidate: leaving them out changes no
    cost."""
    sc = cfg.sampling
    assert sc is not None
    _, inverse, counts = np.unique(gids, return_inverse=True, return_counts=True)
    pad = np.where(counts[inverse] >= 2, cfg.max_group_span_m, 0.0)
    gap = np.linalg.norm(fut - robot_xy, axis=-1) - cfg.robot.max_speed_mps * times[:, None]  # (F, T, n)
    near = gap.min(axis=(0, 1)) - radii - cfg.robot.radius_m - pad < max(sc.margin_m, sc.group_margin_m)
    return near | np.isin(inverse, inverse[near & (counts[inverse] >= 2)])


def risk_costs(points: np.ndarray, prediction: PedPrediction, cfg: MPCConfig, robot_xy: np.ndarray) -> np.ndarray:
    """Each candidate's expected risk (C,) s from its check points (C, T, 2) m (`check_points`), averaged over the
    predicted samples, the constant-velocity future (when there is one) weighted `cv_weight`: per future a contact
    costs `contact_cost_s` discounted at its first time, and every shortfall below the margins
    `shortfall_cost_sps` per m and s, discounted (module docstring)."""
    sc, robot = cfg.sampling, cfg.robot
    assert sc is not None
    step = cfg.dt_s / 2
    times = step * np.arange(1, points.shape[1] + 1)
    fut, radii, has_cv = futures_at(prediction, times, cfg.shield_cv)
    gids = np.asarray(prediction.group_ids)[np.asarray(prediction.mask, bool)]
    if fut.shape[2] == 0:
        return np.zeros(len(points))
    near = within_reach(fut, radii, gids, robot_xy, times, cfg)
    fut, radii, gids = fut[:, :, near], radii[near], gids[near]
    disc = np.exp(-times / sc.tau_s)
    from planner.kernels import capsule_clearance, person_clearance  # numba: `import planner` stays numpy + casadi

    ped = person_clearance(points, np.ascontiguousarray(fut), radii) - robot.radius_m  # (C, F, T)
    per = _exposure(ped, sc.margin_m, disc, sc, step)
    seg, rad = group_segments(fut, radii, gids, cfg.max_group_span_m)
    if seg.shape[2]:  # entering a group's region costs as a contact does
        per = per + _exposure(capsule_clearance(points, seg, rad) - robot.radius_m, sc.group_margin_m, disc, sc, step)
    if not has_cv:
        return per.mean(-1)
    return (1.0 - sc.cv_weight) * per[:, :-1].mean(-1) + sc.cv_weight * per[:, -1]


def _exposure(clear: np.ndarray, margin_m: float, disc: np.ndarray, sc: SamplingConfig, step_s: float) -> np.ndarray:
    """Per candidate and future (C, F) s, from clearances (C, F, T) m at times discounted by disc (T,): the contact cost
    discounted at the first overlap (clearance < 0), plus the discounted shortfall below margin_m (m s) priced."""
    hit = clear < 0.0
    first = np.where(hit.any(-1), disc[np.argmax(hit, axis=-1)], 0.0)
    shortfall = (np.maximum(margin_m - clear, 0.0) * disc).sum(-1)
    return sc.contact_cost_s * first + sc.shortfall_cost_sps * step_s * shortfall


def arbitrate(cands: Candidates, togo_m: np.ndarray, prediction: PedPrediction, walls: np.ndarray | None,
              cfg: MPCConfig) -> Verdict:
    """Score the candidates (their remaining way to the goal from each end, togo_m (C,) m) and choose (module
    docstring, 3-4)."""
    sc, robot = cfg.sampling, cfg.robot
    assert sc is not None
    points = check_points(cands.states, cands.controls, cfg.dt_s, robot.model)
    risk = risk_costs(points, prediction, cfg, cands.states[0, 0, :2])
    cost = togo_m / robot.max_speed_mps + risk + WALL_COST_S * (wall_clearance(points, walls) < robot.radius_m).any(-1)
    cost[0] -= sc.keep_plan_s
    own = risk_costs(points[:1, : 2 * cfg.horizon_steps], prediction, cfg, cands.states[0, 0, :2])[0]  # its horizon
    chosen = 0 if own <= sc.plan_risk_s else int(np.argmin(cost))
    cost[0] += sc.keep_plan_s
    order = np.argsort(cost, kind="stable")
    seen = [cands.first[chosen]]
    options = []
    for i in order:
        if len(options) >= sc.n_options or cost[i] >= WALL_COST_S:
            break
        if i != chosen and all(np.abs(cands.first[i] - f).max() > 1e-9 for f in seen):
            options.append(int(i))
            seen.append(cands.first[i])
    return Verdict(chosen, cost, np.array(options, int))
