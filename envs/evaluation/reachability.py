"""What any robot could do in an episode: reachable-set bounds on success, for crowds that ignore the robot.

Where the crowd does not react to the robot (a replayed recording, or simulated people who do not see it), the
pedestrians' whole future is fixed by the episode's seed. Whether *some* robot could have reached the goal in time
without touching anybody is then a geometric question, answered here on a grid over the scene, by two reachable
sets stepped forward in time from the robot's start (`reach`):

- **optimistic** (an upper bound on what any robot can do): a holonomic robot at up to `max_speed_mps` with no
  acceleration or turn-rate limit, checked against pedestrians only every `optimistic_dt_s`. Every grid cell that
  may hold a reachable point is kept: the set grows by `max_speed * optimistic_dt + h * sqrt(2)` per check (h the
  cell side) and pedestrians shrink by half a cell diagonal. A pedestrian is ignored during its first
  `SPAWN_WINDOW_S` in view (the env does not end an episode on a contact that began as a spawn; a robot riding
  along such a pedestrian past that window is not modelled). An env step that can end within the goal
  tolerance, clear of everybody then, counts as arrival. If this set never arrives before the time limit, **no
  robot at that speed could have succeeded**: the episode is "infeasible", whatever the planner. Its first
  arrival is a lower bound on any robot's time to goal.
- **conservative** (a witness): a holonomic robot moving from grid centre to grid centre at most
  `max_speed * dt_s` per env step (env steps finer than MIN_STEP_S are strided: a straight move over several steps),
  keeping at every step the clearance that makes the env's swept contact test (closest approach of the two straight
  motions over the step) pass, and the env's wall test. If it reaches
  the goal, a contact-free path exists for a holonomic robot at that speed: the episode is "feasible". The
  benchmark's robot is a unicycle with acceleration limits, so a feasible episode may still be out of its reach.
- otherwise "open": neither bound decides.

Units: m, s. Grid: square cells of side h = the conservative step at full speed / `cells_per_step`, one centre at the
robot's start. The grid covers the scene, every pedestrian and the goal with a margin; outside it nothing
stands, and any path leaving it can be projected back onto its border (projection onto a box is 1-Lipschitz),
so the bounds hold for paths anywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from envs.config import REPLAY_SCENARIO, CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.scoring.collisions import SPAWN_WINDOW_S
from planner import point_segment_distances
from planner.foresight import dilate as _dilate  # the bounds and the planner's foresight search grow and trace alike
from planner.foresight import distance_to_marked as _distance
from planner.foresight import trace_back

VERDICTS = ("infeasible", "feasible", "open")
DEFAULT_CHECK_S = 0.2  # the optimistic set's check period by default: the smallest multiple of the env step >= this
MIN_STEP_S = 0.1  # the conservative set steps at least this long (whole env steps): finer env steps are strided


@dataclass(frozen=True)
class ReachConfig:
    """Grid settings. cells_per_step: the grid cell side is the robot's longest env step (max_speed * dt_s) divided
    by this (1.2 m/s, 0.1 s: 0.024 m), so that the witness moves whole cells at full speed along the axes;
    optimistic_dt_s: how often the optimistic set is checked against the pedestrians, s (None: the smallest whole
    multiple of the env step that is at least DEFAULT_CHECK_S; else a whole multiple of the
    env's dt_s; coarser means a looser bound, but each check adds a cell diagonal of slack, so the default 0.2 s
    keeps that at 0.17 m/s on top of the robot's 1.2 m/s)."""

    cells_per_step: int = 5
    optimistic_dt_s: float | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.cells_per_step, int) and 2 <= self.cells_per_step <= 20):
            raise ValueError(f"cells_per_step must be an integer in [2, 20], got {self.cells_per_step!r}")
        if self.optimistic_dt_s is not None and not (0.0 < self.optimistic_dt_s <= 1.0):
            raise ValueError(f"optimistic_dt_s must be in (0, 1] s, got {self.optimistic_dt_s}")

    def resolved(self, dt_s: float) -> ReachConfig:
        """This config with optimistic_dt_s set for an env step of dt_s (s); ValueError if it is not a whole
        multiple of it."""
        check = self.optimistic_dt_s
        if check is None:
            check = dt_s * math.ceil(DEFAULT_CHECK_S / dt_s - 1e-9)
        out = ReachConfig(self.cells_per_step, round(check, 12))
        out.steps_per_check(dt_s)
        return out

    def steps_per_check(self, dt_s: float) -> int:
        """Env steps between the optimistic set's checks; ValueError unless optimistic_dt_s is a whole multiple of
        dt_s (s)."""
        if self.optimistic_dt_s is None:
            return self.resolved(dt_s).steps_per_check(dt_s)
        every = int(round(self.optimistic_dt_s / dt_s))
        if every < 1 or abs(every * dt_s - self.optimistic_dt_s) > 1e-9:
            raise ValueError(f"optimistic_dt_s {self.optimistic_dt_s} must be a whole multiple of the env step {dt_s}")
        return every


@dataclass
class Course:
    """One episode's fixed geometry, from the robot's start (time 0) to the time limit.

    start, goal (2,) m; goal_tolerance_m; robot_radius_m; max_speed_mps; dt_s: env step, s; n_steps: the time
    limit in env steps; walls (W, 2, 2) m; ped_pos: per env step k = 0..n_steps an (n_k, 2) array of positions, m;
    ped_radius: per step (n_k,) m; ped_id: per step (n_k,) int; ped_fresh: per step (n_k,) bool, the pedestrian
    came into view less than SPAWN_WINDOW_S ago.
    """

    start: np.ndarray
    goal: np.ndarray
    goal_tolerance_m: float
    robot_radius_m: float
    max_speed_mps: float
    dt_s: float
    n_steps: int
    walls: np.ndarray
    ped_pos: list[np.ndarray]
    ped_radius: list[np.ndarray]
    ped_id: list[np.ndarray]
    ped_fresh: list[np.ndarray]


@dataclass(frozen=True)
class ReachResult:
    """verdict: one of VERDICTS; earliest_arrival_s: the optimistic set's first arrival (a lower bound on any robot's
    time to goal; None: infeasible); witness_arrival_s: the conservative set's first arrival (None: none found);
    path: (k + 1, 2) m, the witness's position at each env step when asked for (`reach(..., witness_path=True)`)."""

    verdict: str
    earliest_arrival_s: float | None
    witness_arrival_s: float | None
    path: np.ndarray | None = None


def crowd_is_fixed(config: CrowdNavConfig) -> bool:
    """Whether the crowd's future does not depend on the robot (a replay, or a robot nobody sees)."""
    return config.scenario == REPLAY_SCENARIO or not config.robot_visible


def course_of(config: CrowdNavConfig, seed: int) -> Course:
    """The episode `seed` of `config` as the env builds it (same start, goal and crowd), the crowd stepped to the
    time limit with the robot parked at its start (it does not see the robot). Raises ValueError where the crowd
    reacts to the robot."""
    if not crowd_is_fixed(config):
        raise ValueError("reachability needs a crowd that ignores the robot (a replay, or robot_visible false); "
                         f"scenario {config.scenario!r} sees the robot")
    cfg = replace(config, observation=replace(config.observation, predictions=False, prediction_calibration=False,
                                              group_source="truth"))
    env = CrowdNavEnv(cfg)
    env.reset(seed=seed)
    crowd, dt = env.crowd, cfg.dt_s
    age = getattr(crowd, "track_age_s", None)
    first_seen: dict[int, int] = {}
    pos, rad, pid, fresh = [], [], [], []
    for k in range(cfg.max_steps + 1):
        if k:
            state = crowd.step()
            now_pos, now_rad, ids = state.pos[state.active], state.radius[state.active], state.ped_id[state.active]
        else:
            p = env.pedestrians()
            now_pos, now_rad, ids = p.pos, p.radius, p.ped_id
        for i in ids:
            first_seen.setdefault(int(i), k if k else -10**9)
        if age is not None:
            f = np.array([age(int(i)) < SPAWN_WINDOW_S - 1e-9 for i in ids], bool)
        else:
            f = np.array([(k - first_seen[int(i)]) * dt < SPAWN_WINDOW_S - 1e-9 for i in ids], bool)
        pos.append(now_pos.copy())
        rad.append(now_rad.copy())
        pid.append(ids.copy())
        fresh.append(f)
    return Course(env.robot_state[:2].copy(), env.goal.copy(), cfg.goal_tolerance_m, cfg.robot.radius_m,
                  cfg.robot.max_speed_mps, dt, cfg.max_steps, np.asarray(crowd.walls, float).reshape(-1, 2, 2),
                  pos, rad, pid, fresh)


class Grid:
    """Square cells of side h with one centre exactly at `origin_cell`'s point; centres x0 + i h, y0 + j h."""

    def __init__(self, course: Course, h: float, margin_m: float) -> None:
        pts = [course.start[None], course.goal[None], course.walls.reshape(-1, 2)]
        pts += [p for p in course.ped_pos if len(p)]
        allp = np.concatenate(pts)
        lo, hi = allp.min(axis=0) - margin_m, allp.max(axis=0) + margin_m
        below = np.ceil((course.start - lo) / h)
        self.h = h
        self.x0 = course.start - below * h  # so that the start is a centre
        self.shape = tuple(int(n) for n in (np.ceil((hi - self.x0) / h) + 1).astype(int))
        self.start = tuple(int(b) for b in below)
        ii, jj = np.meshgrid(np.arange(self.shape[0]), np.arange(self.shape[1]), indexing="ij")
        self.xy = np.stack([self.x0[0] + ii * h, self.x0[1] + jj * h], axis=-1)  # (nx, ny, 2) centres, m
        self.goal_dist = np.hypot(*(self.xy - course.goal).transpose(2, 0, 1))
        if len(course.walls):
            self.wall_dist = point_segment_distances(self.xy, course.walls.reshape(-1, 4)).min(axis=-1)
        else:
            self.wall_dist = np.full(self.shape, np.inf)

    def blocked(self, pos: np.ndarray, clear: np.ndarray) -> np.ndarray:
        """(nx, ny) bool: centres closer than clear[i] m to pedestrian i at pos[i] (n, 2). One slice per disc: on
        this fine grid that is ~10x faster than one batched stencil for all discs (same cells)."""
        out = np.zeros(self.shape, bool)
        h = self.h
        for p, c in zip(pos, clear, strict=True):
            if c <= 0:
                continue
            lo = np.maximum(np.floor((p - c - self.x0) / h).astype(int), 0)
            hi = np.minimum(np.ceil((p + c - self.x0) / h).astype(int) + 1, self.shape)
            if np.any(hi <= lo):
                continue
            sub = self.xy[lo[0]:hi[0], lo[1]:hi[1]]
            out[lo[0]:hi[0], lo[1]:hi[1]] |= np.hypot(sub[..., 0] - p[0], sub[..., 1] - p[1]) < c
        return out


def _optimistic(course: Course, grid: Grid, every: int) -> float | None:
    """First time (s) the optimistic set can be at the goal, or None before the time limit (module docstring)."""
    h, half_diag, step_m = grid.h, grid.h / math.sqrt(2.0), course.max_speed_mps * course.dt_s
    free_wall = grid.wall_dist >= course.robot_radius_m - half_diag
    near_goal = (grid.goal_dist < course.goal_tolerance_m + half_diag) & free_wall
    reach = np.zeros(grid.shape, bool)
    reach[grid.start] = True
    for k in range(0, course.n_steps, every):
        dist = _distance(reach, step_m * every + h * math.sqrt(2.0), h)
        last = min(k + every, course.n_steps)
        for j in range(k + 1, last + 1):  # a step ending at the goal, free of everybody then, succeeds
            can = near_goal & (dist <= step_m * (j - k) + h * math.sqrt(2.0) + 1e-9)
            if can.any() and (can & ~_blocked_opt(course, grid, j)).any():
                return j * course.dt_s
        reach = (dist <= step_m * (last - k) + h * math.sqrt(2.0) + 1e-9) & free_wall \
            & ~_blocked_opt(course, grid, last)
        if not reach.any():
            return None
    return None


def _blocked_opt(course: Course, grid: Grid, k: int) -> np.ndarray:
    """Cells no point of which is clear of a pedestrian at env step k (fresh ones left out): centres within the
    contact distance less half a cell diagonal."""
    keep = ~course.ped_fresh[k]
    clear = course.ped_radius[k][keep] + course.robot_radius_m - grid.h / math.sqrt(2.0)
    return grid.blocked(course.ped_pos[k][keep], clear)


def _swept_margin(course: Course, stride: int = 1) -> float:
    """Extra clearance (m) at both ends of a conservative step of `stride` env steps that keeps every contact test
    the env makes in between passing. stride 1: the closest approach of the two straight motions over the step stays
    at least the contact distance when both ends keep sqrt(R^2 + (L / 2)^2) - R more, L the most the pair can move
    apart-wise in one step (the robot's max_speed * dt plus the fastest pedestrian step) and R the smallest contact
    distance. stride > 1 (people walk polylines in between): L itself, the robot's straight move plus the longest
    pedestrian path over the stride (by the triangle inequality)."""
    steps = []
    for k in range(course.n_steps):
        _, i, j = np.intersect1d(course.ped_id[k], course.ped_id[k + 1], return_indices=True)
        steps.append(float(np.max(np.hypot(*(course.ped_pos[k + 1][j] - course.ped_pos[k][i]).T))) if len(i) else 0.0)
    radii = [r for r in course.ped_radius if len(r)]
    if not radii:
        return 0.0
    if stride > 1:
        path = max((sum(steps[k:k + stride]) for k in range(0, len(steps), stride)), default=0.0)
        return course.max_speed_mps * course.dt_s * stride + path
    contact = float(np.min(np.concatenate(radii))) + course.robot_radius_m
    half = 0.5 * (course.max_speed_mps * course.dt_s + max(steps, default=0.0))
    return math.sqrt(contact * contact + half * half) - contact


def stride_of(dt_s: float) -> int:
    """Env steps per conservative step: 1 from MIN_STEP_S up, more for finer env steps (CrowdNav++'s 0.05 s)."""
    return max(1, int(round(MIN_STEP_S / dt_s)))


def _conservative(course: Course, grid: Grid, keep: bool, speed_mps: float | None = None,
                  extra_m: float = 0.0) -> tuple[float | None, np.ndarray | None]:
    """First time (s) the conservative set is at the goal (None: not before the time limit) and, if `keep`, a
    witness path (k + 1, 2) m, one point per env step from the start (grid centres every `stride_of(dt)` steps,
    straight lines between; module docstring). speed_mps: the witness's top speed (default the robot's); extra_m:
    clearance kept beyond the contact test, m."""
    stride = stride_of(course.dt_s)
    arrival, cells = conservative_run(course, grid, grid.start, 0, speed_mps, extra_m, keep=keep)
    if arrival is None:
        return None, None
    return arrival * course.dt_s, (fill_strides(np.array([grid.xy[c] for c in cells]), stride) if keep else None)


def conservative_run(course: Course, grid: Grid, start: tuple[int, int], first_step: int,
                     speed_mps: float | None = None, extra_m: float = 0.0, known: np.ndarray | None = None,
                     keep: bool = True, partial: bool = False) -> tuple[int | None, list[tuple[int, int]]]:
    """The conservative set stepped from grid cell `start` at env step `first_step` (a whole multiple of the
    stride) to the time limit, against the pedestrians whose ids are in `known` (None: everybody). Returns the env
    step of the first arrival at the goal (None: none) and, if `keep`, the witness's cells, one per stride from the
    start: traced back from the goal, or with `partial` and no arrival, from the cell of the last non-empty set
    nearest the goal (else []). speed_mps, extra_m: as in `_conservative`."""
    speed = course.max_speed_mps if speed_mps is None else speed_mps
    stride = stride_of(course.dt_s)
    h, margin, step_m = grid.h, _swept_margin(course, stride) + extra_m, speed * course.dt_s * stride
    pad = int(math.ceil(step_m / h)) + 1
    free_wall = grid.wall_dist >= course.robot_radius_m + extra_m + 1e-6
    at_goal = grid.goal_dist < course.goal_tolerance_m
    reach = np.zeros(grid.shape, bool)
    reach[start] = True
    history = [reach]
    for k in range(first_step + stride, course.n_steps + 1, stride):
        pos, radius = course.ped_pos[k], course.ped_radius[k]
        if known is not None:
            mine = np.isin(course.ped_id[k], known)
            pos, radius = pos[mine], radius[mine]
        nxt = _dilate(reach, step_m, h) & free_wall & ~grid.blocked(pos, radius + course.robot_radius_m + margin)
        if not nxt.any():
            break
        reach = nxt
        if keep:
            history.append(reach)
        if np.any(reach & at_goal):
            return k, (trace_back(history, tuple(np.argwhere(reach & at_goal)[0]), pad) if keep else [])
    if not (keep and partial):
        return None, []
    dist = np.where(reach, grid.goal_dist, np.inf)
    return None, trace_back(history, np.unravel_index(int(np.argmin(dist)), dist.shape), pad)


def fill_strides(corners: np.ndarray, stride: int) -> np.ndarray:
    """(n + 1, 2) points a stride apart -> (n * stride + 1, 2), straight lines between."""
    if stride == 1:
        return corners
    w = (np.arange(stride) / stride)[None, :, None]
    inner = corners[:-1, None] * (1 - w) + corners[1:, None] * w  # (n, stride, 2)
    return np.concatenate([inner.reshape(-1, 2), corners[-1:]])


def reach(course: Course, config: ReachConfig | None = None, witness_path: bool = False) -> ReachResult:
    """Both bounds for one course (module docstring); with `witness_path`, the result holds the conservative
    set's path (one grid centre per env step) when it found one."""
    cfg = config or ReachConfig()
    every = cfg.steps_per_check(course.dt_s)
    grid = grid_for(course, cfg, every)
    earliest = _optimistic(course, grid, every)
    witness, path = _conservative(course, grid, witness_path) if earliest is not None else (None, None)
    verdict = "infeasible" if earliest is None else "feasible" if witness is not None else "open"
    return ReachResult(verdict, earliest, witness, path)


def roomy_path(course: Course, config: ReachConfig | None = None, speed_fraction: float = 0.85,
               extra_m: float = 0.1) -> np.ndarray | None:
    """A conservative witness path (k + 1, 2) m, one point per env step, for a slower robot (speed_fraction of the
    top speed) that keeps extra_m more clearance from people and walls: room for a robot with acceleration and
    turn-rate limits to track it (`envs.evaluation.witness`). None where there is none before the time limit."""
    cfg = config or ReachConfig()
    grid = grid_for(course, cfg, cfg.steps_per_check(course.dt_s))
    return _conservative(course, grid, True, speed_fraction * course.max_speed_mps, extra_m)[1]


def grid_for(course: Course, cfg: ReachConfig, every: int) -> Grid:
    """The grid of a course: cell side = the robot's longest conservative step / cells_per_step."""
    h = course.max_speed_mps * course.dt_s * stride_of(course.dt_s) / cfg.cells_per_step
    return Grid(course, h, margin_m=course.robot_radius_m + 4 * h + course.max_speed_mps * course.dt_s * every)
