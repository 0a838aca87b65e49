"""Frozen configuration of the crowd-navigation env. Every default runs; fields carry their units."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from crowdsim import SCENARIOS, GroupConfig, SimConfig
from crowdsim.config import BehaviourConfig
from crowdsim.names import unknown_name
from crowdsim.scenarios import is_scenario_file, scenario_file
from envs.crowds.models import DEFAULT_CROWD_MODEL, REPLAY_SCENARIO, check_crowd_model
from envs.crowds.orca import OrcaCrowdConfig
from envs.timing import DEFAULT_TIMING
from planner import RobotConfig

GROUP_SOURCES = ("truth", "predicted")
# Where the observed predictions come from: "predictor" (`ObservationConfig.predictor`) or "oracle" (the true future
# of the people observed, privileged: an upper bound for an agent reading predictions).
PREDICTION_SOURCES = ("predictor", "oracle")
# The predictor mpc-gpgraph uses and the observation's predictions come from, unless one is named: the shipped
# crowdsim-trained GP-Graph (RESULTS.md, "Default synthetic predictor") grouping people by the coherent-motion rule
# (predictor.group_rules) instead of its learned assigner, which does not transfer to real people: on the UCY group
# annotations (validation) PW / G-MITRE F1 0.76 / 0.85 pooled against 0.43 / 0.59 (RESULTS.md, "sim-to-real").
# Defined here only.
DEFAULT_PREDICTOR = "gpgraph-stgcnn-synthetic+coherent-motion"


def _finite(obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        value = getattr(obj, name)
        if not math.isfinite(value):
            raise ValueError(f"{type(obj).__name__}.{name} must be finite, got {value!r}")


def _positive(obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value > 0 or not math.isfinite(value):
            raise ValueError(f"{type(obj).__name__}.{name} must be a positive finite number, got {value!r}")


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the named reward terms (see `envs.rewards`). The reward is the sum of weight x term.

    Terms: progress (m of goal distance gained this step), success (1 on arrival), collision (1 on
    contact), discomfort (seconds weighted by how deep the robot is inside the 0.2 m comfort zone, 0..dt),
    group_intrusion (seconds spent inside a group's region), time (seconds elapsed).
    """

    progress_per_m: float = 1.0
    success: float = 10.0
    collision: float = -10.0
    discomfort_per_s: float = -2.0
    group_intrusion_per_s: float = -2.0
    time_per_s: float = -0.1

    def __post_init__(self) -> None:
        _finite(self, tuple(self.__dataclass_fields__))

    def as_dict(self) -> dict[str, float]:
        return {
            "progress": self.progress_per_m, "success": self.success, "collision": self.collision,
            "discomfort": self.discomfort_per_s, "group_intrusion": self.group_intrusion_per_s,
            "time": self.time_per_s,
        }


@dataclass(frozen=True)
class ObservationConfig:
    """What the agent observes (see `envs.observation` for the layout).

    max_pedestrians: P, the nearest P pedestrians within `sensor_range_m` are observed, the rest padded.
    sensor_range_m: pedestrians farther than this from the robot are not observed, m.
    sensor_gap_m: pedestrians whose surface gap from the robot (centre distance minus both radii) is larger than this
        are hidden from every policy: the observation and the planners' `PolicyView` (pedestrians, history,
        future). CrowdNav++'s robot sensor_range (5 m); inf (default): nobody is hidden by it, m.
    fov_deg: the sensor's field of view, centred on its heading (a unicycle's heading; a holonomic robot's direction
        of motion, kept while it stands, the goal's direction at the start), degrees in (0, 360]; a pedestrian is
        perceived only if some part of their body disc lies inside it (`envs.perception`). 360 (default): all round.
    occlusion: whether walls and other pedestrians' bodies hide a pedestrian: perceived only if the sight line from
        the robot's centre to their centre or to one of their disc's two tangent points is clear
        (`envs.perception`). False (default): the sensor sees through everything.
        Whom fov_deg and occlusion hide (with sensor_gap_m) is hidden from every policy input: the observation, the
        `PolicyView` (pedestrians, history, future) and the predictor's input; the history forgets a pedestrian the
        moment they are out of sight, so one who comes back is a newcomer (`envs.history`'s back-fill). Metrics and
        collisions still count everybody.
    position_bound_m: Box bound on every relative position; values are clipped to it, m.
    speed_bound_mps: Box bound on velocities, m/s.
    group_source: "truth" (the simulator's labels) or "predicted" (the predictor's assignment).
    predictions: include the predicted futures (K, 12, P, 2) in the observation.
    n_prediction_samples: K in the observation.
    predictor: predictor name or checkpoint path, used only for predicted groups or predictions (source "predictor").
    prediction_source: where predictions and predicted groups come from (`PREDICTION_SOURCES`): "predictor" (default,
        `predictor`'s samples) or "oracle": the true future of the people observed (`Crowd.future`; one sample, seen
        as K copies, a person leaving within 4.8 s held where last seen) and their true groups, an upper bound.
    prediction_calibration: with predictions, also observe how wrong they have been so far in the episode
        (`envs.calibration`): per person, the conformal (1 - calibration_alpha) quantile of each step's displacement
        errors (`prediction_error`, (P, 12) m) and how many step-1 errors it rests on (`prediction_error_count`).
    calibration_alpha: the miscoverage level of that quantile, in (0, 1).
    calibration_window: the errors kept per person and step (the last ones), >= 1.
    wall_rays: R range rays around the robot (0: no `walls` key); ray k points 360 k / R degrees left of the
        robot's heading (holonomic: of +x).
    wall_range_m: a ray that meets no wall within this range reads it, m.
    """

    max_pedestrians: int = 20
    sensor_range_m: float = 10.0
    sensor_gap_m: float = math.inf
    fov_deg: float = 360.0
    occlusion: bool = False
    position_bound_m: float = 40.0
    speed_bound_mps: float = 5.0
    group_source: str = "truth"
    predictions: bool = False
    n_prediction_samples: int = 3
    predictor: str = DEFAULT_PREDICTOR
    prediction_source: str = "predictor"
    prediction_calibration: bool = False
    calibration_alpha: float = 0.1
    calibration_window: int = 20
    wall_rays: int = 0
    wall_range_m: float = 5.0

    def __post_init__(self) -> None:
        if not isinstance(self.wall_rays, int) or self.wall_rays < 0:
            raise ValueError(f"wall_rays must be an integer >= 0, got {self.wall_rays!r}")
        if self.max_pedestrians < 1:
            raise ValueError(f"max_pedestrians must be >= 1, got {self.max_pedestrians}")
        if self.n_prediction_samples < 1:
            raise ValueError(f"n_prediction_samples must be >= 1, got {self.n_prediction_samples}")
        _positive(self, ("sensor_range_m", "position_bound_m", "speed_bound_mps", "wall_range_m"))
        if not (isinstance(self.sensor_gap_m, int | float) and self.sensor_gap_m > 0):  # inf allowed
            raise ValueError(f"sensor_gap_m must be > 0 (inf: nobody hidden), got {self.sensor_gap_m!r}")
        if isinstance(self.fov_deg, bool) or not (isinstance(self.fov_deg, int | float) and 0 < self.fov_deg <= 360):
            raise ValueError(f"fov_deg must be a number in (0, 360] (360: all round), got {self.fov_deg!r}")
        if not isinstance(self.occlusion, bool):
            raise ValueError(f"occlusion must be a bool, got {self.occlusion!r}")
        if self.group_source not in GROUP_SOURCES:
            raise ValueError(f"unknown group_source {self.group_source!r}; valid: {', '.join(GROUP_SOURCES)}")
        self._check_prediction_settings()

    def _check_prediction_settings(self) -> None:
        if self.prediction_source not in PREDICTION_SOURCES:
            raise ValueError(unknown_name("prediction_source", self.prediction_source, PREDICTION_SOURCES))
        if not isinstance(self.prediction_calibration, bool):
            raise ValueError(f"prediction_calibration must be a bool, got {self.prediction_calibration!r}")
        if self.prediction_calibration and not self.predictions:
            raise ValueError("prediction_calibration (crowdnav train --calibration) calibrates the observed "
                             "predictions: it needs predictions=True (--predictions)")
        if isinstance(self.calibration_alpha, bool) or not (isinstance(self.calibration_alpha, int | float)
                                                            and 0 < self.calibration_alpha < 1):
            raise ValueError(f"calibration_alpha must be a number in (0, 1), got {self.calibration_alpha!r}")
        if not isinstance(self.calibration_window, int) or self.calibration_window < 1:
            raise ValueError(f"calibration_window must be an integer >= 1, got {self.calibration_window!r}")

    @property
    def needs_predictor(self) -> bool:
        """Whether predictions or predicted groups are observed (from the predictor, or the oracle's truth)."""
        return self.predictions or self.group_source == "predicted"

    @property
    def limited_view(self) -> bool:
        """Whether the field of view or occlusion can hide anyone (`envs.perception`; False by default)."""
        return self.fov_deg < 360 or self.occlusion


@dataclass(frozen=True)
class CrowdNavConfig:
    """The env: a crowd scenario, a robot with a goal, rewards and observation options.

    scenario: a crowdsim scenario name, the path of a scenario file (ending in .toml, `crowdsim.scenario_files`), or
        "replay" (then `replay` must be set).
    n_pedestrians: crowd size (simulated scenarios).
    scenario_options: crowdsim scenario overrides as (name, value) pairs.
    groups: group sizes and events (crowdsim's `GroupConfig`).
    behaviour: what the simulated people do besides walking in formation (crowdsim's `BehaviourConfig`: stops in
        F-formations, meeting and parting, strangers walking close); the default turns every behaviour off.
    robot: robot body and kinematic limits (the planner's `RobotConfig`).
    robot_visible: whether pedestrians see the robot (social force + physical contact); invisible robots
        pass unseen, as in CrowdNav's invisible setting.
    dt_s: env step, s. The predictor's step (0.4 s) must be a whole number of env steps.
    time_limit_s: episode length before truncation, s.
    warmup_s: crowd simulated before the robot starts moving (the robot stands at its start), s; fills the
        pedestrians' 0.4 s history.
    goal_tolerance_m: success when the robot centre is this close to the goal (CrowdNav: one robot radius), m.
    discomfort_distance_m: surface distance under which a step counts as discomfort, m.
    group_space_m: personal-space margin around a group's region (the hull of its members' discs); the robot
        intrudes when its body comes closer than this to the region, m.
    group_span_m: a ground-truth group wider than this (max pairwise distance) is not treated as a region, m.
    start_clearance_m: surface clearance required around the robot's start when choosing a route, m.
    start_lookahead_s: the start must keep that clearance over this time with every pedestrian's current
        velocity held, so that nobody is already walking into the standing robot (0: now only), s.
    spawn_contact_ends_episode: whether a contact of kind "spawn" (`envs.scoring.collisions`: a replayed track that
        began on the robot or within one prediction step of reaching it, an annotation artefact no planner can avoid)
        ends the episode as a collision. False: that pedestrian is ignored for contact, discomfort and reward
        until it is clear of the robot, and the contact is counted in the metrics (`spawn_contacts`).
    rewards, observation: see their classes.
    replay: an `envs.crowds.replay.ReplayConfig` for scenario "replay".
    crowd_model: who the simulated pedestrians are (`envs.crowds.models.CROWD_MODELS`): "social-force" (crowdsim, the
        default) or "orca" (CrowdNav's ORCA humans, scenario circle_crossing only, for comparability).
    orca: the ORCA humans' settings (`envs.crowds.orca.OrcaCrowdConfig`), read by crowd model "orca" only.
    """

    scenario: str = "plaza"
    n_pedestrians: int = 24
    scenario_options: tuple[tuple[str, float], ...] = ()
    groups: GroupConfig = field(default_factory=GroupConfig)
    behaviour: BehaviourConfig = field(default_factory=BehaviourConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    robot_visible: bool = True
    dt_s: float = 0.1
    time_limit_s: float = 40.0
    warmup_s: float = 3.2
    goal_tolerance_m: float = 0.3
    discomfort_distance_m: float = 0.2
    group_space_m: float = 0.2
    group_span_m: float = 3.0
    start_clearance_m: float = 0.5
    start_lookahead_s: float = 2.0
    spawn_contact_ends_episode: bool = True
    rewards: RewardWeights = field(default_factory=RewardWeights)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    replay: Any = None
    crowd_model: str = DEFAULT_CROWD_MODEL
    orca: OrcaCrowdConfig = field(default_factory=OrcaCrowdConfig)

    def __post_init__(self) -> None:
        valid = (*sorted(SCENARIOS), REPLAY_SCENARIO)
        if is_scenario_file(self.scenario):
            scenario_file(self.scenario)  # a bad file: one line naming the file and the key
        elif self.scenario not in valid:
            raise ValueError(unknown_name("scenario", self.scenario, valid) + "; or a .toml scenario file")
        if self.scenario == REPLAY_SCENARIO and self.replay is None:
            raise ValueError("scenario 'replay' needs replay=ReplayConfig(path=...)")
        if self.scenario != REPLAY_SCENARIO or self.crowd_model != DEFAULT_CROWD_MODEL:
            check_crowd_model(self.crowd_model, self.scenario)
        if not isinstance(self.orca, OrcaCrowdConfig):
            raise TypeError(f"CrowdNavConfig.orca must be envs.crowds.orca.OrcaCrowdConfig, got {type(self.orca)}")
        if not isinstance(self.robot, RobotConfig):
            raise TypeError(f"CrowdNavConfig.robot must be planner.RobotConfig (the robot's kinematic limits), got "
                            f"{type(self.robot).__module__}.{type(self.robot).__name__}; crowdsim.RobotSlot "
                            "describes the robot as the crowd sees it and is built by the env")
        if self.n_pedestrians < 1:
            raise ValueError(f"n_pedestrians must be >= 1, got {self.n_pedestrians}")
        _positive(self, ("dt_s", "time_limit_s", "goal_tolerance_m", "discomfort_distance_m", "group_span_m"))
        if not 0 <= self.group_space_m < math.inf:
            raise ValueError(f"group_space_m must be finite and >= 0, got {self.group_space_m}")
        if not isinstance(self.spawn_contact_ends_episode, bool):
            raise TypeError(f"spawn_contact_ends_episode must be a bool, got {self.spawn_contact_ends_episode!r}")
        for name in ("warmup_s", "start_clearance_m", "start_lookahead_s"):
            if not 0 <= getattr(self, name) < math.inf:
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)}")
        step = DEFAULT_TIMING.step_s
        if abs(self.ticks_per_prediction_step * self.dt_s - step) > 1e-9:
            raise ValueError(f"dt_s must divide the {step} s prediction step, got {self.dt_s}")
        k = round(self.orca.time_step_s / self.dt_s)
        if self.crowd_model == "orca" and (k < 1 or abs(k * self.dt_s - self.orca.time_step_s) > 1e-9):
            raise ValueError(f"the ORCA time step {self.orca.time_step_s} s must be a whole multiple of dt_s, got "
                             f"dt_s {self.dt_s}")

    @property
    def ticks_per_prediction_step(self) -> int:
        """Env steps per prediction step (`envs.timing.DEFAULT_TIMING`, 0.4 s)."""
        return max(1, round(DEFAULT_TIMING.step_s / self.dt_s))

    @property
    def max_steps(self) -> int:
        return math.ceil(self.time_limit_s / self.dt_s - 1e-9)

    def sim_config(self) -> SimConfig:
        """The crowdsim config stepped at dt_s (forces every min(dt, 0.1) s)."""
        from crowdsim import RobotSlot

        return SimConfig(
            scenario=self.scenario, n_pedestrians=self.n_pedestrians, record_dt_s=self.dt_s,
            force_dt_s=min(self.dt_s, 0.1), groups=self.groups, behaviour=self.behaviour,
            scenario_options=self.scenario_options,
            robot=RobotSlot(visible=self.robot_visible, radius_m=self.robot.radius_m),
        )
