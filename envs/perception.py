"""What the robot's sensor perceives (a field of view, and lines of sight that walls and people block), and what it
remembers: `Senses`, the env's sensor mask and the histories of the people it has perceived.

Off by default (`ObservationConfig.fov_deg` 360, `occlusion` False): then nobody is hidden by this module and the env
never runs its geometry. The rule, for pedestrian i (centre c_i, body radius r_i) seen from the robot centre o with the
sensor's heading h (`sensor_heading`):

- **Field of view** (`in_field_of_view`): some part of i's body disc lies inside the sector of the robot's view, the
  directions within fov_deg / 2 of h: the angle between h and c_i - o is at most fov_deg / 2 + asin(r_i / |c_i - o|)
  (the disc's angular half-width). A disc covering o is always in view.
- **Line of sight** (`unoccluded`, when `occlusion` is on): at least one of three sight lines from o is clear: the
  line to c_i and the lines to the two points where the tangents from o touch i's disc (its left and right edges as
  the robot sees them). A sight line is blocked by a wall segment it crosses (`envs.scoring.geometry.ray_distances`)
  or by another pedestrian's disc it passes through (that pedestrian's centre closer than its radius to the line,
  `planner.point_segment_distances`); every pedestrian's body blocks, whether perceived or not. A disc covering o (a
  contact) blocks nothing and is always seen. Three lines are an approximation: someone whose middle and both edges
  are hidden is hidden, even if a sliver of them shows between two occluders.

A pedestrian is perceived when both hold (each only when enabled). Everything is vectorised numpy: the people pass is
O(N^2) (3 N sight lines against N discs), the wall pass O(N W).
"""

from __future__ import annotations

import math

import numpy as np

from envs.config import CrowdNavConfig
from envs.history import TRACK_ROWS, PedHistory
from envs.scoring.geometry import ray_distances
from envs.timing import PredictionTiming
from envs.view import Pedestrians
from planner import point_segment_distances

FULL_CIRCLE_DEG = 360.0
MOVING_MPS = 1e-3  # a holonomic robot slower than this keeps its sensor heading (`sensor_heading`), m/s


def sensor_heading(robot_state: np.ndarray, unicycle: bool, last_heading_rad: float) -> float:
    """The direction the sensor faces, rad (world frame): a unicycle's heading robot_state[2]; a holonomic robot's
    (state x, y, vx, vy) direction of motion, or `last_heading_rad` (the env keeps the last direction of motion,
    the direction of the goal at the start) while it moves slower than MOVING_MPS."""
    if unicycle:
        return float(robot_state[2])
    vx, vy = float(robot_state[2]), float(robot_state[3])
    return math.atan2(vy, vx) if math.hypot(vx, vy) >= MOVING_MPS else float(last_heading_rad)


def in_field_of_view(origin: np.ndarray, heading_rad: float, fov_deg: float, pos: np.ndarray,
                     radius: np.ndarray) -> np.ndarray:
    """(N,) bool: whether some part of each body disc (centres pos (N, 2) m, radii radius (N,) m) lies within
    fov_deg / 2 degrees of the heading (rad) as seen from origin (2,) m; all True for fov_deg >= 360."""
    if fov_deg >= FULL_CIRCLE_DEG:
        return np.ones(len(pos), bool)
    rel = pos - origin
    dist = np.sqrt((rel * rel).sum(-1))
    off = np.abs((np.arctan2(rel[:, 1], rel[:, 0]) - heading_rad + np.pi) % (2 * np.pi) - np.pi)  # 0..pi rad
    half_width = np.arcsin(np.minimum(1.0, radius / np.maximum(dist, 1e-12)))
    return (dist <= radius) | (off <= math.radians(fov_deg) / 2 + half_width)


def sight_points(origin: np.ndarray, pos: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(N, 3, 2) m: the ends of each pedestrian's three sight lines from origin (2,): its centre and the two points
    where the tangents from origin touch its disc (centres pos (N, 2) m, radii radius (N,) m). For a disc covering
    origin the three are its centre."""
    rel = pos - origin
    dist = np.sqrt((rel * rel).sum(-1))
    bearing = np.arctan2(rel[:, 1], rel[:, 0])
    outside = dist > radius
    half = np.where(outside, np.arcsin(np.minimum(1.0, radius / np.maximum(dist, 1e-12))), 0.0)
    reach = np.where(outside, np.sqrt(np.maximum(dist * dist - radius * radius, 0.0)), dist)
    angles = bearing[:, None] + np.stack([np.zeros_like(half), half, -half], axis=1)  # (N, 3)
    lengths = np.stack([dist, reach, reach], axis=1)
    return origin + lengths[..., None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)


def unoccluded(origin: np.ndarray, pos: np.ndarray, radius: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """(N,) bool: whether at least one of each pedestrian's three sight lines (`sight_points`) from origin (2,) m is
    crossed by no wall segment of walls (W, 4) m (x0, y0, x1, y1) and passes through no other pedestrian's disc
    (centres pos (N, 2) m, radii radius (N,) m). Discs covering origin block nothing and are always seen."""
    n = len(pos)
    if n == 0:
        return np.zeros(0, bool)
    ends = sight_points(origin, pos, radius)  # (N, 3, 2)
    rel = ends - origin
    length = np.sqrt((rel * rel).sum(-1))  # (N, 3)
    clear = np.ones((n, 3), bool)
    walls = np.asarray(walls, float).reshape(-1, 4)
    if len(walls):
        angles = np.arctan2(rel[..., 1], rel[..., 0]).reshape(-1)
        hit = ray_distances(origin, angles, walls.reshape(-1, 2, 2), math.inf).reshape(n, 3)
        clear &= hit >= length
    centre_dist = np.sqrt(((pos - origin) ** 2).sum(-1))
    blocker = centre_dist > radius  # a disc covering the robot's centre blocks nothing
    if n > 1 and blocker.any():
        lines = np.concatenate([np.broadcast_to(origin, (n * 3, 2)), ends.reshape(-1, 2)], axis=1)  # (3N, 4)
        through = point_segment_distances(pos[blocker], lines).reshape(-1, n, 3) < radius[blocker, None, None]
        others = np.flatnonzero(blocker)[:, None] != np.arange(n)[None, :]  # (B, N): a disc never hides itself
        clear &= ~(through & others[..., None]).any(axis=0)
    return clear.any(axis=1) | ~blocker


def perceived(origin: np.ndarray, heading_rad: float, pos: np.ndarray, radius: np.ndarray, walls: np.ndarray,
              fov_deg: float = FULL_CIRCLE_DEG, occlusion: bool = False) -> np.ndarray:
    """(N,) bool: who the sensor at origin (2,) m facing heading_rad perceives among the pedestrians (centres pos
    (N, 2) m, radii radius (N,) m), walls (W, 4) m: in the field of view (fov_deg) and, with occlusion on, in a line
    of sight (the module docstring's rule)."""
    keep = in_field_of_view(origin, heading_rad, fov_deg, pos, radius)
    if occlusion and keep.any():
        keep &= unoccluded(origin, pos, radius, walls)
    return keep


def rows_of(p: Pedestrians, keep: np.ndarray | None) -> Pedestrians:
    """The rows of `p` that `keep` (N,) bool selects; `p` itself when keep is None."""
    return p if keep is None else Pedestrians(*(a[keep] for a in (p.pos, p.vel, p.radius, p.group_id, p.ped_id)))


class Senses:
    """`CrowdNavEnv`'s perception and memory (the env delegates to it; its docstring states the rules): who the sensor
    perceives now (`ObservationConfig`'s sensor_gap_m, fov_deg and occlusion), its heading, and the histories of
    positions (`envs.history.PedHistory`: the predictor's 8 rows, the group rules' 48) that hold, with a limited view,
    only whom it has perceived since they last came into sight. `walls` (S, 4) m: the scene's wall segments."""

    def __init__(self, config: CrowdNavConfig, walls: np.ndarray, timing: PredictionTiming) -> None:
        self.config = config
        self.walls = np.asarray(walls, float).reshape(-1, 4)
        self.timing = timing
        self.history = PedHistory(timing.obs_len)
        self.track_history = PedHistory(TRACK_ROWS)  # the group rules' longer past (`track`)
        self.limited = config.observation.limited_view  # fov_deg < 360 or occlusion (`envs.perception`)
        self.placed = False  # whether the robot is in the scene (the limited view starts then)
        self.heading_rad = 0.0  # a holonomic robot's sensor heading while it stands (`heading`)
        self._seen_cache: tuple[object, int, np.ndarray | None] = (None, -1, None)
        self._remembered: set[int] = set()  # the ids the histories hold (limited view)

    def clear(self) -> None:
        """Forget everything (a new episode; the robot not yet placed)."""
        self.history.clear()
        self.track_history.clear()
        self.placed = False

    def place(self, heading_rad: float, people: Pedestrians) -> None:
        """The robot enters the scene facing `heading_rad`; with a limited view, `people` (everyone now) are the ids
        remembered until the next `observe` forgets those hidden."""
        self.placed, self.heading_rad = True, heading_rad
        self._seen_cache = (None, -1, None)
        if self.limited:
            self._remembered = {int(i) for i in people.ped_id}

    @property
    def sensing(self) -> bool:
        """Whether the limited view applies now (it starts when the robot is placed)."""
        return self.limited and self.placed

    def heading(self, robot_state: np.ndarray) -> float:
        """The direction the sensor faces, rad (`sensor_heading`)."""
        return sensor_heading(robot_state, self.config.robot.model == "unicycle", self.heading_rad)

    def mask(self, p: Pedestrians, robot_state: np.ndarray, state: object, step: int) -> np.ndarray | None:
        """(N,) bool: the rows of `p` (everyone now, crowd state `state` at sim step `step`) the sensor perceives:
        within its surface gap and, with a limited view, in its field of view and line of sight; None when every row
        is (always so by default: the gap inf, 360 degrees, no occlusion)."""
        gap = self.config.observation.sensor_gap_m
        seen = self._seen(p, robot_state, state, step) if self.sensing else None
        if not math.isfinite(gap) or len(p.pos) == 0:
            return seen
        d = p.pos - robot_state[:2]
        keep = np.sqrt((d * d).sum(-1)) - p.radius - self.config.robot.radius_m <= gap
        if seen is not None:
            keep &= seen
        return None if keep.all() else keep

    def _seen(self, p: Pedestrians, robot_state: np.ndarray, state: object, step: int) -> np.ndarray | None:
        """(N,) bool: the rows of `p` in the field of view and line of sight (`perceived`), computed
        once per state and step; None when every row is."""
        cached_state, cached_step, seen = self._seen_cache
        if cached_state is not state or cached_step != step:
            obs = self.config.observation
            keep = perceived(robot_state[:2], self.heading(robot_state), p.pos, p.radius, self.walls, obs.fov_deg,
                             obs.occlusion)
            seen = None if keep.all() else keep
            self._seen_cache = (state, step, seen)
        return seen

    def observe(self, p: Pedestrians, robot_state: np.ndarray, state: object, step: int) -> None:
        """Every sim step: whoever went out of sight is forgotten (limited view), the perceived rows of `p` (everyone
        now) are observed at time step x dt_s."""
        if self.sensing:
            p = rows_of(p, self.mask(p, robot_state, state, step))
            ids = {int(i) for i in p.ped_id}
            gone = sorted(self._remembered - ids)
            self.history.forget(gone)
            self.track_history.forget(gone)
            self._remembered = ids
        self.history.observe(step * self.config.dt_s, p.ped_id, p.pos)

    def record(self, p: Pedestrians, robot_state: np.ndarray, state: object, step: int) -> None:
        """On a 0.4 s tick: the perceived rows of `p` (everyone now) become the histories' newest snapshot."""
        if self.sensing:
            p = rows_of(p, self.mask(p, robot_state, state, step))
        self.history.record(p.ped_id, p.pos)
        self.track_history.record(p.ped_id, p.pos)

    def window(self, p: Pedestrians, step: int, rows: int | None = None) -> np.ndarray:
        """`CrowdNavEnv.history_window` of the rows `p` at sim step `step`."""
        tick = self.config.ticks_per_prediction_step
        return self.history.window_now(p.ped_id, p.pos, (step % tick) / tick, self.timing.step_s, rows)

    def track(self, p: Pedestrians, step: int, window: np.ndarray) -> np.ndarray:
        """`CrowdNavEnv.track_window` of the rows `p` at sim step `step`, `window` their `window`."""
        tick = self.config.ticks_per_prediction_step
        return self.track_history.track_now(p.ped_id, p.pos, (step % tick) / tick, window)
