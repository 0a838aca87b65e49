"""Real-time CasADi MPC for a robot in a crowd, with group-aware soft constraints and baselines.

Imports numpy and casadi only (scipy when a global route is searched). Entry points:

* :class:`MPCPlanner` ``(config).plan(robot_state, goal, prediction, obstacles) -> PlanResult``;
* :class:`PedPrediction` (the prediction input), :func:`constant_velocity_prediction`,
  :func:`frozen_prediction`;
* :func:`robot_dynamics` (the MPC's ``casadi.Function``) and :func:`step_robot` (its bit-identical float
  twin, which the env steps the robot with);
* baselines via :func:`make_planner` (``mpc``, ``mpc-cv``, ``mpc-none``, ``social-force``);
* :class:`Router` and :func:`grid_route` (planner/route.py), the global route through walls that gives the MPC a
  subgoal it can reach (``MPCConfig.route``);
* :data:`CROWD_MPC`, the recommended :class:`MPCConfig` among real crowds (crowd-risk options: planner/risk.py).
"""

from planner.baselines import (
    PLANNERS,
    ConstantVelocityMPC,
    FrozenMPC,
    ReactiveForceParams,
    SocialForcePlanner,
    make_planner,
)
from planner.config import (
    CROWD_MPC,
    ROBOT_MODELS,
    SOLVERS,
    CostWeights,
    ForesightConfig,
    GuidanceConfig,
    MPCConfig,
    RobotConfig,
    RouteConfig,
)
from planner.dynamics import brake_control, clip_control, model_dims, robot_dynamics, rollout, step_robot
from planner.mpc import MPCPlanner
from planner.prediction import (
    PedPrediction,
    constant_velocity_prediction,
    empty_prediction,
    frozen_prediction,
    validate_prediction,
)
from planner.result import PlanResult, PlanStats
from planner.route import Router, grid_route
from planner.scene import point_segment_distances, polygon_to_segments, segment_projection, select_modes

__all__ = [
    "CROWD_MPC",
    "PLANNERS",
    "ROBOT_MODELS",
    "SOLVERS",
    "ConstantVelocityMPC",
    "CostWeights",
    "ForesightConfig",
    "FrozenMPC",
    "GuidanceConfig",
    "MPCConfig",
    "MPCPlanner",
    "PedPrediction",
    "PlanResult",
    "PlanStats",
    "ReactiveForceParams",
    "RobotConfig",
    "RouteConfig",
    "Router",
    "SocialForcePlanner",
    "brake_control",
    "clip_control",
    "constant_velocity_prediction",
    "empty_prediction",
    "frozen_prediction",
    "grid_route",
    "make_planner",
    "model_dims",
    "point_segment_distances",
    "polygon_to_segments",
    "robot_dynamics",
    "rollout",
    "segment_projection",
    "select_modes",
    "step_robot",
    "validate_prediction",
]
