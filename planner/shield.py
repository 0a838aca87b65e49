"""A sampling safety shield over the MPC's first control: a chance constraint checked at the control rate.

The MPC plans on 0.4 s knots with a few representative modes per pedestrian. Between its knots, and for the
samples it did not keep, a pedestrian can still reach the robot. The shield closes that gap cheaply, in numpy:

1. Candidates: the MPC's plan (its controls in turn) plus a grid of constant commands. For the unicycle
   this is forward speed x yaw rate; for the holonomic robot it is speed x direction, plus standing still.
2. Each candidate is held for ``shield_horizon_s``. It is rolled out at ``shield_dt_s`` (the env's control
   step) with the acceleration bounds applied, giving robot positions ``(C, T, 2)``.
3. Every predicted sample ``(K, T, N, 2)``, resampled from the prediction's step to ``shield_dt_s``, is one
   possible future. A candidate *hits* a sample when its clearance (centre distance - robot radius -
   pedestrian radius) drops below ``shield_margin_m`` at some time, or it comes that close to a wall. While no
   pedestrian is within reach over the look-ahead, walls are held to the MPC's own ``wall_margin_m`` instead: a wall
   is known exactly, and with the pedestrians' margin the shield vetoed every plan through a door that the MPC fits
   with its 0.05 m wall margin, so the robot stood at the jamb (crowdnav-tune, mpc-gpgraph: 84 -> 96 successes of
   140, collisions 23 -> 24). With someone within reach the wider margin stays: relaxing it there too let the robot
   press along the walls of dense corridors and collide more (23 -> 34; docs/decisions/planner-settings.md).
   Its risk is the fraction of samples it hits.
4. When the MPC's control has risk <= ``shield_max_risk``, it is kept. Otherwise the shield takes the candidate
   with the least time-discounted violation ``mean_k sum_t exp(-t / shield_tau_s) * relu(margin - clearance)``
   (m). Ties go to the candidate nearest the MPC's control. A candidate whose
   body would touch a wall within the look-ahead is taken only when every candidate would (before 2026-11-25 wall
   contact was one more soft violation, and in dense corridors the shield steered the robot into the wall).
   A commitment to the last replacement command and a cost for passing through predicted groups were tried and
   not adopted; they were removed on 2026-11-28 (docs/decisions/planner-settings.md, "Removed layers").

With ``shield_cv`` (default) the pedestrians' last observed velocity, held over the look-ahead, is one more
future that counts as certain (risk 1 when hit): at this range constant velocity is hard to beat, and a learned
predictor can under-estimate a fast walker. It needs ``prediction.history``.

Contacts that already exist now (t = 0) are not counted as hits, because no control can undo them within one
step. The discounted violation still prefers the candidate that moves away fastest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from planner.config import MPCConfig, RobotConfig
from planner.dynamics import _clip1, _clip_one, clip_control, step_numpy
from planner.prediction import PedPrediction, current_positions
from planner.scene import resample_in_time, wall_clearance

N_SPEEDS = 5  # candidate forward speeds (unicycle) / speed magnitudes (holonomic), rest excluded
N_TURNS = 9  # candidate yaw rates (unicycle) / directions (holonomic: 2 * N_TURNS)
DEVIATION_WEIGHT = 1e-3  # m of discounted violation per unit of normalised control change (tie-break)
SINC_EPS = float(np.finfo(float).eps)  # np.sinc's stand-in for 0 (numpy 2)
WALL_CONTACT_COST = 1e6  # added to a candidate whose body would touch a wall: chosen only if all would


@dataclass(frozen=True)
class ShieldVerdict:
    """control (2,): the control to apply; risk: the fraction of samples the MPC's control hits;
    replaced: True when the shield chose another control; chosen_risk: the chosen control's risk; option: the index of
    the alternative plan whose first control was chosen (-1: none)."""

    control: np.ndarray
    risk: float
    replaced: bool
    chosen_risk: float
    option: int = -1


def candidate_controls(robot: RobotConfig, preferred: np.ndarray) -> np.ndarray:
    """(C, 2) constant commands, the preferred (MPC) control first."""
    return np.vstack([np.asarray(preferred, float)[None], _command_grid(robot)])


@lru_cache(maxsize=16)
def _command_grid(robot: RobotConfig) -> np.ndarray:
    """The (C - 1, 2) grid of `candidate_controls` (read-only: one array per robot, built once)."""
    grid = command_grid(robot, N_SPEEDS, N_TURNS)
    grid.flags.writeable = False
    return grid


def command_grid(robot: RobotConfig, n_speeds: int, n_turns: int) -> np.ndarray:
    """(C, 2) constant commands: unicycle, n_speeds forward speeds (from -min_speed_mps to the top speed) x n_turns yaw
    rates; holonomic, standing still and n_speeds - 1 speeds x 2 n_turns directions (vx, vy)."""
    if robot.model == "unicycle":
        speeds = np.linspace(-robot.min_speed_mps, robot.max_speed_mps, n_speeds)
        turns = np.linspace(-robot.max_yaw_rate_radps, robot.max_yaw_rate_radps, n_turns)
        return np.stack(np.meshgrid(speeds, turns, indexing="ij"), axis=-1).reshape(-1, 2)
    speeds = np.linspace(0.0, robot.max_speed_mps, n_speeds)[1:]
    angles = np.linspace(-np.pi, np.pi, 2 * n_turns, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    return np.vstack([np.zeros((1, 2)), (speeds[:, None, None] * dirs[None]).reshape(-1, 2)])


def rollout_candidates(state: np.ndarray, commands: np.ndarray, dt_s: float, robot: RobotConfig) -> np.ndarray:
    """Robot positions (C, T, 2) at +dt_s .. +T dt_s applying commands (C, T, 2) in turn, each clipped to the
    acceleration bounds, from ``state`` (state_dim,)."""
    if robot.model == "unicycle":
        rollout = _rollout_one if len(commands) == 1 else _rollout_unicycle
        return rollout(np.asarray(state, float), np.asarray(commands, float), dt_s, robot)
    x = np.tile(np.asarray(state, float), (len(commands), 1))
    out = []
    for k in range(commands.shape[1]):
        x = step_numpy(x, clip_control(x, commands[:, k], dt_s, robot), dt_s, robot.model)
        out.append(x[:, :2])
    return np.stack(out, axis=1)


def rollout_constant(state: np.ndarray, commands: np.ndarray, n_steps: int, dt_s: float,
                     robot: RobotConfig) -> np.ndarray:
    """`rollout_candidates` of constant commands (C, 2), each held for n_steps: positions (C, n_steps, 2), the same
    floats. For the unicycle the speeds and yaw rates ramp independently, so each distinct value of each is ramped
    once, on Python floats (the shield's grid has 5 speeds and 9 yaw rates for its 45 commands)."""
    commands = np.asarray(commands, float)
    if robot.model != "unicycle":
        return rollout_candidates(state, np.repeat(commands[:, None], n_steps, axis=1), dt_s, robot)
    state = np.asarray(state, float)
    vels = np.empty((len(commands), n_steps, 2))
    limits = ((robot.max_accel_mps2 * dt_s, -robot.min_speed_mps, robot.max_speed_mps),
              (robot.max_yaw_accel_radps2 * dt_s, -robot.max_yaw_rate_radps, robot.max_yaw_rate_radps))
    for j, (accel, lo, hi) in enumerate(limits):
        ramps: dict[float, list[float]] = {}  # one ramp per distinct value (0.0 and -0.0 ramp alike: tested)
        column = commands[:, j].tolist()
        for u in column:
            if u not in ramps:
                ramps[u] = _ramp(float(state[3 + j]), u, n_steps, accel, lo, hi)
        vels[:, :, j] = [ramps[u] for u in column]
    return _pose_rollout(state, vels, dt_s)


def _ramp(v: float, u: float, n_steps: int, accel: float, lo: float, hi: float) -> list[float]:
    """One velocity component under a constant command u: `clip_control`'s update on floats (`_clip1`, as
    `_clip_one` does it), n_steps times; once an update leaves v as it was, it stays there."""
    out: list[float] = []
    while len(out) < n_steps:
        new = _clip1(v + _clip1(u - v, -accel, accel), lo, hi)
        if new == v and out:  # a fixed point (the sign of a zero aside, which the next update keeps too)
            return out + [new] * (n_steps - len(out))
        out.append(new)
        v = new
    return out


def _rollout_unicycle(state: np.ndarray, commands: np.ndarray, dt_s: float, robot: RobotConfig) -> np.ndarray:
    """`rollout_candidates` for the unicycle: the float operations of `clip_control` and `step_numpy` in the same
    order (so bit-identical). Only the velocities need a loop over the steps (each clipped against the last, with
    `np.clip`'s max-then-min spelt as ufuncs); the pose follows for all steps at once (`_pose_rollout`)."""
    c, n_steps = commands.shape[:2]
    vel = np.tile(np.asarray(state[3:5], float), (c, 1))
    accel = np.array([robot.max_accel_mps2, robot.max_yaw_accel_radps2]) * dt_s
    lo = np.array([-robot.min_speed_mps, -robot.max_yaw_rate_radps])
    hi = np.array([robot.max_speed_mps, robot.max_yaw_rate_radps])
    vels = np.empty((c, n_steps, 2))
    for k in range(n_steps):
        vel = np.minimum(np.maximum(vel + np.minimum(np.maximum(commands[:, k] - vel, -accel), accel), lo), hi)
        vels[:, k] = vel
    return _pose_rollout(state, vels, dt_s)


def _pose_rollout(state: np.ndarray, vels: np.ndarray, dt_s: float) -> np.ndarray:
    """Unicycle positions (C, T, 2) from `state` under the applied velocities (C, T, 2): `step_numpy`'s exact
    integration, with the heading and position updates as running sums from the start pose (`np.cumsum` adds in
    order, as the stepwise update does) and `np.sinc` (numpy 2) spelt out."""
    c, n_steps = vels.shape[:2]
    half = vels[..., 1] * dt_s / 2
    y = np.pi * (half / np.pi)
    y = np.where(y, y, SINC_EPS)
    dist = vels[..., 0] * dt_s * (np.sin(y) / y)
    runs = np.empty((c, n_steps + 1))  # a start value, then the increments: their running sum is the update
    runs[:, 0] = state[2]
    np.multiply(vels[:, :-1, 1], dt_s, out=runs[:, 1:n_steps])
    heading = np.cumsum(runs[:, :n_steps], axis=1) + half  # the heading before each step + half its turn
    out = np.empty(vels.shape)
    for i, trig in enumerate((np.cos, np.sin)):
        runs[:, 0] = state[i]
        np.multiply(dist, trig(heading), out=runs[:, 1:])
        out[..., i] = np.cumsum(runs, axis=1)[:, 1:]
    return out


def _rollout_one(state: np.ndarray, commands: np.ndarray, dt_s: float, robot: RobotConfig) -> np.ndarray:
    """`_rollout_unicycle` of one command sequence (1, T, 2) on Python floats (the shield's check of the plan alone,
    every step): the same operations (`clip_control`'s float twin `_clip_one`, `np.sinc` (numpy 2) spelled out, libm
    sin/cos), ~10x cheaper."""
    px, py, th, v0, v1 = (float(x) for x in state[:5])
    out = np.empty((1, len(commands[0]), 2))
    for k, (c0, c1) in enumerate(commands[0].tolist()):
        v0, v1 = _clip_one(v0, v1, c0, c1, dt_s, robot)  # `clip_control` on floats
        half = v1 * dt_s / 2
        y = math.pi * (half / math.pi)
        y = y if y != 0.0 else SINC_EPS
        dist = v0 * dt_s * (math.sin(y) / y)
        heading = th + half
        px, py, th = px + dist * math.cos(heading), py + dist * math.sin(heading), th + v1 * dt_s
        out[0, k] = px, py
    return out


def plan_commands(planned: np.ndarray, plan_dt_s: float, dt_s: float, n_steps: int) -> np.ndarray:
    """The MPC's planned controls (H, 2), each held plan_dt_s, as commands (n_steps, 2) every dt_s (the last
    control is held past the plan's end)."""
    idx = np.minimum((dt_s * np.arange(n_steps) / plan_dt_s + 1e-9).astype(int), len(planned) - 1)
    return np.asarray(planned, float)[idx]


def sample_futures(prediction: PedPrediction, dt_s: float, n_steps: int,
                   with_cv: bool) -> tuple[np.ndarray, np.ndarray, bool]:
    """Real pedestrians' futures (K [+1], n_steps, n, 2) at the shield's times, their radii (n,), and whether
    the last future is the constant-velocity one: the last observed velocity (last two history rows) held,
    appended when `with_cv` and the prediction has a history of >= 2 rows."""
    real = np.asarray(prediction.mask, bool)
    now = current_positions(prediction)[real]
    positions = np.asarray(prediction.positions, float)[:, :, real]
    futures = resample_in_time(positions, now, prediction.step_s, dt_s, n_steps)
    hist = prediction.history
    has_cv = with_cv and hist is not None and np.shape(hist)[0] >= 2
    if has_cv:
        hist = np.asarray(hist, float)[:, real]
        cv = cv_futures(now, (hist[-1] - hist[-2]) / prediction.step_s, dt_s, n_steps)
        futures = np.concatenate([futures, cv])
    return futures, np.asarray(prediction.radii)[real], has_cv


def cv_futures(now: np.ndarray, velocity: np.ndarray, dt_s: float, n_steps: int) -> np.ndarray:
    """The constant-velocity future (1, n_steps, n, 2) m at +dt_s .. +n_steps dt_s of pedestrians at `now` (n, 2) m
    walking at `velocity` (n, 2) m/s."""
    times = dt_s * np.arange(1, n_steps + 1)
    return (now[None] + times[:, None, None] * velocity[None])[None]


def horizon_steps(cfg: MPCConfig) -> int:
    """The shield's look-ahead in checks (T): `shield_horizon_s` / `shield_dt_s`, at least 1."""
    return max(1, int(round(cfg.shield_horizon_s / cfg.shield_dt_s)))


def within_reach(robot_xy: np.ndarray, futures: np.ndarray, radii: np.ndarray, cfg: MPCConfig) -> np.ndarray:
    """(n,) bool: the pedestrians that some future (K, T, n, 2) brings within the margin of a point the robot
    could reach by then from robot_xy (2,) at its top speed; the others cannot matter to any candidate."""
    if futures.shape[2] == 0:
        return np.zeros(0, bool)
    reach = cfg.robot.max_speed_mps * cfg.shield_dt_s * np.arange(1, futures.shape[1] + 1)  # (T,)
    gap = np.linalg.norm(futures - robot_xy, axis=-1) - radii - cfg.robot.radius_m - reach[:, None]  # (K, T, n)
    return (gap < cfg.shield_margin_m).any(axis=(0, 1))


def clearances(robot_xy: np.ndarray, futures: np.ndarray, radii: np.ndarray, robot_radius: float,
               walls: np.ndarray | None, wall_slack_m: float = 0.0, wall_m: np.ndarray | None = None) -> np.ndarray:
    """Smallest clearance (m) to any pedestrian or wall: robot (C, T, 2), futures (K, T, n, 2) -> (C, K, T). A wall's
    clearance counts `wall_slack_m` more (the shield's margin minus the MPC's wall margin: a wall is where it is).
    `wall_m` (C, T): the centre's distance to the nearest wall, when already computed (`wall_clearance`)."""
    c, t = robot_xy.shape[:2]
    if futures.shape[2]:
        dx = robot_xy[:, None, :, None, 0] - futures[None, ..., 0]  # (C, K, T, n)
        dy = robot_xy[:, None, :, None, 1] - futures[None, ..., 1]
        ped = (np.sqrt(dx * dx + dy * dy) - radii).min(-1) - robot_radius
    else:
        ped = np.full((c, max(futures.shape[0], 1), t), np.inf)
    wall = (wall_clearance(robot_xy, walls) if wall_m is None else wall_m) - robot_radius + wall_slack_m
    return np.minimum(ped, wall[:, None, :])


def touches_wall(robot_xy: np.ndarray | None, walls: np.ndarray | None, robot_radius: float,
                 wall_m: np.ndarray | None = None) -> np.ndarray:
    """(C,) bool: the rollouts (C, T, 2) whose body touches a wall at some step. A wall is where it is, not a
    prediction: such a command is chosen only when every candidate touches one. `wall_m` (C, T): the centres'
    distances to the nearest wall when already computed (`wall_clearance`; robot_xy and walls are then not read)."""
    return ((wall_clearance(robot_xy, walls) if wall_m is None else wall_m) < robot_radius).any(-1)


def shield_control(state: np.ndarray, planned: np.ndarray, prediction: PedPrediction,
                   walls: np.ndarray | None, cfg: MPCConfig,
                   alternatives: np.ndarray | None = None) -> ShieldVerdict:
    """Check the plan's controls (H, 2) (each held ``cfg.dt_s``; the first is the one to apply) from ``state``
    (state_dim,) against every predicted sample and wall; replace its first control by a constant command
    when its risk exceeds ``cfg.shield_max_risk`` (see the module docstring). ``alternatives`` (A, H, 2):
    other plans from the same state (the guidance layer's other passing options), best first: when the plan fails
    the check, the first of them that passes it gives the control, before any constant command is tried."""
    futures, radii, has_cv = sample_futures(prediction, cfg.shield_dt_s, horizon_steps(cfg), cfg.shield_cv)
    return shield_futures(state, planned, futures, radii, walls, cfg, certain_last=has_cv, alternatives=alternatives)


def shield_futures(state: np.ndarray, planned: np.ndarray, futures: np.ndarray, radii: np.ndarray,
                   walls: np.ndarray | None, cfg: MPCConfig, certain_last: bool = False,
                   alternatives: np.ndarray | None = None) -> ShieldVerdict:
    """`shield_control` on the pedestrians' futures (K, T, n, 2) m at the shield's own times (+shield_dt_s ..
    +T shield_dt_s, T = `horizon_steps(cfg)`) with radii (n,) m; `certain_last`: the last future counts as certain
    (a hit is risk 1: the constant-velocity one). With that one future alone, the risk is 0 or 1. `alternatives`: as
    in `shield_control`."""
    n_steps = horizon_steps(cfg)
    planned = np.asarray(planned, float)
    cands = candidate_controls(cfg.robot, planned[0])
    near = within_reach(np.asarray(state, float)[:2], futures, radii, cfg)
    # walls: the MPC's wall margin while nobody is within reach, else the pedestrians' (see the module docstring)
    wall_slack = 0.0 if near.any() else cfg.shield_margin_m - (cfg.wall_clearance_m - cfg.robot.radius_m)
    futures, radii = futures[:, :, near], radii[near]
    n_sampled = len(futures) - certain_last

    def check(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wall distances (c, T), shortfalls below the margin (c, K, T) and risks (c,) of roll-outs (c, T, 2)."""
        wall_m = wall_clearance(xy, walls)
        short = cfg.shield_margin_m - clearances(xy, futures, radii, cfg.robot.radius_m, walls, wall_slack, wall_m)
        hit = (short > 0).any(-1)  # (c, K)
        risk = hit[:, :n_sampled].mean(-1) if n_sampled else np.zeros(len(hit))
        if certain_last:  # the constant-velocity future must be avoided outright
            risk = np.maximum(risk, hit[:, -1])
        return wall_m, short, risk

    # the plan alone first: when it passes (most steps), the grid of alternatives is never rolled out
    if len(planned) == 1:  # one command held (a shielded agent's): the cheaper constant roll-out, the same floats
        xy0 = rollout_constant(state, planned, n_steps, cfg.shield_dt_s, cfg.robot)
    else:
        plan = plan_commands(planned, cfg.dt_s, cfg.shield_dt_s, n_steps)[None]
        xy0 = rollout_candidates(state, plan, cfg.shield_dt_s, cfg.robot)
    wall0, short0, risk0 = check(xy0)
    if risk0[0] <= cfg.shield_max_risk:
        return ShieldVerdict(cands[0].copy(), float(risk0[0]), False, float(risk0[0]))
    if alternatives is not None and len(alternatives):
        plans = np.stack([plan_commands(alt, cfg.dt_s, cfg.shield_dt_s, n_steps) for alt in alternatives])
        alt_risk = check(rollout_candidates(state, plans, cfg.shield_dt_s, cfg.robot))[2]
        passing = np.flatnonzero(alt_risk <= cfg.shield_max_risk)
        if passing.size:
            i = int(passing[0])
            return ShieldVerdict(np.asarray(alternatives[i][0], float).copy(), float(risk0[0]), True,
                                 float(alt_risk[i]), i)
    xy = rollout_constant(state, cands[1:], n_steps, cfg.shield_dt_s, cfg.robot)
    wall_m, short, risk = check(xy)
    wall_m, short, risk = (np.concatenate(pair) for pair in ((wall0, wall_m), (short0, short), (risk0, risk)))
    weights = np.exp(-cfg.shield_dt_s * np.arange(1, n_steps + 1) / cfg.shield_tau_s)
    violation = (np.maximum(short, 0.0) * weights).sum(-1).mean(-1)
    scale = np.array([cfg.robot.max_speed_mps, cfg.robot.max_yaw_rate_radps if cfg.robot.model == "unicycle"
                      else cfg.robot.max_speed_mps])
    cost = violation + DEVIATION_WEIGHT * (((cands - cands[0]) / scale) ** 2).sum(-1)
    cost = cost + WALL_CONTACT_COST * touches_wall(None, walls, cfg.robot.radius_m, wall_m)
    best = int(np.argmin(cost))
    return ShieldVerdict(cands[best].copy(), float(risk[0]), best != 0, float(risk[best]))
