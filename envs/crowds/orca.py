"""`OrcaCrowd`: CrowdNav's crowd (ORCA humans crossing a circle) behind the env's `Crowd` interface.

It exists so that results compare with the CrowdNav literature (SARL, CrowdNav++); the default crowd stays the
social-force simulator (`envs.crowds.crowd.SimCrowd`). What it reproduces (vita-epfl/CrowdNav, `crowd_sim.py`,
`policy/orca.py`, `configs/env.config`; README "CrowdNav's settings" lists what differs):

- circle crossing: each human starts on a circle of radius `radius_m` (scenario option) plus a uniform offset per
  axis (`start_noise`: +-v_pref/2 m, CrowdNav; or 0 to 2 m, CrowdNav++'s `crowd_sim_var_num.py`), and walks to the
  point opposite its start; a start is redrawn while it is closer than r_h + r_other + `spawn_gap_m` to the start
  or goal of the robot or of a human placed before it;
- every `params.time_step_s` each human takes the ORCA velocity towards its goal (preferred velocity:
  `envs.crowds.rvo.pref_velocity`), avoiding every other human and, when `robot_visible`, the robot; it then walks in a
  straight line at that velocity. By default a human who arrives stays at its goal (CrowdNav's test episodes);
- CrowdNav++'s livelier humans, each off by default (its `crowd_nav/configs/config.py` and `crowd_sim_pred.py`):
  `randomize_attributes` draws every human's radius from U(0.3, 0.5) m and v_pref from U(0.5, 1.5) m/s;
  every `goal_change_period_s` each human, with chance `goal_change_chance`, takes a new goal on the circle (a
  uniform angle plus +-v_pref/2 m per axis); with `respawn_on_arrival` a human within its radius of its goal is
  replaced by a new one (a new id, new attributes, a new start with its goal opposite). New goals and starts keep
  r_h + r_other + `spawn_gap_m` from every human's position and goal and from the robot's route ends. CrowdNav++
  checks the robot's position now instead; the route ends keep the crowd the same for every policy (the same seed,
  the same crowd, as paired comparisons and the oracle's future need);
- the robot's route: "fixed" (CrowdNav: (0, -r) to (0, r)), or "random" (CrowdNav++'s holonomic robot: start and
  goal uniform in the square of half-width `route_half_width_m`, by default r, at least `route_min_m` apart),
  drawn before the humans.

Groups: ORCA humans walk alone. `group_id` is the truth, every human its own group, so `group_labels` is True and
group intrusion, measured, is 0 by construction (a group of one is no region).
No walls: `CrowdNavConfig` refuses crowd model "orca" in any scenario but circle_crossing.
ORCA holds no state between steps (`envs.crowds.rvo`): the crowd is its arrays, so `future` steps a copy of them.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from crowdsim import CrowdState
from envs.crowds.crowd import rows_of
from envs.crowds.rvo import OrcaParams, load_pyrvo, orca_velocities, pref_velocity

if TYPE_CHECKING:
    from planner import RobotConfig

ROBOT_ROUTES = ("fixed", "random")
START_NOISES = ("centred", "positive")
RADIUS_RANGE_M = (0.3, 0.5)  # CrowdNav++ `Agent.sample_random_attributes`
V_PREF_RANGE_MPS = (0.5, 1.5)
POSITIVE_NOISE_M = 2.0  # CrowdNav++ `generate_circle_crossing_human`: noise_range
DEFAULT_RADIUS_M = 4.0  # CrowdNav's circle (the social-force circle_crossing defaults to 6 m)
MAX_DRAWS = 10_000


@dataclass(frozen=True)
class OrcaCrowdConfig:
    """CrowdNav's human settings (defaults: `crowd_nav/configs/env.config` and `policy/orca.py`).

    human_radius_m: body radius of every human, m.
    human_v_pref_mps: preferred (and maximum) speed of every human, m/s.
    neighbor_dist_m, max_neighbors, time_horizon_s, time_horizon_obst_s, safety_space_m: ORCA's
        (`envs.crowds.rvo.OrcaParams`).
    time_step_s: ORCA's decision period (CrowdNav's env step); a whole multiple of the env's dt_s, s.
    spawn_gap_m: extra surface gap between a new start and the others' starts and goals (CrowdNav's
        discomfort_dist), m.
    robot_route: "fixed" or "random" (module docstring).
    route_min_m: least start-goal distance of a "random" robot route, m.
    route_half_width_m: half-width of the square a "random" route is drawn in, m; 0: the circle's radius.
    start_noise: "centred" (CrowdNav) or "positive" (CrowdNav++), the offset of a start from the circle.
    randomize_attributes: every human's radius and v_pref drawn (CrowdNav++), instead of the two fields above.
    goal_change_period_s: every this long each human may take a new goal (0: never), s.
    goal_change_chance: the chance that it does, in [0, 1].
    respawn_on_arrival: a human who reaches its goal is replaced by a new one.
    """

    human_radius_m: float = 0.3
    human_v_pref_mps: float = 1.0
    # ORCA's settings: `envs.crowds.rvo.OrcaParams` owns CrowdNav's values
    neighbor_dist_m: float = OrcaParams.neighbor_dist_m
    max_neighbors: int = OrcaParams.max_neighbors
    time_horizon_s: float = OrcaParams.time_horizon_s
    time_horizon_obst_s: float = OrcaParams.time_horizon_obst_s
    safety_space_m: float = OrcaParams.safety_space_m
    time_step_s: float = OrcaParams.time_step_s
    spawn_gap_m: float = 0.2
    robot_route: str = "fixed"
    route_min_m: float = 6.0
    route_half_width_m: float = 0.0
    start_noise: str = "centred"
    randomize_attributes: bool = False
    goal_change_period_s: float = 0.0
    goal_change_chance: float = 0.5
    respawn_on_arrival: bool = False

    def __post_init__(self) -> None:
        self.params  # noqa: B018  (validates the ORCA fields)
        for name in ("human_radius_m", "human_v_pref_mps"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"OrcaCrowdConfig.{name} must be a positive finite number, got {value!r}")
        for name in ("spawn_gap_m", "route_min_m", "route_half_width_m", "goal_change_period_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ValueError(f"OrcaCrowdConfig.{name} must be finite and >= 0, got {value!r}")
        if self.robot_route not in ROBOT_ROUTES:
            raise ValueError(f"unknown robot_route {self.robot_route!r}; valid: {', '.join(ROBOT_ROUTES)}")
        if self.start_noise not in START_NOISES:
            raise ValueError(f"unknown start_noise {self.start_noise!r}; valid: {', '.join(START_NOISES)}")
        if not (isinstance(self.goal_change_chance, int | float) and 0.0 <= self.goal_change_chance <= 1.0):
            raise ValueError(f"OrcaCrowdConfig.goal_change_chance must be in [0, 1], got {self.goal_change_chance!r}")
        for name in ("randomize_attributes", "respawn_on_arrival"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"OrcaCrowdConfig.{name} must be true or false, got {getattr(self, name)!r}")

    @property
    def params(self) -> OrcaParams:
        return OrcaParams(self.neighbor_dist_m, self.max_neighbors, self.time_horizon_s, self.time_horizon_obst_s,
                          self.safety_space_m, self.time_step_s)


class OrcaSetting(Protocol):
    """What `OrcaCrowd` reads of a config (`envs.config.CrowdNavConfig` is one): `orca`, n_pedestrians, the scenario's
    name and options (`radius_m`, m), robot_visible, the robot's body (`robot.radius_m`, m) and the env step dt_s, s."""

    orca: OrcaCrowdConfig
    n_pedestrians: int
    scenario: str
    scenario_options: tuple[tuple[str, float], ...]
    robot_visible: bool
    robot: RobotConfig
    dt_s: float


class OrcaCrowd:
    """N ORCA humans crossing a circle (module docstring), stepped at the env's dt_s."""

    group_labels = True  # the truth: every human walks alone

    def __init__(self, config: OrcaSetting) -> None:
        load_pyrvo()  # a missing package fails here, once, before any episode
        self.cfg = config.orca
        self.params = self.cfg.params
        self.n = config.n_pedestrians
        self.radius_m = float(dict(config.scenario_options).get("radius_m", DEFAULT_RADIUS_M))
        self.robot_visible = config.robot_visible
        self.robot_radius_m = config.robot.radius_m
        self.name = config.scenario
        self.dt_s = config.dt_s
        self.ticks_per_decision = round(self.cfg.time_step_s / self.dt_s)
        period = self.cfg.goal_change_period_s
        self.ticks_per_goal_change = round(period / self.dt_s) if period > 0 else 0
        top_speed = V_PREF_RANGE_MPS[1] if self.cfg.randomize_attributes else self.cfg.human_v_pref_mps
        half = self.radius_m + max(top_speed / 2, POSITIVE_NOISE_M if self.cfg.start_noise == "positive" else 0) + 1.0
        self.walls = np.zeros((0, 2, 2))
        self.bounds = (-half, -half, half, half)
        self.rng = np.random.default_rng(0)
        self.pos = np.zeros((self.n, 2))
        self.vel = np.zeros((self.n, 2))
        self.goal = np.zeros((self.n, 2))
        self.radius = np.full(self.n, self.cfg.human_radius_m)
        self.v_pref = np.full(self.n, self.cfg.human_v_pref_mps)
        self.ped_id = np.arange(self.n)
        self.route = (np.zeros(2), np.zeros(2))
        self.robot: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # pos, velocity now, velocity before
        self.tick = 0

    # ------------------------------------------------------------------------------------------ Crowd
    def reset(self, seed: int | None) -> CrowdState:
        """The robot's route, then the humans on the circle (module docstring); the same seed, the same crowd."""
        self.rng = np.random.default_rng(seed)
        self.route = self._draw_route()
        self.pos, self.goal = np.zeros((0, 2)), np.zeros((0, 2))
        self.radius, self.v_pref = np.zeros(0), np.zeros(0)
        for _ in range(self.n):
            r, v = self._attributes()
            p = self._clear_point(r, v, self.cfg.start_noise, "start")
            self.pos, self.goal = np.vstack([self.pos, p]), np.vstack([self.goal, -p])
            self.radius, self.v_pref = np.append(self.radius, r), np.append(self.v_pref, v)
        self.vel = np.zeros((self.n, 2))
        self.ped_id = np.arange(self.n)
        self.robot, self.tick = None, 0
        return self.state()

    def step(self) -> CrowdState:
        """Advance dt_s: on a decision tick every human takes its ORCA velocity; then all walk straight; then, on a
        decision tick, CrowdNav++'s goal changes and arrivals (module docstring)."""
        if self.tick % self.ticks_per_decision == 0:
            self.vel = self._decide()
        self.pos = self.pos + self.dt_s * self.vel
        self.tick += 1
        if self.ticks_per_goal_change and self.tick % self.ticks_per_goal_change == 0:
            self._change_goals()
        if self.cfg.respawn_on_arrival and self.tick % self.ticks_per_decision == 0:
            self._respawn_arrived()
        return self.state()

    def set_robot(self, pos: np.ndarray, vel: np.ndarray, radius_m: float) -> None:
        """The robot at `pos` (2,) m moving at `vel` (2,) m/s this step. Humans who see it read its position now and
        its velocity over the previous step (what they could have observed; CrowdNav's robot state)."""
        before = self.robot[1] if self.robot is not None else np.zeros(2)
        self.robot = (np.asarray(pos, float).copy(), np.asarray(vel, float).copy(), before)
        self.robot_radius_m = float(radius_m)

    def clear_robot(self) -> None:
        self.robot = None

    def robot_route(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The route drawn at reset (the humans were placed clear of it); `rng` is not used."""
        return self.route[0].copy(), self.route[1].copy()

    def future(self, ped_ids: np.ndarray, times_s: np.ndarray) -> np.ndarray:
        """See `Crowd.future`: a copy of the crowd stepped ahead, the robot moving on at its current velocity. With a
        robot the humans do not see, exactly the future that happens (the copy draws from a copy of the random
        generator). NaN where a human will have been replaced. times_s: whole multiples of dt_s."""
        steps = np.rint(np.asarray(times_s, float) / self.dt_s).astype(np.int64)
        if np.any(steps < 1) or not np.allclose(steps * self.dt_s, times_s):
            raise ValueError(f"times_s must be positive whole multiples of dt_s = {self.dt_s}, got {times_s}")
        fork = copy.copy(self)  # shares the arrays: a change writes only into a fresh copy of them
        fork.rng = copy.deepcopy(self.rng)
        out = np.full((len(steps), len(ped_ids), 2), np.nan)
        want = {int(k): i for i, k in enumerate(steps)}
        robot = self.robot
        for k in range(1, int(steps.max()) + 1):
            if robot is not None:
                fork.set_robot(robot[0] + k * self.dt_s * robot[1], robot[1], self.robot_radius_m)
            state = fork.step()
            if k in want:
                out[want[k]] = rows_of(state, ped_ids)
        return out

    def state(self) -> CrowdState:
        n = self.n
        return CrowdState(pos=self.pos.copy(), vel=self.vel.copy(), goal=self.goal.copy(), radius=self.radius.copy(),
                          group_id=np.arange(n), ped_id=self.ped_id.copy(), active=np.ones(n, bool),
                          label=self.ped_id.copy(), frame=self.tick, time_s=self.tick * self.dt_s)

    # ------------------------------------------------------------------------------------------ internals
    def _decide(self) -> np.ndarray:
        """The humans' ORCA velocities (N, 2) m/s from the current positions and velocities."""
        pos, vel, radius, speed = self.pos, self.vel, self.radius, self.v_pref
        pref = pref_velocity(pos, self.goal, speed)
        if self.robot_visible and self.robot is not None:
            rpos, _, rvel = self.robot
            pos, vel = np.vstack([pos, rpos]), np.vstack([vel, rvel])
            pref, speed = np.vstack([pref, rvel]), np.append(speed, max(float(np.linalg.norm(rvel)), 1e-6))
            radius = np.append(radius, self.robot_radius_m)
        return orca_velocities(pos, vel, pref, radius, speed, self.params)[: self.n]

    def _attributes(self) -> tuple[float, float]:
        """A new human's radius (m) and v_pref (m/s): drawn with `randomize_attributes`, else the configured ones."""
        if self.cfg.randomize_attributes:
            return float(self.rng.uniform(*RADIUS_RANGE_M)), float(self.rng.uniform(*V_PREF_RANGE_MPS))
        return self.cfg.human_radius_m, self.cfg.human_v_pref_mps

    def _offset(self, v_pref: float, noise: str) -> np.ndarray:
        """A point on the circle plus its noise (2,) m: "centred" +-v_pref/2 per axis, "positive" 0-2 m."""
        a = self.rng.uniform(0.0, 2.0 * np.pi)
        extra = self.rng.uniform(size=2) * POSITIVE_NOISE_M if noise == "positive" \
            else (self.rng.uniform(size=2) - 0.5) * v_pref
        return self.radius_m * np.array([np.cos(a), np.sin(a)]) + extra

    def _clear_point(self, radius: float, v_pref: float, noise: str, what: str, skip: int = -1) -> np.ndarray:
        """A point drawn by `_offset` until it keeps radius + r_other + spawn_gap_m from the robot's route ends and
        every other human's position and goal (row `skip` left out); ValueError after MAX_DRAWS draws."""
        keep = np.arange(len(self.pos)) != skip
        others = np.vstack([*self.route, self.pos[keep], self.goal[keep]])
        radii = np.concatenate([[self.robot_radius_m] * 2, self.radius[keep], self.radius[keep]])
        need = radius + radii + self.cfg.spawn_gap_m
        for _ in range(MAX_DRAWS):
            p = self._offset(v_pref, noise)
            if np.all(np.linalg.norm(p - others, axis=1) >= need):
                return p
        raise ValueError(f"cannot place a human's {what} on a {self.radius_m} m circle {self.cfg.spawn_gap_m} m clear "
                         f"of {len(self.pos)} others")

    def _change_goals(self) -> None:
        """Each human, with chance goal_change_chance, takes a new goal (CrowdNav++ `update_human_goals_randomly`)."""
        self.goal = self.goal.copy()  # a fresh array: a fork made by `future` keeps the old one
        for i in range(self.n):
            if self.rng.uniform() <= self.cfg.goal_change_chance:
                self.goal[i] = self._clear_point(self.radius[i], self.v_pref[i], "centred", "goal", skip=i)

    def _respawn_arrived(self) -> None:
        """Every human within its radius of its goal becomes a new one (CrowdNav++ `crowd_sim_pred.step`)."""
        arrived = np.flatnonzero(np.linalg.norm(self.goal - self.pos, axis=1) < self.radius)
        if arrived.size:  # fresh arrays: a fork made by `future` keeps the old ones
            self.pos, self.goal, self.vel = self.pos.copy(), self.goal.copy(), self.vel.copy()
            self.radius, self.v_pref, self.ped_id = self.radius.copy(), self.v_pref.copy(), self.ped_id.copy()
        for i in arrived:
            r, v = self._attributes()
            p = self._clear_point(r, v, self.cfg.start_noise, "start", skip=i)
            self.pos[i], self.goal[i], self.vel[i] = p, -p, 0.0
            self.radius[i], self.v_pref[i] = r, v
            self.ped_id[i] = int(self.ped_id.max()) + 1

    def _draw_route(self) -> tuple[np.ndarray, np.ndarray]:
        r = self.radius_m
        if self.cfg.robot_route == "fixed":
            return np.array([0.0, -r]), np.array([0.0, r])
        half = self.cfg.route_half_width_m or r
        for _ in range(MAX_DRAWS):
            start, goal = self.rng.uniform(-half, half, 2), self.rng.uniform(-half, half, 2)
            if np.linalg.norm(goal - start) >= self.cfg.route_min_m:
                return start, goal
        raise ValueError(f"no robot route {self.cfg.route_min_m} m long fits in a square of half-width {half} m")
