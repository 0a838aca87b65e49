"""Crowd sources behind one small interface: the social-force simulator, or a replayed recording.

The env only talks to a `Crowd`. `SimCrowd` wraps `crowdsim.CrowdSimulator` (reactive pedestrians, optional
robot visibility); `envs.crowds.replay.ReplayCrowd` replays an ETH/UCY-format file (non-reactive pedestrians).
"""

from __future__ import annotations

import copy
import math
from typing import Protocol

import numpy as np

from crowdsim import CrowdSimulator, CrowdState, SimConfig
from crowdsim.scenarios import builtin_name


class Crowd(Protocol):
    """What the env needs from a crowd.

    Attributes:
        name: scenario name.
        walls: (W, 2, 2) static wall segments, m.
        bounds: (x_min, y_min, x_max, y_max) of the scene, m.
        dt_s: the time one `step()` advances, s.
        group_labels: whether `CrowdState.group_id` holds ground-truth groups (a simulated crowd; a recording with a
            group file). False: every pedestrian is its own group for want of labels, and group intrusion is not
            measured (None, printed "n/a").
    """

    name: str
    walls: np.ndarray
    bounds: tuple[float, float, float, float]
    dt_s: float
    group_labels: bool

    def reset(self, seed: int | None) -> CrowdState:
        """Start a new episode; the same seed gives the same crowd."""

    def step(self) -> CrowdState:
        """Advance `dt_s` seconds and return the new state."""

    def set_robot(self, pos: np.ndarray, vel: np.ndarray, radius_m: float) -> None:
        """Place the robot (pos (2,) m, vel (2,) m/s) for the next step."""

    def clear_robot(self) -> None:
        """Remove the robot from the crowd's world."""

    def robot_route(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A start (2,) and a goal (2,) across the scene for the robot, m."""

    def future(self, ped_ids: np.ndarray, times_s: np.ndarray) -> np.ndarray:
        """Privileged (the oracle's): where pedestrians `ped_ids` (N,) will be at `times_s` (T,) s from now, (T, N, 2)
        m, NaN where one is not in the scene then. The crowd itself is left exactly as it was."""


def clear_route(crowd: Crowd, pos: np.ndarray, vel: np.ndarray, radius: np.ndarray, need_m: float, lookahead_s: float,
                dt_s: float, rng: np.random.Generator, draws: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """A robot route (start (2,), goal (2,) m) of `crowd` whose start keeps `need_m` (centre to each pedestrian's
    surface) from the pedestrians at `pos` (n, 2) m with `radius` (n,) m now and, their velocities `vel` (n, 2) m/s
    held, over `lookahead_s` (checked every dt_s); after `draws` draws, the draw with the most clearance."""
    times = np.linspace(0.0, lookahead_s, 1 + math.ceil(lookahead_s / dt_s))
    future = pos[None] + times[:, None, None] * vel[None]  # (T, n, 2)
    best, best_gap = None, -np.inf
    for _ in range(draws):
        start, goal = crowd.robot_route(rng)
        gap = float((np.linalg.norm(future - start, axis=-1) - radius).min()) if len(pos) else np.inf
        if gap > best_gap:
            best, best_gap = (start, goal), gap
        if gap >= need_m:
            break
    start, goal = best
    return np.asarray(start, float), np.asarray(goal, float)


class SimCrowd:
    """`crowdsim.CrowdSimulator` stepped at the env's time step (`config.record_dt_s`)."""

    group_labels = True  # crowdsim labels every pedestrian's group

    def __init__(self, config: SimConfig, route_margin_m: float = 1.5) -> None:
        self.sim = CrowdSimulator(config)
        self.name = config.scenario
        self.walls = np.asarray(self.sim.scenario.walls, dtype=float).reshape(-1, 2, 2)
        self.bounds = tuple(float(b) for b in self.sim.scenario.bounds)
        self.dt_s = config.record_dt_s
        self.route_margin_m = route_margin_m

    def reset(self, seed: int | None) -> CrowdState:
        return self.sim.reset(seed)

    def step(self) -> CrowdState:
        return self.sim.step()

    def set_robot(self, pos: np.ndarray, vel: np.ndarray, radius_m: float) -> None:
        self.sim.set_robot(pos, vel, radius_m)

    def clear_robot(self) -> None:
        self.sim.clear_robot()

    def future(self, ped_ids: np.ndarray, times_s: np.ndarray) -> np.ndarray:
        """See `Crowd.future`: a fork of the simulation (its state and random generator) stepped ahead, the robot
        moving on at its current velocity (the pedestrians who see it react to that). With a robot the crowd does
        not see, this is the future that happens, exactly, unless two bodies touch at the fork (pymunk does not copy
        its contact cache: millimetres a step there). times_s: whole multiples of `dt_s`."""
        steps = np.rint(np.asarray(times_s, float) / self.dt_s).astype(np.int64)
        if np.any(steps < 1) or not np.allclose(steps * self.dt_s, times_s):
            raise ValueError(f"times_s must be positive whole multiples of dt_s = {self.dt_s}, got {times_s}")
        sim = self.sim
        fork = copy.deepcopy(sim, {id(sim.config): sim.config, id(sim.scenario): sim.scenario})  # those are read-only
        robot = fork.robot
        out = np.full((len(steps), len(ped_ids), 2), np.nan)
        want = {int(k): i for i, k in enumerate(steps)}
        for k in range(1, int(steps.max()) + 1):
            if robot is not None:
                fork.set_robot(robot.pos + k * self.dt_s * robot.vel, robot.vel, robot.radius_m)
            state = fork.step()
            if k in want:
                out[want[k]] = rows_of(state, ped_ids)
        return out

    def robot_route(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A start and a goal (2,) m for this scenario (see `ROUTES`, also for a built-in's file run by its path; a
        scenario file with a [robot] table: `area_route`; other scenarios: `side_to_side`)."""
        name = builtin_name(self.name) or self.name
        if name not in ROUTES and self.sim.scenario.robot_start is not None:
            return area_route(self, rng)
        return ROUTES.get(name, side_to_side)(self, rng)


def area_route(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A scenario file's [robot] table: the start drawn uniformly in its start area, the goal in its goal area;
    with both_ways, swapped in half of the episodes."""
    scen = crowd.sim.scenario
    (sx0, sy0, sx1, sy1), (gx0, gy0, gx1, gy1) = scen.robot_start, scen.robot_goal
    start = np.array([rng.uniform(sx0, sx1), rng.uniform(sy0, sy1)])
    goal = np.array([rng.uniform(gx0, gx1), rng.uniform(gy0, gy1)])
    return (goal, start) if scen.robot_both_ways and rng.uniform() < 0.5 else (start, goal)


def circle_route(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Opposite points of the crossing circle (CrowdNav's circle crossing)."""
    r = float(dict(crowd.sim.scenario.options).get("radius_m", 6.0))
    a = rng.uniform(0.0, 2.0 * np.pi)
    start = r * np.array([np.cos(a), np.sin(a)])
    return start, -start


def plaza_route(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Corner to opposite corner (3 m inside the walls, +-0.5 m jitter): the diagonal crosses every flow
    between the four gates, and the start stays clear of the gates where groups enter."""
    x0, y0, x1, y1 = crowd.bounds
    inset = 3.0
    lo, hi = np.array([x0 + inset, y0 + inset]), np.array([x1 - inset, y1 - inset])
    corner = rng.integers(4)
    cx, cy = corner % 2, corner // 2
    start = np.array([(lo, hi)[cx][0], (lo, hi)[cy][1]]) + rng.uniform(-0.5, 0.5, 2)
    goal = np.array([(hi, lo)[cx][0], (hi, lo)[cy][1]]) + rng.uniform(-0.5, 0.5, 2)
    return start, goal


def side_to_side(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Opposite sides of the bounds along the longer axis, `route_margin_m` inside, with a random lateral
    offset over the middle half; random direction."""
    x0, y0, x1, y1 = crowd.bounds
    m = crowd.route_margin_m
    long_x = (x1 - x0) >= (y1 - y0)
    lo, hi = (y0, y1) if long_x else (x0, x1)
    mid, quarter = 0.5 * (lo + hi), 0.25 * (hi - lo)
    a, b = rng.uniform(mid - quarter, mid + quarter, 2)
    if long_x:
        start, goal = np.array([x0 + m, a]), np.array([x1 - m, b])
    else:
        start, goal = np.array([a, y0 + m]), np.array([b, y1 - m])
    return (start, goal) if rng.uniform() < 0.5 else (goal, start)


def street_route(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Crossing: along the west-east street (lateral offset within its middle two thirds), either direction,
    through the intersection where the south-north flow crosses."""
    half = float(dict(crowd.sim.scenario.options).get("half_length_m", 10.0))
    w = float(dict(crowd.sim.scenario.options).get("width_m", 6.0)) / 2.0
    x = half - crowd.route_margin_m
    y0, y1 = rng.uniform(-w / 1.5, w / 1.5, 2)
    start, goal = np.array([-x, y0]), np.array([x, y1])
    return (start, goal) if rng.uniform() < 0.5 else (goal, start)


def corridor_route(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Corridor: end to end 2.5 m inside the corridor (clear of where the flows appear and leave), lateral
    offsets 1 m inside the walls, either direction, against one flow and with the other."""
    opt = dict(crowd.sim.scenario.options)
    length, width = float(opt.get("length_m", 20.0)), float(opt.get("width_m", 4.0))
    y0, y1 = rng.uniform(1.0, width - 1.0, 2)
    start, goal = np.array([2.5, y0]), np.array([length - 2.5, y1])
    return (start, goal) if rng.uniform() < 0.5 else (goal, start)


def door_route(crowd: SimCrowd, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Bottleneck: through the door between the room (at 0.7 of its depth, clear of the spawn area) and the open
    ground 3 m past the door, either direction (inwards it meets the evacuating crowd head-on)."""
    size = float(dict(crowd.sim.scenario.options).get("room_m", 8.0))
    mid = size / 2.0
    room = np.array([0.7 * size, rng.uniform(mid - 2.0, mid + 2.0)])
    outside = np.array([size + 3.0, rng.uniform(mid - 1.5, mid + 1.5)])
    return (room, outside) if rng.uniform() < 0.5 else (outside, room)


ROUTES = {"circle_crossing": circle_route, "plaza": plaza_route, "crossing": street_route,
          "corridor": corridor_route, "bottleneck": door_route}


def rows_of(state: CrowdState, ped_ids: np.ndarray) -> np.ndarray:
    """Positions (N, 2) m of pedestrians `ped_ids` (N,) in `state`, NaN for those not in it."""
    out = np.full((len(ped_ids), 2), np.nan)
    active = np.flatnonzero(state.active)
    order = np.argsort(state.ped_id[active], kind="stable")
    at, found = match_ids(state.ped_id[active][order], ped_ids)
    out[found] = state.pos[active[order[at]]]
    return out


def match_ids(known: np.ndarray, ped_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each of `ped_ids` (N,) stands in the ascending ids `known` (A,): (indices into `known` of those found,
    found mask (N,))."""
    at = np.minimum(np.searchsorted(known, ped_ids), max(len(known) - 1, 0))
    found = (known[at] == ped_ids) if len(known) else np.zeros(len(ped_ids), bool)
    return at[found], found
