"""What a robot that senses could do: a witness path that knows the future only of the people it has sensed.

The any-robot witness (`envs.evaluation.reachability`) knows the whole episode, people included who appear only
later. No robot that senses could know them. `sensing_path` builds its path from the same conservative reachable
sets (same grid, same swept-contact clearance, the same `speed_fraction` and `extra_m` room for the tracker), but
re-planned along the way:

- Whom it knows: a pedestrian is *sensed* from the first env step at which they are within `sensor_range_m` of the
  path's own position (the env's sensor range; the field of view and occlusion are not modelled: the default
  all-round sensor). From then on the witness knows their whole future, as if it had a perfect predictor of
  everyone it has sensed: what `mpc-oracle` is given, over the rest of the episode instead of 4.8 s.
- When it re-plans: every `replan_s` (default 0.4 s, the rate at which the env's predictions are made), if someone
  was sensed since the last plan, a new plan starts from where the last plan has the robot then (stitched: the
  path never jumps), over the rest of the episode, against everyone sensed so far. Between re-plans it follows
  the last plan; a plan that cannot reach the goal is traced back from the reachable cell nearest to it, and where
  nothing is reachable (a newly sensed person leaves no move) the path holds its position.

The path is then tracked by the benchmark's robot in the env (`envs.evaluation.witness.track`), as the any-robot
witness is, so a success proves the episode could be won by a robot that senses and predicts the people it has
sensed perfectly; a failure proves nothing. Units: m, s; the path has one point per env step.
"""

from __future__ import annotations

import numpy as np

from envs.evaluation.reachability import Course, ReachConfig, conservative_run, fill_strides, grid_for, stride_of

DEFAULT_REPLAN_S = 0.4  # s between the witness's chances to re-plan (the env's prediction period)


def sensing_path(course: Course, config: ReachConfig, sensor_range_m: float, speed_fraction: float = 0.85,
                 extra_m: float = 0.1, replan_s: float = DEFAULT_REPLAN_S) -> tuple[np.ndarray, int]:
    """The sensing witness's path (n_steps + 1, 2) m, one point per env step from the start, and how many plans it
    made (module docstring). `config` must be resolved for the course's env step (`ReachConfig.resolved`)."""
    if not (sensor_range_m > 0 and replan_s > 0):
        raise ValueError(f"sensor_range_m and replan_s must be > 0, got {sensor_range_m}, {replan_s}")
    grid = grid_for(course, config, config.steps_per_check(course.dt_s))
    stride = stride_of(course.dt_s)
    per_plan = max(1, int(round(replan_s / (course.dt_s * stride))))  # strides between chances to re-plan
    speed = speed_fraction * course.max_speed_mps
    cells = [grid.start]  # one grid cell per stride from the start
    sensed = _sensed(course, grid.xy[grid.start], 0, np.zeros(0, int), sensor_range_m)
    known: np.ndarray | None = None
    plan: list[tuple[int, int]] = []
    n_plans = 0
    last = course.n_steps // stride  # strides in the episode
    while len(cells) <= last:
        if known is None or len(sensed) > len(known):
            _, traced = conservative_run(course, grid, cells[-1], (len(cells) - 1) * stride, speed, extra_m,
                                         known=sensed, partial=True)
            plan, known, n_plans = traced[1:], sensed, n_plans + 1
        for _ in range(min(per_plan, last + 1 - len(cells))):
            cells.append(plan.pop(0) if plan else cells[-1])
            sensed = _sensed(course, grid.xy[cells[-1]], (len(cells) - 1) * stride, sensed, sensor_range_m)
    return fill_strides(np.array([grid.xy[c] for c in cells]), stride), n_plans


def _sensed(course: Course, xy: np.ndarray, step: int, sensed: np.ndarray, range_m: float) -> np.ndarray:
    """The ids sensed so far (sorted int array): `sensed` and those within range_m of xy (2,) m at env step `step`."""
    ids, pos = course.ped_id[step], course.ped_pos[step]
    if not len(ids):
        return sensed
    near = ids[np.hypot(*(pos - xy).T) <= range_m]
    return np.union1d(sensed, near.astype(int)) if len(near) else sensed
