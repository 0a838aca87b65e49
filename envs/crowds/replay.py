"""`ReplayCrowd`: pedestrians replayed from an ETH/UCY-format recording, behind the env's `Crowd` protocol.

The pedestrians are non-reactive: they follow their recorded tracks whatever the robot does. Positions at env
times are linearly interpolated between a pedestrian's annotated frames, and its velocity is the slope of the
segment it is on, so the two are consistent. A pedestrian is in the scene from its first to its last annotated
time (gaps inside a track are bridged by the interpolation). When the recording ends the crowd empties; the
env's time limit ends the episode (`finished` tells when no pedestrian will appear again).

Times: the recording's time 0 is its first frame id; one annotation step (the most common positive difference
of consecutive distinct frame ids, unless given) lasts `frame_step_s`: given, or taken from `KNOWN_FRAME_STEPS_S`
by the file's name (biwi_eth 0.6667 s, the other ETH/UCY recordings 0.4 s), or else 0.4 s (the ETH/UCY format's
convention, which crowdsim's exports follow). The episode starts at `start_time_s` of
the recording, fixed or drawn at `reset`; `CrowdState.time_s` counts from the episode start.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crowdsim.state import CrowdState
from crowdsim.trajnet import SUFFIX as TRAJNET_SUFFIX
from crowdsim.trajnet import read_trajnet
from envs.crowds.crowd import match_ids
from envs.crowds.replay_overlay import overlay_rows
from predictor.ethucy import (  # the one ETH/UCY reader (torch-free)
    GROUP_OVERLAPS,
    STEP_S,
    GroupFileWarning,
    read_groups,
    read_trajectories,
)

START_MODES = ("random", "fixed")
DEFAULT_FRAME_STEP_S = STEP_S  # the ETH/UCY format's annotation step (owned by predictor.ethucy)
# Seconds per annotation step of the known recordings, by file stem (a `_train`/`_val` suffix of the benchmark's
# split files is ignored). biwi_eth is the exception: its frame ids advance by 10 per ~0.667 s (the original
# annotation steps 6 frames at 2.5 fps, the benchmark counts 10); the suites state the same values per cell.
KNOWN_FRAME_STEPS_S = {
    "biwi_eth": 0.6667, "biwi_hotel": 0.4, "crowds_zara01": 0.4, "crowds_zara02": 0.4, "crowds_zara03": 0.4,
    "students001": 0.4, "students003": 0.4, "uni_examples": 0.4,
}


def known_frame_step(path: Path | str) -> float | None:
    """The annotation step (s) of a known recording (`KNOWN_FRAME_STEPS_S`) by its file name; None if unknown."""
    stem = Path(path).stem
    for suffix in ("_train", "_val", "_test"):
        stem = stem.removesuffix(suffix)
    return KNOWN_FRAME_STEPS_S.get(stem)


_SNAP = 1e-9  # times within this many annotation steps of a whole step are snapped onto it


@dataclass(frozen=True)
class ReplayConfig:
    """How to replay a recording.

    Attributes:
        path: trajectory file, rows `frame ped x y` (m), tab- or whitespace-separated, or a TrajNet++ `.ndjson`
            file (`crowdsim.trajnet`).
        groups_path: optional group file, one group per line (ped ids separated by whitespace); a pedestrian
            not listed is its own group. None: every pedestrian is alone.
        group_overlaps: a pedestrian listed on two lines of the group file: "error" (refuse the file) or "merge"
            (merge those lines' groups; each merge is noted in `ReplayCrowd.group_notes`; `predictor.ethucy`).
        frame_step_s: seconds per annotation step; None (the default): the known recording's own
            (`known_frame_step`: biwi_eth 0.6667, the other ETH/UCY files 0.4), else `DEFAULT_FRAME_STEP_S`.
            The config holds the resolved value.
        frame_increment: frame-id increment per annotation step; None infers it from the file.
        dt_s: time one env step advances, s.
        ped_radius_m: body radius given to every pedestrian, m.
        route_margin_m: inset of the robot's start and goal from the trajectories' bounding box, m.
        route_clearance_m: a robot start counts as free when every pedestrian's centre is farther than
            `ped_radius_m + route_clearance_m` from it, m.
        route_tries: draws of the robot route before settling for the one with the most clearance.
        bounds_margin_m: margin added around the trajectories (and walls) to make `bounds`, m.
        start_mode: "random": each episode starts at a time drawn uniformly from
            [start_time_s, duration_s - min_remaining_s] with `np.random.default_rng(seed)`; "fixed": at
            `start_time_s`.
        start_time_s: fixed start, or earliest random start, s of recording time.
        min_remaining_s: recording time a random start leaves before the end (clipped to what exists), s.
        capacity: rows of the state arrays; None: the most pedestrians ever in the scene at once.
        walls: wall segments ((x0, y0), (x1, y1)) in m; none by default.
        name: scenario name; None: the trajectory file's stem (with `_x<overlay>` when overlaid).
        overlay: superimpose this many circularly time-shifted copies of the recording (`envs.crowds.replay_overlay`):
            a crowd K times as dense from a sparse recording; 1 (the default): the recording as it is. Not with a
            group file (the copies' ids are new).
    """

    path: Path | str
    groups_path: Path | str | None = None
    group_overlaps: str = "error"
    frame_step_s: float | None = None
    frame_increment: float | None = None
    dt_s: float = 0.1
    ped_radius_m: float = 0.25
    route_margin_m: float = 1.5
    route_clearance_m: float = 0.5
    route_tries: int = 10
    bounds_margin_m: float = 1.0
    start_mode: str = "random"
    start_time_s: float = 0.0
    min_remaining_s: float = 0.0
    capacity: int | None = None
    walls: Sequence = ()
    name: str | None = None
    overlay: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        if self.frame_step_s is None:
            object.__setattr__(self, "frame_step_s", known_frame_step(self.path) or DEFAULT_FRAME_STEP_S)
        if self.groups_path is not None:
            object.__setattr__(self, "groups_path", Path(self.groups_path))
        if self.group_overlaps not in GROUP_OVERLAPS:
            raise ValueError(f"unknown group_overlaps {self.group_overlaps!r}; valid: {', '.join(GROUP_OVERLAPS)}")
        for key in ("frame_step_s", "dt_s", "ped_radius_m"):
            _check(math.isfinite(getattr(self, key)) and getattr(self, key) > 0, f"{key} must be > 0")
        for key in ("route_margin_m", "route_clearance_m", "bounds_margin_m", "start_time_s", "min_remaining_s"):
            _check(math.isfinite(getattr(self, key)) and getattr(self, key) >= 0, f"{key} must be >= 0")
        inc = self.frame_increment
        _check(inc is None or (math.isfinite(inc) and inc > 0), "frame_increment must be > 0 or None")
        _check(self.route_tries >= 1, "route_tries must be >= 1")
        _check(isinstance(self.overlay, int) and self.overlay >= 1, "overlay must be an integer >= 1")
        _check(self.overlay == 1 or self.groups_path is None, "overlay > 1 cannot take a group file (new ids)")
        _check(self.start_mode in START_MODES, f"start_mode must be one of {START_MODES}")
        _check(self.capacity is None or self.capacity >= 1, "capacity must be >= 1 or None")
        walls = np.asarray(self.walls, dtype=float)
        _check(walls.size == 0 or (walls.ndim == 3 and walls.shape[1:] == (2, 2)), "walls must be (W, 2, 2)")
        _check(bool(np.all(np.isfinite(walls))), "walls must be finite")
        object.__setattr__(self, "walls", tuple(tuple(map(tuple, w)) for w in walls.reshape(-1, 2, 2).tolist()))

    @property
    def walls_array(self) -> np.ndarray:
        """(W, 2, 2) wall segments, m."""
        return np.asarray(self.walls, dtype=float).reshape(-1, 2, 2)


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(message)


def read_rows(path: Path) -> np.ndarray:
    """(R, 4) ``frame ped x y`` rows of a recording: an ETH/UCY text file (`predictor.ethucy`) or, by its
    ``.ndjson`` suffix, a TrajNet++ file's track rows (`crowdsim.trajnet`; its ``group`` fields are not used:
    groups come from `groups_path`)."""
    return read_trajnet(path).rows if path.suffix == TRAJNET_SUFFIX else read_trajectories(path)


def _snap(u: float) -> float:
    """u (annotation steps) snapped onto the nearest whole step when within `_SNAP` of it."""
    return float(round(u)) if abs(u - round(u)) < _SNAP else u


def infer_frame_increment(frames: np.ndarray) -> float:
    """The most common positive difference of consecutive distinct frame ids (ties: the smallest); 1 when the
    file has a single frame."""
    diffs = np.round(np.diff(np.unique(frames)), 9)
    if diffs.size == 0:
        return 1.0
    values, counts = np.unique(diffs, return_counts=True)
    return float(values[np.argmax(counts)])


def assign_slots(first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Rows for pedestrians present over the closed intervals [first, last] (P,), so that no two present at the
    same time share a row: greedy colouring by start time, which uses as many rows as the most pedestrians
    present at once (the number of rows is `slots.max() + 1`)."""
    slots = np.empty(len(first), np.int64)
    free_at: list[float] = []  # per row, the time its last pedestrian leaves
    for p in np.lexsort((last, first)):
        row = next((r for r, t in enumerate(free_at) if t < first[p]), len(free_at))
        if row == len(free_at):
            free_at.append(0.0)
        free_at[row] = last[p]
        slots[p] = row
    return slots


class ReplayCrowd:
    """Pedestrians replayed from a recording (see the module docstring); satisfies `envs.crowds.crowd.Crowd`.

    Attributes:
        config: the `ReplayConfig`.
        name: scenario name.
        walls: (W, 2, 2) wall segments, m (empty (0, 2, 2) unless configured).
        bounds: (x_min, y_min, x_max, y_max): the trajectories' (and walls') bounding box plus the margin, m.
        dt_s: time one `step()` advances, s.
        capacity: rows of the state arrays.
        ped_ids: (P,) int file ids of all pedestrians, ascending.
        duration_s: recording time from the first to the last annotated frame, s.
        start_time_s: recording time at which the current episode started, s.
        robot: (pos (2,) m, vel (2,) m/s, radius m) last given by `set_robot`, or None; it moves nobody.
    """

    @property
    def group_labels(self) -> bool:
        """True when the recording came with a group file (see `Crowd`)."""
        return self.config.groups_path is not None

    def __init__(self, config: ReplayConfig) -> None:
        self.config = config
        self.name = config.name or config.path.stem + (f"_x{config.overlay}" if config.overlay > 1 else "")
        self.dt_s = config.dt_s
        self.walls = config.walls_array
        rows = read_rows(config.path)
        if config.overlay > 1:
            rows = overlay_rows(rows, config.overlay, config.frame_increment or infer_frame_increment(rows[:, 0]))
        self._load_tracks(rows)
        self._load_groups()
        self.bounds = self._bounds()
        self.duration_s = float(self._last.max()) * config.frame_step_s
        needed = int(self._slot.max()) + 1
        if config.capacity is not None and config.capacity < needed:
            raise ValueError(f"capacity {config.capacity} < {needed} pedestrians present at once in {config.path}")
        self.capacity = config.capacity or needed
        if config.start_time_s > self.duration_s:
            raise ValueError(f"start_time_s {config.start_time_s} is past the recording's end ({self.duration_s} s)")
        self.robot: tuple[np.ndarray, np.ndarray, float] | None = None
        self.start_time_s = config.start_time_s
        self._step = 0
        self._state = self._make_state()

    # ----- loading -----
    def _load_tracks(self, rows: np.ndarray) -> None:
        """Per pedestrian (ascending id): knot times u (annotation steps from the first frame) and positions."""
        inc = self.config.frame_increment or infer_frame_increment(rows[:, 0])
        rows = rows[np.lexsort((rows[:, 0], rows[:, 1]))]
        ids, starts = np.unique(rows[:, 1], return_index=True)
        self.ped_ids = ids.astype(np.int64)
        u = (rows[:, 0] - rows[:, 0].min()) / inc
        self._u = np.split(u, starts[1:])
        self._xy = np.split(rows[:, 2:4], starts[1:])
        self._first = np.array([k[0] for k in self._u])
        self._last = np.array([k[-1] for k in self._u])
        self._goal = np.array([p[-1] for p in self._xy])
        self._slot = assign_slots(self._first, self._last)
        self._all_xy = rows[:, 2:4]

    def _load_groups(self) -> None:
        """Global group label per pedestrian: the group file's line order, then one label per lone pedestrian."""
        label = np.full(len(self.ped_ids), -1, np.int64)
        index = {int(p): i for i, p in enumerate(self.ped_ids)}
        path = self.config.groups_path
        with warnings.catch_warnings(record=True) as merges:  # kept as notes, not printed by every worker
            warnings.simplefilter("always", GroupFileWarning)
            groups = read_groups(path, self.config.group_overlaps) if path is not None else ()
        self.group_notes = tuple(str(w.message) for w in merges)
        for g, members in enumerate(groups):
            label[[index[m] for m in members if m in index]] = g
        lone = label < 0
        label[lone] = label.max(initial=-1) + 1 + np.arange(int(lone.sum()))
        self._label = label

    def _bounds(self) -> tuple[float, float, float, float]:
        pts = np.concatenate([self._all_xy, self.walls.reshape(-1, 2)])
        m = self.config.bounds_margin_m
        lo, hi = pts.min(axis=0) - m, pts.max(axis=0) + m
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    # ----- time -----
    @property
    def recording_time_s(self) -> float:
        """Recording time of the current state, s."""
        return self.start_time_s + self._step * self.dt_s

    @property
    def finished(self) -> bool:
        """True once the recording has ended: no pedestrian is or will be in the scene."""
        return self._u_now() > self._last.max()

    def track_age_s(self, ped_id: int) -> float:
        """Recording time since pedestrian `ped_id`'s track began (its first annotated frame), s."""
        i = int(np.searchsorted(self.ped_ids, ped_id))
        if i >= len(self.ped_ids) or self.ped_ids[i] != ped_id:
            raise KeyError(f"no pedestrian {ped_id} in {self.config.path}")
        return (self._u_now() - float(self._first[i])) * self.config.frame_step_s

    def _u_now(self) -> float:
        """Current time in annotation steps from the first frame."""
        cfg = self.config
        return _snap(self.start_time_s / cfg.frame_step_s + self._step * (cfg.dt_s / cfg.frame_step_s))

    # ----- Crowd protocol -----
    def reset(self, seed: int | None) -> CrowdState:
        """Start an episode; "random" mode draws the start time with `np.random.default_rng(seed)`."""
        cfg = self.config
        if cfg.start_mode == "random":
            hi = max(cfg.start_time_s, self.duration_s - cfg.min_remaining_s)
            self.start_time_s = float(np.random.default_rng(seed).uniform(cfg.start_time_s, hi))
        else:
            self.start_time_s = cfg.start_time_s
        self._step = 0
        self._state = self._make_state()
        return self._state

    def step(self) -> CrowdState:
        """Advance `dt_s` seconds along the recording and return the new state."""
        self._step += 1
        self._state = self._make_state()
        return self._state

    def state(self) -> CrowdState:
        """The current state (as last returned by `reset` or `step`)."""
        return self._state

    def set_robot(self, pos: np.ndarray, vel: np.ndarray, radius_m: float) -> None:
        """Record the robot (pos (2,) m, vel (2,) m/s, radius m); the replayed pedestrians ignore it."""
        self.robot = (np.array(pos, dtype=float), np.array(vel, dtype=float), float(radius_m))

    def clear_robot(self) -> None:
        self.robot = None

    def robot_route(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A start (2,) and goal (2,) in m on opposite sides of the trajectories' bounding box along its longer
        axis, inset by `route_margin_m` (at most a quarter of that side), with lateral offsets drawn over the
        middle half of the other side, in random order. Up to `route_tries` draws look for a start clear of the
        pedestrians present now (call after `reset`); failing that, the draw with the most clearance is kept."""
        cfg = self.config
        best, best_gap = None, -np.inf
        for _ in range(cfg.route_tries):
            start, goal = self._draw_route(rng)
            gap = self._clearance(start)
            if gap > best_gap:
                best, best_gap = (start, goal), gap
            if gap > cfg.ped_radius_m + cfg.route_clearance_m:
                break
        return best

    def _draw_route(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self._all_xy.min(axis=0), self._all_xy.max(axis=0)
        axis = 0 if (hi[0] - lo[0]) >= (hi[1] - lo[1]) else 1
        inset = min(self.config.route_margin_m, 0.25 * (hi[axis] - lo[axis]))
        mid, quarter = 0.5 * (lo[1 - axis] + hi[1 - axis]), 0.25 * (hi[1 - axis] - lo[1 - axis])
        start, goal = np.empty(2), np.empty(2)
        start[axis], goal[axis] = lo[axis] + inset, hi[axis] - inset
        start[1 - axis], goal[1 - axis] = rng.uniform(mid - quarter, mid + quarter, 2)
        return (start, goal) if rng.uniform() < 0.5 else (goal, start)

    def _clearance(self, point: np.ndarray) -> float:
        """Distance from point (2,) to the nearest pedestrian centre in the current state, m (inf if none)."""
        pos = self._state.pos[self._state.active]
        return float(np.linalg.norm(pos - point, axis=1).min()) if len(pos) else np.inf

    def future(self, ped_ids: np.ndarray, times_s: np.ndarray) -> np.ndarray:
        """Privileged (the oracle's; `envs.crowds.crowd.Crowd.future`): the recorded positions (T, N, 2) m of
        pedestrians `ped_ids` (N,) at `times_s` (T,) s from now, interpolated as the replay does, NaN once a track has
        ended."""
        out = np.full((len(times_s), len(ped_ids), 2), np.nan)
        for k, t in enumerate(np.asarray(times_s, float)):
            ids, pos, _ = self.positions_at(self.recording_time_s + t)
            at, found = match_ids(ids, ped_ids)
            out[k, found] = pos[at]
        return out

    # ----- state -----
    def positions_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pedestrians present at recording time `time_s` (s): their ids (A,) (ascending), positions (A, 2) m
        and velocities (A, 2) m/s, interpolated linearly between annotated frames."""
        idx, pos, vel = self._interpolate(_snap(time_s / self.config.frame_step_s))
        return self.ped_ids[idx], pos, vel

    def _interpolate(self, u: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Indices (A,) into `ped_ids` of the pedestrians present at u (annotation steps from the first frame),
        their positions (A, 2) m and velocities (A, 2) m/s."""
        idx = np.flatnonzero((self._first <= u) & (u <= self._last))
        pos, vel = np.zeros((len(idx), 2)), np.zeros((len(idx), 2))
        for row, p in enumerate(idx):
            knots, xy = self._u[p], self._xy[p]
            if len(knots) == 1:
                pos[row] = xy[0]
                continue
            i = min(int(np.searchsorted(knots, u, side="right")) - 1, len(knots) - 2)
            w = (u - knots[i]) / (knots[i + 1] - knots[i])
            pos[row] = (1.0 - w) * xy[i] + w * xy[i + 1]
            vel[row] = (xy[i + 1] - xy[i]) / ((knots[i + 1] - knots[i]) * self.config.frame_step_s)
        return idx, pos, vel

    def _make_state(self) -> CrowdState:
        c = self.capacity
        idx, pos_a, vel_a = self._interpolate(self._u_now())
        rows = self._slot[idx]
        active = np.zeros(c, bool)
        active[rows] = True
        pos, vel, goal = (np.full((c, 2), np.nan) for _ in range(3))
        pos[rows], vel[rows], goal[rows] = pos_a, vel_a, self._goal[idx]
        radius = np.where(active, self.config.ped_radius_m, np.nan)
        group, ped, label = np.full(c, -1, np.int64), np.full(c, -1, np.int64), np.full(c, -1, np.int64)
        group[rows] = np.unique(self._label[idx], return_inverse=True)[1]
        label[rows] = self._label[idx]
        ped[rows] = self.ped_ids[idx]
        return CrowdState(pos=pos, vel=vel, goal=goal, radius=radius, group_id=group, ped_id=ped,
                          active=active, label=label, frame=self._step, time_s=self._step * self.dt_s)
