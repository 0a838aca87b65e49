"""`OrcaCrowd`: CrowdNav's crowd (ORCA humans crossing a circle) behind the env's `Crowd` interface.

It exists so that results compare with the CrowdNav literature (SARL, CrowdNav++); the default crowd stays the
social-force simulator (`envs.crowd.SimCrowd`). What it reproduces (vita-epfl/CrowdNav, `crowd_sim.py`,
`policy/orca.py`, `configs/env.config`; README "CrowdNav's settings" lists what differs):

- circle crossing: each human starts on a circle of radius `radius_m` (scenario option) plus a uniform offset of
  +-v_pref/2 m per axis, and walks to the point opposite its start; a start is redrawn while it is closer than
  r_h + r_other + `spawn_gap_m` to the start or goal of the robot or of a human placed before it;
- every `params.time_step_s` each human takes the ORCA velocity towards its goal (preferred velocity:
  `envs.rvo.pref_velocity`), avoiding every other human and, when `robot_visible`, the robot; it then walks in a
  straight line at that velocity. A human who arrives stays at its goal (CrowdNav's test episodes);
- the robot's route: "fixed" (CrowdNav: (0, -r) to (0, r)), or "random" (CrowdNav++'s holonomic robot: start and
  goal uniform in the square of half-width r, at least `route_min_m` apart), drawn before the humans.

Groups: ORCA humans walk alone. `group_id` is the truth, every human its own group, so `group_labels` is True and
group intrusion, measured, is 0 by construction (a group of one is no region).
No walls: `CrowdNavConfig` refuses crowd model "orca" in any scenario but circle_crossing.
ORCA holds no state between steps (`envs.rvo`): the crowd is its arrays, so `future` steps a copy of them.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from crowdsim import CrowdState
from envs.crowd import rows_of
from envs.rvo import OrcaParams, load_pyrvo, orca_velocities, pref_velocity

if TYPE_CHECKING:
    from envs.config import CrowdNavConfig

ROBOT_ROUTES = ("fixed", "random")
DEFAULT_RADIUS_M = 4.0  # CrowdNav's circle (the social-force circle_crossing defaults to 6 m)
MAX_DRAWS = 10_000


@dataclass(frozen=True)
class OrcaCrowdConfig:
    """CrowdNav's human settings (defaults: `crowd_nav/configs/env.config` and `policy/orca.py`).

    human_radius_m: body radius of every human, m.
    human_v_pref_mps: preferred (and maximum) speed of every human, m/s.
    neighbor_dist_m, max_neighbors, time_horizon_s, time_horizon_obst_s, safety_space_m: ORCA's (`envs.rvo.OrcaParams`).
    time_step_s: ORCA's decision period (CrowdNav's env step); a whole multiple of the env's dt_s, s.
    spawn_gap_m: extra surface gap between a new start and the others' starts and goals (CrowdNav's
        discomfort_dist), m.
    robot_route: "fixed" or "random" (module docstring).
    route_min_m: least start-goal distance of a "random" robot route, m.
    """

    human_radius_m: float = 0.3
    human_v_pref_mps: float = 1.0
    # ORCA's settings: `envs.rvo.OrcaParams` owns CrowdNav's values
    neighbor_dist_m: float = OrcaParams.neighbor_dist_m
    max_neighbors: int = OrcaParams.max_neighbors
    time_horizon_s: float = OrcaParams.time_horizon_s
    time_horizon_obst_s: float = OrcaParams.time_horizon_obst_s
    safety_space_m: float = OrcaParams.safety_space_m
    time_step_s: float = OrcaParams.time_step_s
    spawn_gap_m: float = 0.2
    robot_route: str = "fixed"
    route_min_m: float = 6.0

    def __post_init__(self) -> None:
        self.params  # noqa: B018  (validates the ORCA fields)
        for name in ("human_radius_m", "human_v_pref_mps"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"OrcaCrowdConfig.{name} must be a positive finite number, got {value!r}")
        for name in ("spawn_gap_m", "route_min_m"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ValueError(f"OrcaCrowdConfig.{name} must be finite and >= 0, got {value!r}")
        if self.robot_route not in ROBOT_ROUTES:
            raise ValueError(f"unknown robot_route {self.robot_route!r}; valid: {', '.join(ROBOT_ROUTES)}")

    @property
    def params(self) -> OrcaParams:
        return OrcaParams(self.neighbor_dist_m, self.max_neighbors, self.time_horizon_s, self.time_horizon_obst_s,
                          self.safety_space_m, self.time_step_s)


class OrcaCrowd:
    """N ORCA humans crossing a circle (module docstring), stepped at the env's dt_s."""

    group_labels = True  # the truth: every human walks alone

    def __init__(self, config: CrowdNavConfig) -> None:
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
        half = self.radius_m + self.cfg.human_v_pref_mps / 2 + 1.0
        self.walls = np.zeros((0, 2, 2))
        self.bounds = (-half, -half, half, half)
        self.rng = np.random.default_rng(0)
        self.pos = np.zeros((self.n, 2))
        self.vel = np.zeros((self.n, 2))
        self.goal = np.zeros((self.n, 2))
        self.route = (np.zeros(2), np.zeros(2))
        self.robot: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # pos, velocity now, velocity before
        self.tick = 0

    # ------------------------------------------------------------------------------------------ Crowd
    def reset(self, seed: int | None) -> CrowdState:
        """The robot's route, then the humans on the circle (module docstring); the same seed, the same crowd."""
        self.rng = np.random.default_rng(seed)
        self.route = self._draw_route()
        self.pos, self.goal = self._circle_crossing()
        self.vel = np.zeros((self.n, 2))
        self.robot, self.tick = None, 0
        return self.state()

    def step(self) -> CrowdState:
        """Advance dt_s: on a decision tick every human takes its ORCA velocity; then all walk straight."""
        if self.tick % self.ticks_per_decision == 0:
            self.vel = self._decide()
        self.pos = self.pos + self.dt_s * self.vel
        self.tick += 1
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
        robot the humans do not see, exactly the future that happens. times_s: whole multiples of dt_s."""
        steps = np.rint(np.asarray(times_s, float) / self.dt_s).astype(np.int64)
        if np.any(steps < 1) or not np.allclose(steps * self.dt_s, times_s):
            raise ValueError(f"times_s must be positive whole multiples of dt_s = {self.dt_s}, got {times_s}")
        fork = copy.copy(self)  # its arrays are replaced, never written in place
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
        ids = np.arange(n)
        return CrowdState(pos=self.pos.copy(), vel=self.vel.copy(), goal=self.goal.copy(),
                          radius=np.full(n, self.cfg.human_radius_m), group_id=ids.copy(), ped_id=ids.copy(),
                          active=np.ones(n, bool), label=ids.copy(), frame=self.tick, time_s=self.tick * self.dt_s)

    # ------------------------------------------------------------------------------------------ internals
    def _decide(self) -> np.ndarray:
        """The humans' ORCA velocities (N, 2) m/s from the current positions and velocities."""
        c = self.cfg
        pos, vel = self.pos, self.vel
        pref = pref_velocity(pos, self.goal, np.full(self.n, c.human_v_pref_mps))
        radius = np.full(self.n, c.human_radius_m)
        speed = np.full(self.n, c.human_v_pref_mps)
        if self.robot_visible and self.robot is not None:
            rpos, _, rvel = self.robot
            pos, vel = np.vstack([pos, rpos]), np.vstack([vel, rvel])
            pref, speed = np.vstack([pref, rvel]), np.append(speed, max(float(np.linalg.norm(rvel)), 1e-6))
            radius = np.append(radius, self.robot_radius_m)
        return orca_velocities(pos, vel, pref, radius, speed, self.params)[: self.n]

    def _draw_route(self) -> tuple[np.ndarray, np.ndarray]:
        r = self.radius_m
        if self.cfg.robot_route == "fixed":
            return np.array([0.0, -r]), np.array([0.0, r])
        for _ in range(MAX_DRAWS):
            start, goal = self.rng.uniform(-r, r, 2), self.rng.uniform(-r, r, 2)
            if np.linalg.norm(goal - start) >= self.cfg.route_min_m:
                return start, goal
        raise ValueError(f"no robot route {self.cfg.route_min_m} m long fits in a square of half-width {r} m")

    def _circle_crossing(self) -> tuple[np.ndarray, np.ndarray]:
        """Starts and goals (N, 2) m (module docstring), each start drawn until it is clear of those placed."""
        c, r = self.cfg, self.radius_m
        starts = [self.route[0]]
        goals = [self.route[1]]
        radii = [self.robot_radius_m]
        for _ in range(self.n):
            for _ in range(MAX_DRAWS):
                a = self.rng.uniform(0.0, 2.0 * np.pi)
                p = r * np.array([np.cos(a), np.sin(a)]) + (self.rng.uniform(size=2) - 0.5) * c.human_v_pref_mps
                need = c.human_radius_m + np.asarray(radii) + c.spawn_gap_m
                if np.all(np.linalg.norm(p - np.asarray(starts), axis=1) >= need) and \
                        np.all(np.linalg.norm(p - np.asarray(goals), axis=1) >= need):
                    break
            else:
                raise ValueError(f"cannot place {self.n} humans on a {r} m circle {c.spawn_gap_m} m apart")
            starts.append(p)
            goals.append(-p)
            radii.append(c.human_radius_m)
        return np.array(starts[1:]).reshape(-1, 2), np.array(goals[1:]).reshape(-1, 2)
