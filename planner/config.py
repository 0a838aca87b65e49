"""Frozen, validated configuration for the robot model and the MPC.

Units are in the field names: ``_m`` metres, ``_s`` seconds, ``_mps`` m/s, ``_mps2`` m/s²,
``_radps`` rad/s, ``_radps2`` rad/s². Every default runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

ROBOT_MODELS = ("unicycle", "holonomic")
SOLVERS = ("ipopt", "fatrop")


def _check_name(kind: str, name: str, valid: tuple[str, ...]) -> None:
    if name not in valid:
        raise ValueError(f"unknown {kind} {name!r}; valid names: {', '.join(valid)}")


def _check_positive(obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value > 0:
            raise ValueError(f"{type(obj).__name__}.{name} must be > 0, got {value!r}")


def _check_non_negative(obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value >= 0:
            raise ValueError(f"{type(obj).__name__}.{name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class RobotConfig:
    """Robot body and kinematic limits.

    ``unicycle``: state (x, y, heading, v, omega), control (v, omega).
    ``holonomic``: state (x, y, vx, vy), control (vx, vy); the speed bound is on the norm.
    The velocity part of the state is the control applied during the previous step, so
    acceleration bounds are local to a stage.
    """

    model: str = "unicycle"
    radius_m: float = 0.3
    max_speed_mps: float = 1.2  # unicycle forward speed / holonomic speed norm
    min_speed_mps: float = 0.0  # unicycle only: most negative (reverse) speed is -min_speed_mps
    max_accel_mps2: float = 1.5  # unicycle |dv/dt| / holonomic |dv/dt| norm
    max_yaw_rate_radps: float = 2.0  # unicycle only
    max_yaw_accel_radps2: float = 4.0  # unicycle only

    def __post_init__(self) -> None:
        _check_name("robot model", self.model, ROBOT_MODELS)
        _check_positive(self, ("radius_m", "max_speed_mps", "max_accel_mps2", "max_yaw_rate_radps",
                               "max_yaw_accel_radps2"))
        _check_non_negative(self, ("min_speed_mps",))


@dataclass(frozen=True)
class CostWeights:
    """Weights of the MPC cost terms (dimensionless multipliers of the terms documented in ``ocp``)."""

    goal: float = 1.0  # per stage, on the pseudo-Huber distance to the goal (m)
    goal_terminal: float = 5.0  # on the final stage's distance to the goal (m)
    effort: float = 0.05  # on (control / control bound)²
    smoothness: float = 0.5  # on (control change / acceleration bound per step)²
    social: float = 0.5  # on exp(-d² / (2 comfort²)) per pedestrian and mode
    slack_l1: float = 200.0  # on slack (m)
    slack_l2: float = 2000.0  # on slack² (m²)

    def __post_init__(self) -> None:
        _check_non_negative(self, ("goal", "goal_terminal", "effort", "smoothness", "social",
                                   "slack_l1", "slack_l2"))


@dataclass(frozen=True)
class RouteConfig:
    """Settings of the global route (planner/route.py), in metres. The free space keeps the MPC's wall clearance
    (`MPCConfig.wall_clearance_m`)."""

    cell_m: float = 0.1  # grid resolution
    comfort_m: float = 0.8  # steps nearer a wall than this cost more
    clearance_weight: float = 2.0  # extra cost per metre of path at zero clearance (relative to 1)
    lookahead_m: float = 2.0  # carrot distance along the path
    replan_distance_m: float = 1.0  # search again when the robot is farther than this from the path
    padding_m: float = 1.0  # grid margin around the walls, the robot and the goal
    max_cells: int = 250_000  # a larger grid is refused (ValueError): coarsen cell_m instead

    def __post_init__(self) -> None:
        for name in ("cell_m", "comfort_m", "lookahead_m", "replan_distance_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"RouteConfig.{name} must be > 0 m, got {value!r}")
        if not (math.isfinite(self.clearance_weight) and self.clearance_weight >= 0):
            raise ValueError(f"RouteConfig.clearance_weight must be >= 0, got {self.clearance_weight!r}")
        if not (math.isfinite(self.padding_m) and self.padding_m >= 0):
            raise ValueError(f"RouteConfig.padding_m must be >= 0 m, got {self.padding_m!r}")
        if self.max_cells < 4:
            raise ValueError(f"RouteConfig.max_cells must be >= 4, got {self.max_cells!r}")


@dataclass(frozen=True)
class GuidanceConfig:
    """Settings of the guidance layer (planner/guidance.py): passing options searched in space-time, each held by
    half-planes in its own solve; metres, seconds, degrees."""

    n_paths: int = 2  # guided solves beside the free one (the MPC as without guidance)
    heading_offsets_deg: tuple[float, ...] = (0.0, -25.0, 25.0, -50.0, 50.0, -80.0, 80.0)  # from the goal direction
    speed_fractions: tuple[float, ...] = (1.0, 0.5)  # of the robot's top speed; a standing path is always added
    relevance_m: float = 1.5  # a person whose predicted surface gap to a path falls below this gets a passing side
    min_winding_deg: float = 10.0  # the bearing must turn at least this much over the horizon to count as a side
    risk_weight: float = 20.0  # path cost per metre of shortfall below the MPC's clearance, summed over knots
    hold_discount: float = 0.1  # a plan that keeps the last applied plan's passing sides costs this fraction less
    max_iter: int = 25  # iteration cap of a guided solve (one that needs more is dropped: plan-time budget)

    def __post_init__(self) -> None:
        for name in ("n_paths", "max_iter"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise ValueError(f"GuidanceConfig.{name} must be an integer >= 1, got {getattr(self, name)!r}")
        if not self.heading_offsets_deg or not self.speed_fractions:
            raise ValueError("GuidanceConfig.heading_offsets_deg and speed_fractions must not be empty")
        for name, values in (("heading_offsets_deg", self.heading_offsets_deg),
                             ("speed_fractions", self.speed_fractions)):
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"GuidanceConfig.{name} must be finite, got {values!r}")
        if not all(0.0 < v <= 1.0 for v in self.speed_fractions):
            raise ValueError(f"GuidanceConfig.speed_fractions must be in (0, 1], got {self.speed_fractions!r}")
        for name in ("relevance_m", "min_winding_deg", "risk_weight"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"GuidanceConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.hold_discount < 1.0:
            raise ValueError(f"GuidanceConfig.hold_discount must be in [0, 1), got {self.hold_discount!r}")


@dataclass(frozen=True)
class ForesightConfig:
    """Settings of the foresight search (planner/foresight.py): reachable sets over a long view against the predicted
    people, the subgoal on the earliest way to the goal; metres, seconds."""

    horizon_s: float = 10.0  # how far the search looks; predictions shorter than this are extended (module docstring)
    step_s: float = 0.4  # time between the reachable sets (the predictor's step)
    cell_m: float = 0.15  # grid cell side
    clearance_m: float = 0.3  # kept beyond robot radius + person radius from every person's sample mean
    retry_without_margin: bool = True  # where no set lives to the end with clearance_m, search again without it
    speed_fraction: float = 0.85  # of the robot's top speed: the searched robot is slower, room to track its way
    spread_inflation: float = 0.5  # clearance added per metre of the samples' RMS spread about their mean, m/m
    max_inflation_m: float = 0.3  # cap on that inflation, m
    goal_reach_m: float = 0.5  # a reachable cell this near the target ends the search
    lead_s: float = 4.0  # the subgoal is the searched path's point this far ahead (the MPC's horizon: 1.6 s slowed it)
    # a subgoal farther from the goal than the nearest the robot has come to it (this episode) plus this is not
    # taken: the robot holds where it is instead of backing away with an oncoming flow; inf: no bound
    retreat_m: float = 2.0

    def __post_init__(self) -> None:
        _check_positive(self, ("horizon_s", "step_s", "cell_m", "goal_reach_m", "lead_s"))
        if not 0.0 < self.speed_fraction <= 1.0:
            raise ValueError(f"ForesightConfig.speed_fraction must be in (0, 1], got {self.speed_fraction!r}")
        _check_non_negative(self, ("clearance_m", "spread_inflation", "max_inflation_m"))
        for name in ("horizon_s", "step_s", "cell_m", "clearance_m", "spread_inflation", "max_inflation_m",
                     "goal_reach_m", "lead_s"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"ForesightConfig.{name} must be finite, got {getattr(self, name)!r}")
        if not self.retreat_m >= 0:
            raise ValueError(f"ForesightConfig.retreat_m must be >= 0 (inf: off), got {self.retreat_m!r}")
        if self.horizon_s < self.step_s:
            raise ValueError(f"ForesightConfig.horizon_s must be >= step_s, got {self.horizon_s} < {self.step_s}")


@dataclass(frozen=True)
class MPCConfig:
    """Sizes, timing and solver choice of the MPC. Sizes are fixed when the problem is built."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    weights: CostWeights = field(default_factory=CostWeights)
    solver: str = "fatrop"
    dt_s: float = 0.4  # plan (and control) step
    horizon_steps: int = 10  # H; horizon = H * dt_s
    max_peds: int = 8  # M: the nearest M valid pedestrians are constrained, the rest padded
    n_modes: int = 3  # K: representative prediction samples per pedestrian
    max_groups: int = 3  # group regions (groups of >= 2) constrained, nearest first
    max_group_span_m: float = 3.0  # a group predicted to spread wider than this is not treated as one region
    max_walls: int = 8  # obstacle segments constrained, nearest first
    safety_margin_m: float = 0.1  # added to robot radius + pedestrian radius
    # added to the robot radius against walls, which are known exactly; None: safety_margin_m (before 2026-11-25
    # the only margin: 0.3 m in CROWD_MPC left 0.6 m to each jamb, and a 1 m door could not be entered)
    wall_margin_m: float | None = None
    check_midpoints: bool = False  # also check clearances half-way through each plan step (2x cost)
    comfort_distance_m: float = 1.0  # length scale of the social-comfort cost
    time_budget_s: float = 0.2  # wall-time budget of one solve; over it counts as a timeout
    max_iter: int = 100  # solver iterations
    tolerance: float = 1e-4  # solver convergence tolerance
    # Reject (fall back from) a plan whose first step violates a clearance by more than this, m;
    # inf (default) trusts the soft constraints. Starts in collision are always rejected.
    max_slack_m: float = float("inf")
    max_plan_reuse_steps: int = 3  # how many steps a previous plan may be replayed in fallback
    # Passing options: solve from the n_starts cheapest distinct initial guesses (the shifted plan and the go-to-goal
    # rollouts at HEADING_OFFSETS_RAD, which pass people on different sides) and keep the solved plan of lowest
    # cost; 1 (default) = one solve from the cheapest guess, the MPC before 2026-11-28. Costs up to n_starts solves.
    n_starts: int = 1
    verbose: bool = False
    # -- crowd risk (planner/risk.py); the defaults leave the plain MPC above unchanged --------------------
    clearance_growth_mps: float = 0.0  # clearance added per second of prediction time, m/s
    spread_inflation: float = 0.0  # clearance added per metre of sample spread (RMS about the mean), m/m
    max_clearance_inflation_m: float = 0.5  # cap on the two inflations above, m
    # -- safety shield (planner/shield.py); shield_horizon_s = 0 (default) turns it off ---------------------
    # The plan's first control is checked against every predicted sample at the control rate; if more than
    # shield_max_risk of the samples come within shield_margin_m within shield_horizon_s, a safer constant
    # command replaces it.
    shield_horizon_s: float = 0.0  # look-ahead, s (0 = no shield)
    shield_dt_s: float = 0.1  # time resolution of the check = the control step the command is held for, s
    shield_margin_m: float = 0.05  # clearance below which a sample counts as hit, m
    shield_max_risk: float = 0.1  # largest accepted fraction of hit samples, in [0, 1]
    shield_tau_s: float = 0.8  # time constant of the discount on later violations, s
    shield_cv: bool = True  # also avoid the last observed velocity held (needs prediction.history)
    # -- global route (planner/route.py); None (default): head straight for the goal -------------------------
    route: RouteConfig | None = None
    # -- guidance layer (planner/guidance.py); None (default): one free solve, the MPC before 2026-11-28 ----------
    guidance: GuidanceConfig | None = None
    # -- foresight search (planner/foresight.py); None (default): off ----------------------------------------------
    foresight: ForesightConfig | None = None

    @property
    def wall_clearance_m(self) -> float:
        """Distance (m) the robot's centre keeps from walls: robot radius + wall margin."""
        margin = self.safety_margin_m if self.wall_margin_m is None else self.wall_margin_m
        return self.robot.radius_m + margin

    def __post_init__(self) -> None:
        _check_name("solver", self.solver, SOLVERS)
        _check_positive(self, ("dt_s", "horizon_steps", "max_peds", "n_modes", "n_starts", "comfort_distance_m",
                               "max_group_span_m", "time_budget_s", "max_iter", "tolerance"))
        if self.wall_margin_m is not None:
            _check_non_negative(self, ("wall_margin_m",))
        _check_non_negative(self, ("max_groups", "max_walls", "safety_margin_m", "max_slack_m",
                                   "max_plan_reuse_steps"))
        _check_non_negative(self, ("clearance_growth_mps", "spread_inflation", "max_clearance_inflation_m"))
        _check_positive(self, ("shield_dt_s", "shield_tau_s"))
        _check_non_negative(self, ("shield_horizon_s", "shield_margin_m"))
        if not 0.0 <= self.shield_max_risk <= 1.0:
            raise ValueError(f"MPCConfig.shield_max_risk must be in [0, 1], got {self.shield_max_risk!r}")
        if self.horizon_steps < 2:
            raise ValueError(f"MPCConfig.horizon_steps must be >= 2, got {self.horizon_steps}")
        if self.dt_s * self.robot.max_yaw_rate_radps > 2.0:
            raise ValueError("MPCConfig.dt_s * robot.max_yaw_rate_radps must be <= 2 rad (accuracy of the "
                             f"discrete unicycle), got {self.dt_s * self.robot.max_yaw_rate_radps:.2f}")


# Recommended MPC among real (replayed, non-reactive) crowds: a 0.3 m margin at the 0.4 s knots, clearance inflation
# with prediction time and sample spread (capped at 0.5 m), the safety shield (planner/shield.py) in place of the
# MPC's mid-step checks, and the 12 nearest pedestrians constrained; since 2026-11-25 a 0.05 m margin to walls and
# the global route (planner/route.py). Tuned only on cells and seeds that no reported result uses; how each setting
# was chosen, with its numbers: docs/decisions/planner-settings.md. Set `robot=` to the env's robot with
# dataclasses.replace.
CROWD_MPC = MPCConfig(safety_margin_m=0.3, check_midpoints=False, clearance_growth_mps=0.2, spread_inflation=0.5,
                      max_clearance_inflation_m=0.5, shield_horizon_s=1.6, shield_margin_m=0.15, max_peds=12,
                      wall_margin_m=0.05, route=RouteConfig())
