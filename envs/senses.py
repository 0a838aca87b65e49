"""What the env's robot perceives and remembers: the sensor's mask over the people now, and their histories.

`Senses` is `CrowdNavEnv`'s perception and memory (the env delegates to it; its docstring states the rules): who
the sensor perceives now (`ObservationConfig`'s sensor_gap_m, fov_deg and occlusion, `envs.perception`), the
sensor's heading, and the histories of positions (`envs.history.PedHistory`: the predictor's 8 rows and the group
rules' 48) that hold, with a limited view, only whom it has perceived since they last came into sight.
"""

from __future__ import annotations

import math

import numpy as np

from envs.config import CrowdNavConfig
from envs.history import TRACK_ROWS, PedHistory
from envs.perception import perceived, sensor_heading
from envs.timing import PredictionTiming
from envs.view import Pedestrians


def rows_of(p: Pedestrians, keep: np.ndarray | None) -> Pedestrians:
    """The rows of `p` that `keep` (N,) bool selects; `p` itself when keep is None."""
    return p if keep is None else Pedestrians(*(a[keep] for a in (p.pos, p.vel, p.radius, p.group_id, p.ped_id)))


class Senses:
    """The sensor and the histories of one env. `walls` (S, 4) m: the scene's wall segments (occlusion)."""

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
        """The direction the sensor faces, rad (`envs.perception.sensor_heading`)."""
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
        """(N,) bool: the rows of `p` in the field of view and line of sight (`envs.perception.perceived`), computed
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
