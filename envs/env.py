"""`CrowdNavEnv`: a robot crossing a grouped crowd, Gymnasium API (registered as `crowdnav/CrowdNav-v1`).

`step(action)` runs a fixed sequence:
    1. apply action: scale [-1, 1]^2 to the robot's limits, clip to the reachable accelerations, integrate
       the robot with the planner's dynamics (`step_control(control)` starts from a control in the robot's units
       instead, clipped the same way; the episode loop applies a planner's control so, `step_decision`);
    2. simulate: the crowd advances dt_s with the robot moving along that step (visible or not);
    3. observe: (on each 0.4 s tick) record the pedestrians' history, predict if configured; build the
       observation;
    4. rewards: named terms (`envs.rewards`), weighted by config;
    5. terminated: success or collision;
    6. truncated: the time limit;
    7. info: the weighted reward terms, distances, and at the episode's end `is_success` and the metrics.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from crowdsim import CrowdState
from envs.calibration import episode_calibration
from envs.config import CrowdNavConfig
from envs.crowds.crowd import clear_route
from envs.crowds.models import make_crowd
from envs.drawing.frame import SceneFrame
from envs.history import PedHistory
from envs.observation import build_observation, observation_space
from envs.perception import Senses, rows_of
from envs.prediction import load_predictor_spec, oracle_prediction, predict
from envs.rewards import StepFacts, reward_terms, weighted
from envs.scoring.collisions import SPAWN_WINDOW_S, SpawnContacts, collision_kind
from envs.scoring.geometry import WallIndex
from envs.scoring.kernels import intruded_groups, step_distances
from envs.scoring.metrics import EpisodeMetrics, social_step
from envs.timing import DEFAULT_TIMING
from envs.view import Decision, Pedestrians, PolicyView, action_command, control_action
from planner import clip_control, model_dims, step_robot


class CrowdNavEnv(gym.Env):
    """See the module docstring; observation layout in `envs.observation`, rewards in `envs.rewards`.

    Actions outside [-1, 1]^2 are clipped to it; an action with NaN or inf, or of the wrong shape, raises
    a ValueError. Unicycle: a[0] maps linearly to speed [-min_speed, max_speed] m/s and a[1] to yaw rate
    [-max, max] rad/s; holonomic: a * max_speed (vx, vy) m/s, norm-clipped.

    Perception (`ObservationConfig`): a pedestrian is perceived when within `sensor_gap_m` (surface gap; default inf),
    when some part of their disc lies in the `fov_deg` field of view around the sensor's heading (default 360: all
    round) and, with `occlusion` (default False), when a sight line to them is clear of walls and other people's
    bodies (`envs.perception`). Every policy input holds the perceived pedestrians only: the observation, `view()`
    (pedestrians, history, track, and the reference policies' true future: the oracle predicts perfectly whom it
    perceives and knows nothing of the others) and the predictor's input. With `fov_deg` < 360 or `occlusion` the
    history also holds only what was perceived: a pedestrian out of sight is forgotten, and comes back as one who
    has just come into view (back-filled, `envs.history`); people hidden at the start (the warmup is watched by
    all-seeing eyes) are forgotten at reset. The metrics, rewards and collisions count everybody.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: CrowdNavConfig | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        cfg = config or CrowdNavConfig()
        self.config = replace(cfg, **overrides) if overrides else cfg
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; valid: {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.config.dt_s)}
        self.crowd = make_crowd(self.config)
        self.dims = model_dims(self.config.robot.model)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = observation_space(self.config)
        self.timing = DEFAULT_TIMING
        self._step_start: tuple[np.ndarray, CrowdState] | None = None
        self._nearest_row = -1
        self._spawns = SpawnContacts(self.config.discomfort_distance_m)
        self._predictor = None
        self._pred_rng = np.random.default_rng(0)
        self.robot_state = np.zeros(self.dims.state_dim)
        self.goal = np.zeros(2)
        self.steps = 0
        self._sim_steps = 0
        self.metrics = EpisodeMetrics(labelled=self.crowd.group_labels)
        self._done = True
        self._annotations: dict[str, np.ndarray | None] = {}
        self._pred_samples: np.ndarray | None = None
        self._pred_groups: np.ndarray | None = None
        self._calib = None  # the episode's `envs.calibration.PredictionCalibration` (with prediction_calibration)
        self._walls = WallIndex(self.crowd.walls)  # the walls never change: precomputed for the per-step check
        self.senses = Senses(self.config, self._walls.segments, self.timing)  # perception and memory (envs.perception)
        self._peds_cache: tuple[CrowdState | None, Pedestrians | None] = (None, None)
        self._pred_ids: np.ndarray | None = None  # the ids `_pred_samples` predicts (rows in its order)
        self._obs: dict[str, np.ndarray] = {}

    # ------------------------------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        cfg = self.config
        state = self.crowd.reset(int(self.np_random.integers(2**31 - 1)))
        self._pred_rng = np.random.default_rng(int(self.np_random.integers(2**31 - 1)))
        self.crowd.clear_robot()
        self.senses.clear()
        self.steps = self._sim_steps = 0
        self._state = state
        self._observe_arrivals()
        self._record_tick()
        tick = cfg.ticks_per_prediction_step
        for _ in range(tick * round(cfg.warmup_s / (tick * cfg.dt_s))):
            self._state = self.crowd.step()
            self._sim_steps += 1
            self._observe_arrivals()
            if self._sim_steps % tick == 0:
                self._record_tick()
        start, self.goal = self._choose_route()
        self.robot_state = np.zeros(self.dims.state_dim)
        self.robot_state[:2] = start
        if cfg.robot.model == "unicycle":
            self.robot_state[2] = np.arctan2(*(self.goal - start)[::-1])
        self.crowd.set_robot(start, np.zeros(2), cfg.robot.radius_m)
        self.senses.place(math.atan2(*(self.goal - start)[::-1]), self._peds())
        if self.senses.limited:  # the people hidden from the start are forgotten
            self._observe_arrivals()
        self.metrics = EpisodeMetrics(labelled=self.crowd.group_labels, start=tuple(start), goal=tuple(self.goal),
                                      goal_tolerance_m=cfg.goal_tolerance_m, dt_s=cfg.dt_s,
                                      robot_radius_m=cfg.robot.radius_m)
        self.metrics.observe_people(self._peds())
        self._spawns.reset()
        self._done = False
        self._annotations = {}
        self._calib = episode_calibration(cfg.observation, self.timing.pred_len)
        self._update_prediction()
        self._obs = self._observe()
        return self._obs, {"goal_distance_m": self._goal_distance()}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        self._check_running()
        return self._advance(self.action_to_control(action))

    def step_control(self, control: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """`step()` with a control (2,) in the robot's units (unicycle v m/s, omega rad/s; holonomic vx, vy m/s)
        instead of an action, clipped to the robot's velocity and acceleration limits over dt_s: a planner's control
        as it is (before crowdnav-v1 version 6 it went through the float32 action and was clipped twice)."""
        self._check_running()
        u = np.asarray(control, dtype=float)
        if u.shape != (2,) or not np.all(np.isfinite(u)):
            raise ValueError(f"control must be a finite (2,) array, got {u!r}")
        return self._advance(clip_control(self.robot_state, u, self.config.dt_s, self.config.robot))

    def step_decision(self, decision: Decision) -> tuple[dict, float, bool, bool, dict]:
        """Step with a policy's `Decision`: its action (`step`) or its control (`step_control`)."""
        if decision.action is not None:
            return self.step(decision.action)
        return self.step_control(decision.control)

    def _check_running(self) -> None:
        if self._done:
            raise RuntimeError("step() called on a finished episode; call reset()")

    def _advance(self, control: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """The step sequence (module docstring) with the control (2,) already clipped to the robot's limits."""
        cfg = self.config
        # 1. apply the control
        before_pos, before = self.robot_state[:2].copy(), self._state
        self._step_start = (before_pos, before)
        dist_before = self._goal_distance()
        self.robot_state = step_robot(self.robot_state, control, cfg.dt_s, cfg.robot.model)
        if self.senses.limited:
            self.senses.heading_rad = self.sensor_heading()
        # 2. simulate (the robot body moves along the step's chord)
        self.crowd.set_robot(before_pos, (self.robot_state[:2] - before_pos) / cfg.dt_s, cfg.robot.radius_m)
        self._state = self.crowd.step()
        self._sim_steps += 1
        self.steps += 1
        self._observe_arrivals()
        # 3. observe
        if self.is_planning_tick:
            self._record_tick()
            self._update_prediction()
        obs = self._obs = self._observe()
        # 4. rewards
        facts = self._facts(before_pos, before, dist_before)
        terms = weighted(reward_terms(facts, cfg), cfg)
        moved = self.robot_state[:2] - before_pos
        self.metrics.update(cfg.dt_s, math.sqrt(moved.dot(moved)),
                            facts.min_surface_distance_m, cfg.discomfort_distance_m, facts.intruding)
        self.metrics.spawn_contacts = self._spawns.count
        self.metrics.observe(self.robot_state[:2], facts.social)
        self.metrics.observe_people(self._peds())
        # 5. terminated, 6. truncated
        terminated = facts.collided or facts.reached_goal
        truncated = (not terminated) and self.steps >= cfg.max_steps
        # 7. info
        info = {"reward_terms": terms, "goal_distance_m": facts.goal_distance_after_m,
                "min_surface_distance_m": facts.min_surface_distance_m, "intruding": facts.intruding}
        if terminated or truncated:
            self._finish(facts, truncated)
            info["is_success"] = self.metrics.success
            info["episode_metrics"] = self.metrics.as_dict()
        return obs, float(sum(terms.values())), bool(terminated), bool(truncated), info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        from envs.drawing.render import render_rgb

        return render_rgb(self.frame())

    # ------------------------------------------------------------------ used by policies and observers
    @property
    def is_planning_tick(self) -> bool:
        """Whether now is on the 0.4 s grid of the predictor (history and predictions are fresh)."""
        return self._sim_steps % self.config.ticks_per_prediction_step == 0

    def pedestrians(self) -> Pedestrians:
        """The pedestrians in the scene now (rows in slot order)."""
        s = self._state
        act = s.active
        return Pedestrians(s.pos[act], s.vel[act], s.radius[act], s.group_id[act], s.ped_id[act])

    def _peds(self) -> Pedestrians:
        """`pedestrians()` of the current state, built once per state: internal, read-only use only."""
        state, peds = self._peds_cache
        if state is not self._state or peds is None:
            peds = self.pedestrians()
            self._peds_cache = (self._state, peds)
        return peds

    def view(self, history: bool | int = True, future: bool = False, track: bool = False,
             future_s: float = 0.0) -> PolicyView:
        """What a policy reads now (`envs.view.PolicyView`): the last observation and the typed scene, copies; the
        history window only when asked for (True; an int k: its newest k rows only, as `history_window`); the
        pedestrians' true future only when asked for (reference policies): `pred_len` steps, or as many as cover
        `future_s` seconds where that is longer (a reference that plans farther than the predictor sees); their
        track (`track_window`) only when asked for (policies whose predictor groups by a rule)."""
        if not self._obs:
            raise RuntimeError("view() before reset()")
        p = self._sensed(self.pedestrians())
        ahead = None
        if future:
            if not hasattr(self.crowd, "future"):
                raise ValueError(f"the crowd of scenario {self.config.scenario!r} cannot tell its future")
            t = self.timing
            steps = max(t.pred_len, math.ceil(future_s / t.step_s - 1e-9))
            ahead = self.crowd.future(p.ped_id, t.step_s * np.arange(1, steps + 1))
        rows = self._history_rows(p, history)
        whole = rows if rows is not None and len(rows) == self.timing.obs_len else None  # the track's newest rows
        return PolicyView({k: v.copy() for k, v in self._obs.items()}, self.robot_state.copy(), self.goal.copy(),
                          self.config.robot, p, rows,
                          np.asarray(self.crowd.walls, float).reshape(-1, 4), self.timing, self.config.dt_s, ahead,
                          self.track_window(p, whole) if track else None)

    def action_for(self, decision: Decision) -> np.ndarray:
        """The action (2,) float32 a policy's decision asks for: its action, or the action of its control."""
        return decision.action if decision.action is not None else self.control_to_action(decision.control)

    def _history_rows(self, p: Pedestrians, history: bool | int) -> np.ndarray | None:
        """`view`'s history: None (False), the whole window (True) or its newest `history` rows (an int)."""
        if history is False or history is None:
            return None
        return self.history_window(p, None if history is True else int(history))

    def history_window(self, p: Pedestrians | None = None, rows: int | None = None) -> np.ndarray:
        """(obs_len = 8, N, 2) m positions of `pedestrians()` 0.4 s apart, the last row being now. On a 0.4 s tick the
        rows are the recorded snapshots; between ticks each row is interpolated linearly between the two
        snapshots around its time (the newest interval ends at the current positions). For a pedestrian seen
        for less than 2.8 s, the rows before its first snapshot (or, if it came after the last tick, before now)
        run its velocity over its first 0.4 s in view backwards (`envs.history.extrapolate_back`): one who has
        just come into view is seen walking, not standing (zero velocity only at the instant it appears). `p`: the
        rows to give (default `pedestrians()`; with a limited view, `perceived_pedestrians()`: the history holds no
        one else). `rows`: the newest rows only, (rows, N, 2), the same floats."""
        p = self._remembered_people() if p is None else p
        return self.senses.window(p, self._sim_steps, rows)

    def track_window(self, p: Pedestrians | None = None, window: np.ndarray | None = None) -> np.ndarray:
        """(TRACK_ROWS = 48, N, 2) m: the same pedestrians' longer past for a group rule (`predictor.api`'s `track`),
        0.4 s apart, the last row now: its newest obs_len rows are `history_window`'s (`window`, when the caller has
        it already), the older ones their recorded positions, NaN before each pedestrian was first seen
        (`envs.history.PedHistory.track_now`). `p`: as `history_window`'s."""
        p = self._remembered_people() if p is None else p
        window = self.history_window(p) if window is None else window
        return self.senses.track(p, self._sim_steps, window)

    def perceived_pedestrians(self) -> Pedestrians:
        """The rows of `pedestrians()` the sensor perceives now (`ObservationConfig`'s sensor_gap_m, fov_deg and
        occlusion; all of them by default): who every policy input holds."""
        return self._sensed(self.pedestrians())

    def sensor_heading(self) -> float:
        """The direction the sensor faces now, rad (`envs.perception.sensor_heading`): a unicycle's heading; a
        holonomic robot's direction of motion, or while it stands its last one (the goal's direction at the start)."""
        return self.senses.heading(self.robot_state)

    @property
    def history(self) -> PedHistory:
        """The predictor's history of positions (`envs.history.PedHistory`, obs_len rows; `envs.perception`)."""
        return self.senses.history

    @property
    def track_history(self) -> PedHistory:
        """The group rules' longer history (`envs.history.PedHistory`, TRACK_ROWS rows; `envs.perception`)."""
        return self.senses.track_history

    def action_to_control(self, action: np.ndarray) -> np.ndarray:
        """The control (2,) (unicycle v m/s, omega rad/s; holonomic vx, vy m/s) an action asks for, clipped
        to the robot's velocity and acceleration limits over dt_s."""
        a = np.asarray(action, dtype=float)
        if a.shape != (2,):
            raise ValueError(f"action must have shape (2,), got {a.shape}")
        a0, a1 = float(a[0]), float(a[1])
        if not (math.isfinite(a0) and math.isfinite(a1)):
            raise ValueError(f"action must be finite, got {a}")
        r = self.config.robot
        return clip_control(self.robot_state, action_command(a0, a1, r), self.config.dt_s, r)

    def control_to_action(self, control: np.ndarray) -> np.ndarray:
        """The action (2,) float32 in [-1, 1] that asks for `control` (`envs.view.control_action`)."""
        return control_action(control, self.config.robot)

    def annotate(self, plan: np.ndarray | None = None, predictions: np.ndarray | None = None,
                 predicted_group_id: np.ndarray | None = None, options: np.ndarray | None = None) -> None:
        """Attach a policy's plan (H + 1, 2), predictions (K, T, N, 2) / groups (N,) (rows of `pedestrians()`) and
        other passing options (O, H + 1, 2) to the frames drawn from now on."""
        self._annotations = {"plan": plan, "predictions": predictions, "predicted_group_id": predicted_group_id,
                             "options": options}

    def frame(self, scalars: dict[str, float] | None = None) -> SceneFrame:
        """The current scene for the renderer and the rerun observer."""
        p = self.pedestrians()
        ann = self._annotations
        preds, pgroups = ann.get("predictions"), ann.get("predicted_group_id")
        if preds is None and self._pred_samples is not None and self._pred_samples.shape[2] == len(p.pos):
            preds, pgroups = self._pred_samples, self._pred_groups
        ok = preds is not None and preds.shape[2] == len(p.pos)
        return SceneFrame(
            step=self.steps, time_s=self.steps * self.config.dt_s, robot_state=self.robot_state.copy(),
            robot_radius_m=self.config.robot.radius_m, goal=self.goal.copy(), ped_pos=p.pos, ped_vel=p.vel,
            ped_radius=p.radius, group_id=p.group_id, ped_id=p.ped_id, walls=self.crowd.walls,
            bounds=self.crowd.bounds, plan=ann.get("plan"), predictions=preds if ok else None,
            predicted_group_id=pgroups if ok else None, scalars=dict(scalars or {}), options=ann.get("options"),
        )

    # ---------------------------------------------------------------------------------- internals
    def _observe_arrivals(self) -> None:
        self.senses.observe(self._peds(), self.robot_state, self._state, self._sim_steps)

    def _record_tick(self) -> None:
        self.senses.record(self._peds(), self.robot_state, self._state, self._sim_steps)

    def _goal_distance(self) -> float:
        d = self.goal - self.robot_state[:2]
        return math.sqrt(d.dot(d))  # = np.linalg.norm(d) (sqrt of the same dot product), without its overhead

    def _choose_route(self) -> tuple[np.ndarray, np.ndarray]:
        """A route whose start keeps start_clearance_m (surface) from every pedestrian now and, with their
        current velocities held, over start_lookahead_s (`envs.crowds.crowd.clear_route`)."""
        p, cfg = self.pedestrians(), self.config
        return clear_route(self.crowd, p.pos, p.vel, p.radius, cfg.robot.radius_m + cfg.start_clearance_m,
                           cfg.start_lookahead_s, cfg.dt_s, self.np_random)

    def _update_prediction(self) -> None:
        if not self.config.observation.needs_predictor:
            return
        p = self._remembered_people()
        if self.config.observation.prediction_source == "oracle":  # the true future: an upper bound
            self._pred_samples, self._pred_groups = oracle_prediction(self.crowd, p, self.timing)
        else:
            if self._predictor is None:  # torch is loaded only when predictions are observed
                self._predictor = load_predictor_spec(self.config.observation.predictor, threads=None,
                                                      timing=self.timing)
            window = self.history_window(p)
            track = self.track_window(p, window) if getattr(self._predictor, "reads_track", False) else None
            self._pred_samples, self._pred_groups = predict(self._predictor, window,
                                                            self.config.observation.n_prediction_samples,
                                                            self._pred_rng, self.timing.pred_len, track)
        self._pred_ids = p.ped_id
        if self._calib is not None:  # scores the predictions whose time has come, keeps these
            self._calib.update(self._sim_steps // self.config.ticks_per_prediction_step, p.ped_id, p.pos,
                               self._pred_samples)

    def _remembered_people(self) -> Pedestrians:
        """Whom the history holds now: `pedestrians()`, or with a limited view `perceived_pedestrians()`."""
        return self.perceived_pedestrians() if self.senses.sensing else self.pedestrians()

    def _sensed(self, p: Pedestrians) -> Pedestrians:
        """The rows of `p` (`pedestrians()` now) the sensor perceives (`_sensor_mask`)."""
        return rows_of(p, self._sensor_mask(p))

    def _sensor_mask(self, p: Pedestrians) -> np.ndarray | None:
        """(N,) bool: the rows of `p` (`pedestrians()` now) the sensor perceives (`envs.perception.Senses.mask`); None
        when every row is."""
        return self.senses.mask(p, self.robot_state, self._state, self._sim_steps)

    def _observe(self) -> dict[str, np.ndarray]:
        cfg, p = self.config, self._peds()
        if self.senses.limited:
            p = self._sensed(p)
            groups, samples = self._predicted_rows(p)
        else:
            groups, samples = self._predicted_rows(p)
            keep = self._sensor_mask(p)
            if keep is not None:
                p, groups = rows_of(p, keep), groups[keep]  # the mask once, for the rows and their groups
                samples = None if samples is None else samples[:, :, keep]
        time_left = max(0.0, 1.0 - self.steps / cfg.max_steps)
        calib = None if self._calib is None else self._calib.features(p.ped_id)
        return build_observation(cfg, self.observation_space, self.robot_state, self.goal, time_left,
                                 p.pos, p.vel, p.radius, groups, samples, self._walls.segments, calib)

    def _predicted_rows(self, p: Pedestrians) -> tuple[np.ndarray, np.ndarray | None]:
        """The groups (n,) and predicted samples (K, 12, n, 2) m of the rows of `p`, matched by id to the people the
        last tick's prediction ran on (`_pred_ids`): people arrive and leave between ticks, so a row's prediction is
        found by its id, never by its position in the table. If someone in `p` has no prediction, nobody's is
        observed (samples None, groups the truth); groups are the predictor's with `group_source` "predicted"."""
        groups, samples, ids = p.group_id, None, self._pred_ids
        if not self.config.observation.needs_predictor or self._pred_samples is None or ids is None:
            return groups, samples
        where = {int(i): k for k, i in enumerate(ids)}
        at = [where.get(int(i), -1) for i in p.ped_id]
        if -1 not in at:
            samples = self._pred_samples[:, :, at]
            if self.config.observation.group_source == "predicted":
                groups = self._pred_groups[at]
        return groups, samples

    def _facts(self, before_pos: np.ndarray, before: CrowdState, dist_before: float) -> StepFacts:
        """Distances, contact and intrusion of the step just simulated (`before`: the crowd at its start)."""
        cfg, p, s = self.config, self._peds(), self._state
        here, r = self.robot_state[:2], cfg.robot.radius_m
        # rows keep their pedestrian while it stays: those present at both ends get the closest approach
        centre, surface = step_distances(here, before_pos, s.pos, s.radius, s.active, s.ped_id, before.pos,
                                         before.active, before.ped_id, r)
        active_rows = np.flatnonzero(s.active)
        if not cfg.spawn_contact_ends_episode and len(surface):
            surface = self._spawns.filter(surface, p.ped_id, lambda k: self._is_new(int(active_rows[k])))
        min_surface = float(surface.min()) if len(surface) else float("inf")
        self._nearest_row = int(active_rows[np.argmin(surface)]) if len(surface) else -1
        hit_wall = self._walls.within(here, r)
        intruding = bool(intruded_groups(here, r + cfg.group_space_m, p.pos, p.radius, p.group_id,
                                         cfg.group_span_m, centre))
        dist_after = self._goal_distance()
        social = social_step(before_pos, here, cfg.dt_s, r, centre, surface, p.group_id, before.pos, before.vel,
                             before.radius, before.active)
        return StepFacts(dist_before, dist_after, dist_after < cfg.goal_tolerance_m, hit_wall, min_surface,
                         intruding, social)

    def _is_new(self, row: int) -> bool:
        """Whether the pedestrian in state row `row` is new (`envs.scoring.collisions`): its slot held nobody or
        somebody else at the step's start, or (replays) its track began less than SPAWN_WINDOW_S ago."""
        before, s = self._step_start[1], self._state
        if not (before.active[row] and before.ped_id[row] == s.ped_id[row]):
            return True
        track_age_s = getattr(self.crowd, "track_age_s", None)
        return track_age_s is not None and track_age_s(int(s.ped_id[row])) < SPAWN_WINDOW_S - 1e-9

    def _collision_kind(self) -> str:
        """The kind of this step's pedestrian contact (`envs.scoring.collisions`): the pedestrian nearest along the step
        (`_facts`)."""
        before_pos = self._step_start[0]
        s, here, row = self._state, self.robot_state[:2], self._nearest_row
        robot_vel = (here - before_pos) / self.config.dt_s
        return collision_kind(here, robot_vel, s.pos[row], s.vel[row], self._is_new(row))

    def _finish(self, facts: StepFacts, truncated: bool) -> None:
        m = self.metrics
        if facts.collided:
            m.collision, m.collision_time_s = True, m.time_s
            m.collision_with = "wall" if facts.hit_wall and facts.min_surface_distance_m >= 0 else "pedestrian"
            m.at_fault = self._collision_kind() if m.collision_with == "pedestrian" else "robot"
        elif facts.reached_goal:
            m.success, m.time_to_goal_s = True, m.time_s
        elif truncated:
            m.timeout = True
        m.continue_people(self._peds(), getattr(self.crowd, "future", None))  # ITR's horizon past the end
        self._done = True
