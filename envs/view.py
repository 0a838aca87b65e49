"""What a policy reads (`PolicyView`) and what it returns (`Decision`): the whole policy <-> env contract.

A policy never calls back into the env. Each step the episode loop (`envs.policies.act`) asks the env for a
`PolicyView` (copies, made after the last reset/step), hands it to `policy.act(view)`, attaches the decision's
annotations to the frames drawn from then on, and steps the env with the decision's action.

Learned agents read `view.obs` (the Gymnasium observation) and return an `action` in [-1, 1]^2; planners read the
typed fields and return a `control` in the robot's units, which the env maps to its action (`action_for`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from envs.timing import PredictionTiming
from planner import RobotConfig


@dataclass(frozen=True)
class Pedestrians:
    """The pedestrians in the scene now: pos (N, 2) m, vel (N, 2) m/s, radius (N,) m, group_id (N,)
    ground truth 0..G-1, ped_id (N,)."""

    pos: np.ndarray
    vel: np.ndarray
    radius: np.ndarray
    group_id: np.ndarray
    ped_id: np.ndarray


@dataclass(frozen=True)
class PolicyView:
    """What a policy may read of the env at one step (copies; arrays in m, m/s, rad).

    obs: the observation the env returned last (the Dict of `envs.observation`), for learned agents.
    robot_state: (nz,) the planner's state (unicycle x, y, heading, v, omega; holonomic x, y, vx, vy).
    goal: (2,). robot: the robot's `RobotConfig`. pedestrians: those the robot perceives now (everyone in the scene by
        default; `ObservationConfig`'s sensor_gap_m, fov_deg and occlusion hide the others from every field here).
    history: (obs_len, N, 2) their positions `timing.step_s` apart, the last row now (rows of `pedestrians`); None
        for a policy that declares `reads_history = False` (learned agents: the window costs ~0.1-0.2 ms a step);
        its newest k rows for one that declares `reads_history = k` (an int: the shielded agents read 2).
    walls: (W, 4) wall segments x0, y0, x1, y1. timing: the prediction timing. dt_s: the env step, s.
    future: privileged, for reference policies only (`reads_future = True`, e.g. `mpc-oracle`): where the
        perceived pedestrians will be (a perfect prediction of whom it perceives; the hidden stay unknown), (T, N, 2)
        m at +step_s ... +T step_s (rows of `pedestrians`), T = pred_len or more for a reference that plans farther
        (its `future_s`), NaN where one will have left (`envs.crowds.crowd.Crowd.future`); None for every other
        policy.
    track: (48, N, 2) their longer past on the history's grid, NaN before each was first seen (`CrowdNavEnv.
        track_window`), for a policy that declares `reads_track = True` (one whose predictor groups by a rule:
        the rule reads the track); None otherwise.
    """

    obs: dict[str, np.ndarray]
    robot_state: np.ndarray
    goal: np.ndarray
    robot: RobotConfig
    pedestrians: Pedestrians
    history: np.ndarray | None
    walls: np.ndarray
    timing: PredictionTiming
    dt_s: float
    future: np.ndarray | None = None
    track: np.ndarray | None = None


@dataclass(frozen=True)
class Decision:
    """A policy's answer for one step: exactly one of `control` and `action`, and optional annotations.

    control: (2,) in the robot's units (unicycle: v m/s, omega rad/s; holonomic: vx, vy m/s), from planners.
    action: (2,) in [-1, 1] (the env's action space), from learned agents.
    plan: (H + 1, 2) m, the planned robot path; predictions: (K, T, N, 2) m sampled futures of the view's
    pedestrians; predicted_group_id: (N,); options: (O, H + 1, 2) m, the planner's other passing options (the
    guidance layer's solved plans, planner/guidance.py). When all are None the frames keep the previous annotations
    (a planner holding its plan between re-plans).
    """

    control: np.ndarray | None = None
    action: np.ndarray | None = None
    plan: np.ndarray | None = None
    predictions: np.ndarray | None = None
    predicted_group_id: np.ndarray | None = None
    options: np.ndarray | None = None

    def __post_init__(self) -> None:
        if (self.control is None) == (self.action is None):
            raise ValueError("a Decision holds exactly one of control and action")
        value = self.control if self.control is not None else self.action
        if np.shape(value) != (2,):
            raise ValueError(f"a Decision's control/action must have shape (2,), got {np.shape(value)}")

    @property
    def annotated(self) -> bool:
        """Whether the decision carries annotations for the renderer."""
        return (self.plan is not None or self.predictions is not None or self.predicted_group_id is not None
                or self.options is not None)


def action_command(a0: float, a1: float, robot: RobotConfig) -> np.ndarray:
    """The command (2,) an action (a0, a1) in [-1, 1]^2 asks for, before the acceleration limits (unicycle: speed
    from -min_speed_mps to max_speed_mps, yaw rate +-max_yaw_rate_radps; holonomic: vx, vy +-max_speed_mps). Values
    outside [-1, 1] are clipped (a bound wins a tie, as in numpy)."""
    a0, a1 = ((x if x < 1.0 else 1.0) if x > -1.0 else -1.0 for x in (float(a0), float(a1)))
    if robot.model == "unicycle":
        lo, hi = -robot.min_speed_mps, robot.max_speed_mps
        return np.array([lo + (a0 + 1.0) * 0.5 * (hi - lo), a1 * robot.max_yaw_rate_radps])
    return np.array([a0 * robot.max_speed_mps, a1 * robot.max_speed_mps])


def control_action(control: np.ndarray, robot: RobotConfig) -> np.ndarray:
    """The action (2,) float32 in [-1, 1] that asks for `control` (2,) (`action_command`'s inverse, clipped)."""
    u = np.asarray(control, float)
    if robot.model == "unicycle":
        lo, hi = -robot.min_speed_mps, robot.max_speed_mps
        a = np.array([2.0 * (u[0] - lo) / (hi - lo) - 1.0, u[1] / robot.max_yaw_rate_radps])
    else:
        a = u / robot.max_speed_mps
    return np.clip(a, -1.0, 1.0).astype(np.float32)
