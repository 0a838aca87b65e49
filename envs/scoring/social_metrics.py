"""The field's social-navigation metrics of one episode, as pure vectorised functions of arrays (definitions and
sources: docs/envs.md, "Evaluation metrics (envs)"). The env feeds them one step at a time (`envs.scoring.metrics`); a
whole recorded episode can be passed at once, with the same results.

Shapes and units: robot positions (T + 1, 2) m at the step boundaries 0, dt, ..., T dt (the start included);
per-step robot quantities (T, 2); people (T, N, 2) m with `present` (T, N) bool marking the rows that hold a
person at that step (absent rows may be NaN; everything else must be finite); radii m; dt s; angles rad.
Bad input (NaN where a value is needed, wrong shapes, dt <= 0) raises ValueError.

- Hall zones (HuNavSim's measure): the distance from the robot's edge to the nearest person's centre,
  |robot - person| - robot_radius, falls in one band per step: intimate [.., 0.45), personal [0.45, 1.2),
  social [1.2, 3.6) m, or beyond (public, or nobody present). Bands are exclusive, as HuNavSim counts them.
- time to collision: constant-velocity time until the robot's disc touches a person's disc (0 in contact,
  inf when never on a collision course).
- group contact: contact (surface distance < 0) with a member of a group of >= 2 present people.
- path irregularity: mean over the steps the robot moved of the angle between its displacement and the straight
  line from where it was to the goal (SocNavBench's per-step angle to the goal), rad.
- jerk: mean over time of the magnitude of the third finite difference of position / dt**3 (SocNavBench), m/s^3.
- SPL: success * l / max(p, l), l = the straight start-goal distance minus the goal tolerance (Anderson et al.
  2018 with the shortest path taken as the straight line to the goal region), p the path travelled.
- ITR / SD (CrowdNav++, Liu et al. 2023; Shuijing725/CrowdNav_Prediction_AttnGraph): a state intrudes when the
  robot, where it is now, is closer than the radii sum to where a person present now will be 0.25, 0.5, ..., 1.25 s
  later (centre distances); ITR = intruding states / all T + 1 states of the episode (the terminal one counts,
  never intrudes), SD = the smallest such centre distance of an intruding state (`future_intrusions`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

HALL_ZONES_M: tuple[tuple[str, float], ...] = (("intimate", 0.45), ("personal", 1.2), ("social", 3.6))
ZONES: tuple[str, ...] = tuple(name for name, _ in HALL_ZONES_M)
_ZONE_EDGES: tuple[float, ...] = tuple(r for _, r in HALL_ZONES_M)
MIN_MOVE_M = 1e-6  # a displacement (or distance to the goal) below this has no direction


def _array(name: str, value: object, shape: tuple[int | None, ...], present: np.ndarray | None = None) -> np.ndarray:
    """`value` as a float array of `shape` (None: any size), finite wherever `present` (broadcast over the last
    axes) is True; ValueError otherwise."""
    a = np.asarray(value, dtype=float)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=True)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    check = a if present is None else a[present]
    if not np.all(np.isfinite(check)):
        raise ValueError(f"{name} must be finite (NaN or inf found)")
    return a


def _dt(dt_s: float) -> float:
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be positive and finite, got {dt_s!r}")
    return float(dt_s)


def _present(present: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """The (T, N) presence mask (all True when None)."""
    if present is None:
        return np.ones(shape, bool)
    p = np.asarray(present)
    if p.shape != shape or p.dtype != bool:
        raise ValueError(f"present must be a bool array of shape {shape}, got {p.dtype} {p.shape}")
    return p


def _people(people: object, t: int, present: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """People positions (T, N, 2) and their presence mask (T, N), checked."""
    raw = np.asarray(people, dtype=float)
    if raw.ndim != 3 or raw.shape[0] != t or raw.shape[2] != 2:
        raise ValueError(f"people must have shape ({t}, N, 2), got {raw.shape}")
    mask = _present(present, raw.shape[:2])
    return _array("people", raw, (t, None, 2), mask), mask


def _radii(name: str, radius: object, mask: np.ndarray) -> np.ndarray:
    """Per-person radii (N,) or (T, N) m broadcast to (T, N), finite and >= 0 where present."""
    r = np.asarray(radius, dtype=float)
    if r.shape not in (mask.shape, mask.shape[1:]):
        raise ValueError(f"{name} must have shape (N,) or (T, N) = {mask.shape}, got {r.shape}")
    r = np.broadcast_to(r, mask.shape)
    if not np.all(np.isfinite(r[mask])) or np.any(r[mask] < 0):
        raise ValueError(f"{name} must be finite and >= 0")
    return r


def _radius(name: str, value: float) -> float:
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return float(value)


# ------------------------------------------------------------------------------------------ Hall zones
def nearest_person_distance(robot: np.ndarray, people: np.ndarray, robot_radius_m: float,
                            present: np.ndarray | None = None) -> np.ndarray:
    """(T,) m: per step, the distance from the robot's edge to the nearest present person's centre,
    min_i |robot - people_i| - robot_radius_m (HuNavSim's measure); inf where nobody is present.
    robot (T, 2) m, people (T, N, 2) m, present (T, N) bool."""
    robot = _array("robot", robot, (None, 2))
    people, mask = _people(people, len(robot), present)
    centre = np.where(mask, np.linalg.norm(np.where(mask[..., None], people, 0.0) - robot[:, None], axis=-1), np.inf)
    return (centre.min(axis=1) if centre.shape[1] else np.full(len(robot), np.inf)) - _radius(
        "robot_radius_m", robot_radius_m)


def hall_zone_index(distance_m: np.ndarray) -> np.ndarray:
    """(T,) int per step from `nearest_person_distance` (T,) m: 0 intimate (< 0.45), 1 personal [0.45, 1.2),
    2 social [1.2, 3.6), 3 beyond 3.6 m or nobody present (inf)."""
    d = np.asarray(distance_m, dtype=float)
    if d.ndim != 1 or np.any(np.isnan(d)):
        raise ValueError(f"distance_m must be a (T,) array without NaN, got shape {d.shape}")
    return np.searchsorted(np.array(_ZONE_EDGES), d, side="right")


def zone_of(distance_m: float) -> int:
    """`hall_zone_index` of one distance (m): 0 intimate, 1 personal, 2 social, 3 beyond (the env's per step)."""
    if math.isnan(distance_m):
        raise ValueError("distance_m must not be NaN")
    return bisect.bisect_right(_ZONE_EDGES, distance_m)


def zone_steps(distance_m: np.ndarray) -> dict[str, int]:
    """Steps in each Hall zone (exclusive bands), keyed by `ZONES`, from per-step distances (T,) m."""
    idx = hall_zone_index(distance_m)
    return {name: int(np.count_nonzero(idx == k)) for k, name in enumerate(ZONES)}


def zone_times(robot: np.ndarray, people: np.ndarray, robot_radius_m: float, dt_s: float,
               present: np.ndarray | None = None) -> dict[str, float]:
    """Seconds spent in each Hall zone: dt_s x the steps whose robot position (T, 2) m, taken at the step's end,
    is in that zone of the people (T, N, 2) m. Divide by T dt_s for the fraction of episode time."""
    steps = zone_steps(nearest_person_distance(robot, people, robot_radius_m, present))
    return {name: n * _dt(dt_s) for name, n in steps.items()}


# ------------------------------------------------------------------------------------------ time to collision
def time_to_collision(rel_pos: np.ndarray, rel_vel: np.ndarray, radius_sum_m: np.ndarray | float) -> np.ndarray:
    """(...) s: the smallest t >= 0 with |rel_pos + t rel_vel| <= radius_sum_m, both moving at constant velocity;
    0 when the discs already touch, inf when they never will (moving apart, passing wide, or no relative motion).
    rel_pos (..., 2) m = person - robot; rel_vel (..., 2) m/s = person velocity - robot velocity."""
    p = _array("rel_pos", rel_pos, (*np.shape(rel_pos)[:-1], 2))
    v = _array("rel_vel", rel_vel, p.shape)
    r = np.broadcast_to(np.asarray(radius_sum_m, dtype=float), p.shape[:-1])
    if not np.all(np.isfinite(r)) or np.any(r < 0):
        raise ValueError("radius_sum_m must be finite and >= 0")
    # the smaller root of |p + t v|^2 = r^2 when the discs approach, 0 in contact, inf otherwise (the env's per-step
    # minimum over people is `envs.scoring.kernels.min_time_to_collision`, the same floats)
    a = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]
    b = 2.0 * (p[..., 0] * v[..., 0] + p[..., 1] * v[..., 1])
    c = p[..., 0] * p[..., 0] + p[..., 1] * p[..., 1] - r * r
    disc = b * b - 4.0 * a * c
    approaching = (a > 0) & (b < 0) & (disc >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(approaching, (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a), np.inf)
    return np.where(c <= 0, 0.0, t)


def step_time_to_collision(robot: np.ndarray, robot_vel: np.ndarray, people: np.ndarray, people_vel: np.ndarray,
                           people_radius_m: np.ndarray, robot_radius_m: float,
                           present: np.ndarray | None = None) -> np.ndarray:
    """(T,) s: per step, the smallest `time_to_collision` between the robot's disc and any present person's
    (inf when on no collision course). robot (T, 2) m and robot_vel (T, 2) m/s at the step's start; people
    (T, N, 2) m, people_vel (T, N, 2) m/s, people_radius_m (N,) or (T, N) m."""
    robot = _array("robot", robot, (None, 2))
    vel = _array("robot_vel", robot_vel, robot.shape)
    people, mask = _people(people, len(robot), present)
    pvel = _array("people_vel", people_vel, people.shape, mask)
    radii = _radii("people_radius_m", people_radius_m, mask)
    rel_p = np.where(mask[..., None], people - robot[:, None], 1.0)
    rel_v = np.where(mask[..., None], pvel - vel[:, None], 0.0)
    ttc = time_to_collision(rel_p, rel_v, np.where(mask, radii, 0.0) + _radius("robot_radius_m", robot_radius_m))
    ttc = np.where(mask, ttc, np.inf)
    return ttc.min(axis=1) if ttc.shape[1] else np.full(len(robot), np.inf)


def finite_difference_velocity(positions: np.ndarray, dt_s: float) -> np.ndarray:
    """(T, ..., 2) m/s: the velocity over each step, (x[k + 1] - x[k]) / dt_s, of positions (T + 1, ..., 2) m."""
    x = np.asarray(positions, dtype=float)
    if x.ndim < 2 or x.shape[-1] != 2 or len(x) < 2:
        raise ValueError(f"positions must have shape (T + 1, ..., 2) with T >= 1, got {x.shape}")
    return np.diff(x, axis=0) / _dt(dt_s)


# ------------------------------------------------------------------------------------------ groups
def group_sizes(group_id: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """(T, N) int: per step, how many present people share each person's group id (0 for absent rows and for
    negative ids, which mean "no group"). group_id (T, N) int."""
    g = np.asarray(group_id)
    if g.ndim != 2 or not np.issubdtype(g.dtype, np.integer):
        raise ValueError(f"group_id must be a (T, N) integer array, got {g.dtype} {g.shape}")
    mask = _present(present, g.shape) & (g >= 0)
    same = (g[:, :, None] == g[:, None, :]) & mask[:, :, None] & mask[:, None, :]
    return same.sum(axis=2) * mask


def group_contact(surface_m: np.ndarray, group_id: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """(T,) bool: per step, whether the robot touches (surface distance < 0) a present member of a group of >= 2
    present people. surface_m (T, N) m: centre distance minus both radii (`surface_distances`, or the env's;
    +inf marks a contact that does not count)."""
    g = np.asarray(group_id)
    mask = _present(present, g.shape)
    s = np.asarray(surface_m, dtype=float)
    if s.shape != g.shape or np.any(np.isnan(s[mask])):
        raise ValueError(f"surface_m must have group_id's shape {g.shape} and no NaN where present, got {s.shape}")
    return np.any(mask & (s < 0.0) & (group_sizes(g, mask) >= 2), axis=1)


def surface_distances(robot: np.ndarray, people: np.ndarray, people_radius_m: np.ndarray, robot_radius_m: float,
                      present: np.ndarray | None = None) -> np.ndarray:
    """(T, N) m: |robot - person| - person radius - robot radius (inf for absent rows)."""
    robot = _array("robot", robot, (None, 2))
    people, mask = _people(people, len(robot), present)
    radii = _radii("people_radius_m", people_radius_m, mask)
    centre = np.linalg.norm(np.where(mask[..., None], people, 0.0) - robot[:, None], axis=-1)
    return np.where(mask, centre - np.where(mask, radii, 0.0) - _radius("robot_radius_m", robot_radius_m), np.inf)


# ------------------------------------------------------------------------------------------ path
def path_irregularity(positions: np.ndarray, goal: np.ndarray) -> float | None:
    """rad: the mean over steps of the angle in [0, pi] between the robot's displacement over the step and the
    straight line from its position at the step's start to the goal. Steps where the robot did not move (or
    started on the goal, < `MIN_MOVE_M`) have no direction and are left out; None when no step is left.
    positions (T + 1, 2) m, goal (2,) m."""
    x = _array("positions", positions, (None, 2))
    g = _array("goal", goal, (2,))
    step, to_goal = np.diff(x, axis=0), g - x[:-1]
    keep = (np.linalg.norm(step, axis=1) > MIN_MOVE_M) & (np.linalg.norm(to_goal, axis=1) > MIN_MOVE_M)
    if not keep.any():
        return None
    s, d = step[keep], to_goal[keep]
    angle = np.arctan2(np.abs(s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]), np.einsum("ij,ij->i", s, d))
    return float(angle.mean())


def mean_jerk(positions: np.ndarray, dt_s: float) -> float | None:
    """m/s^3: the mean over time of |x[k + 3] - 3 x[k + 2] + 3 x[k + 1] - x[k]| / dt_s**3 (the third finite
    difference of position); None with fewer than 4 positions. positions (T + 1, 2) m."""
    x = _array("positions", positions, (None, 2))
    dt = _dt(dt_s)
    if len(x) < 4:
        return None
    return float(np.linalg.norm(np.diff(x, n=3, axis=0), axis=1).mean() / dt**3)


def shortest_path_m(start: np.ndarray, goal: np.ndarray, goal_tolerance_m: float) -> float:
    """m: the straight-line distance from the start to the goal region's edge, max(|goal - start| - tol, 0)."""
    s, g = _array("start", start, (2,)), _array("goal", goal, (2,))
    return max(float(np.linalg.norm(g - s)) - _radius("goal_tolerance_m", goal_tolerance_m), 0.0)


def spl(success: bool, start: np.ndarray, goal: np.ndarray, path_length_m: float, goal_tolerance_m: float) -> float:
    """Success weighted by path length, in [0, 1]: success * l / max(p, l), l = `shortest_path_m`, p the path
    travelled (m); 1 for a success with l = 0 (started inside the goal region), 0 for every failure."""
    length = shortest_path_m(start, goal, goal_tolerance_m)
    p = _radius("path_length_m", path_length_m)
    if not success:
        return 0.0
    return 1.0 if length == 0.0 else length / max(p, length)


# ------------------------------------------------------------------------------------------ CrowdNav++ ITR / SD
# CrowdNav++ (rl/evaluation.py; crowd_sim/envs/crowd_sim_var_num.py, calc_reward): its Danger zone is the humans'
# true positions predict_steps = 5 steps of pred_timestep = 0.25 s ahead (crowd_nav/configs/config.py)
ITR_OFFSETS_S: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0, 1.25)
_SNAP = 1e-9  # an offset within this many steps of a whole step is that step (0.25 / 0.05 is not exactly 5)
_BLOCK = 256  # states per block in `future_intrusions`


@dataclass(frozen=True)
class FutureIntrusions:
    """CrowdNav++'s intrusions of one episode (`future_intrusions`).

    intruding: (T,) bool per checked state 0 .. T-1 (the terminal state T is never checked).
    min_distance_m: (T,) m, per intruding state the smallest centre distance among its intruding (offset, person)
        pairs; NaN where the state does not intrude.
    states: T + 1, the states of the episode, terminal included (CrowdNav++'s step count).
    """

    intruding: np.ndarray
    min_distance_m: np.ndarray
    states: int

    @property
    def count(self) -> int:
        """Intruding states."""
        return int(np.count_nonzero(self.intruding))

    @property
    def ratio(self) -> float:
        """ITR as a fraction in [0, 1] (CrowdNav++ prints it x 100, %): intruding states / `states`."""
        return self.count / self.states

    @property
    def social_distance_m(self) -> float | None:
        """SD, m: the mean of `min_distance_m` over the intruding states; None without any."""
        return float(np.nanmean(self.min_distance_m)) if self.count else None


def future_intrusions(robot: np.ndarray, people: np.ndarray, people_radius_m: np.ndarray, robot_radius_m: float,
                      dt_s: float, present: np.ndarray | None = None,
                      offsets_s: tuple[float, ...] = ITR_OFFSETS_S) -> FutureIntrusions:
    """CrowdNav++'s intrusions: state k (time k dt_s, k = 0 .. T-1) intrudes when, for a person present at state k
    and at time k dt_s + o (o in `offsets_s`, s), |people(k dt_s + o) - robot[k]| < robot_radius_m + the person's
    radius. robot (T + 1, 2) m at the states 0 .. T (T steps; state T, the terminal one, is not checked);
    people (S, N, 2) m at the states 0 .. S-1 (S >= T + 1: the states after T continue the crowd past the episode's
    end), each column one person, present (S, N) bool; people_radius_m (N,) or (S, N) m. A time between two states
    is interpolated linearly (both must hold the person); times past state S-1 do not count."""
    robot = _array("robot", robot, (None, 2))
    raw = np.asarray(people, dtype=float)
    people, mask = _people(raw, len(raw) if raw.ndim else 0, present)
    radii = _radii("people_radius_m", people_radius_m, mask)
    t, s = len(robot) - 1, len(people)
    if t < 0 or s < t + 1:
        raise ValueError(f"need robot (T + 1, 2) with T >= 0 and people of at least T + 1 states, got {t + 1}, {s}")
    dt = _dt(dt_s)
    off = np.asarray(offsets_s, float)
    if off.ndim != 1 or not np.all(np.isfinite(off)) or np.any(off <= 0):
        raise ValueError(f"offsets_s must be positive and finite, got {offsets_s!r}")
    pos = np.where(mask[..., None], people, 0.0)
    reach = np.where(mask, radii, 0.0) + _radius("robot_radius_m", robot_radius_m)  # (S, N) contact distance, m
    closest = np.full(t, np.inf)
    for k0 in range(0, t, _BLOCK):  # blocks of states: (block, J, N, 2) arrays stay small on long, crowded replays
        k = np.arange(k0, min(k0 + _BLOCK, t))
        at = k[:, None] + off[None] / dt  # (K, J) fractional state index of each future time
        near = np.rint(at)
        at = np.where(np.abs(at - near) < _SNAP, near, at)
        lo = np.minimum(np.floor(at).astype(np.int64), s - 1)
        hi, w = np.minimum(lo + 1, s - 1), (at - lo)[..., None]  # w (K, J, 1)
        ok = mask[k, None, :] & (at <= s - 1)[..., None] & mask[lo] & (mask[hi] | (w == 0.0))
        future = (1.0 - w[..., None]) * pos[lo] + w[..., None] * pos[hi]  # (K, J, N, 2)
        dist = np.linalg.norm(future - robot[k, None, None], axis=-1)
        hit = ok & (dist < reach[lo])
        if hit.size:
            closest[k] = np.where(hit, dist, np.inf).min(axis=(1, 2))
    intruding = np.isfinite(closest)
    return FutureIntrusions(intruding, np.where(intruding, closest, np.nan), t + 1)
