"""The sensing witness: it knows the future only of the people it has sensed, re-plans when it senses someone new,
and never jumps."""

from __future__ import annotations

import numpy as np
import pytest

from envs.evaluation.reachability import Course, ReachConfig, roomy_path
from envs.evaluation.sensing import sensing_path

DT = 0.1
SECONDS = 20.0
CFG = ReachConfig().resolved(DT)


def _standing(xy: tuple[float, float]) -> np.ndarray:
    return np.tile(np.asarray(xy, float), (int(round(SECONDS / DT)) + 1, 1))


def _course(tracks: list[tuple[np.ndarray, int]], goal: tuple[float, float] = (10.0, 0.0)) -> Course:
    """From (0, 0) to `goal` in open ground; tracks: (positions (T + 1, 2), the env step the person appears at), then
    two bystanders standing 5 m to either side of the line from the start (the grid spans the people: room to pass)."""
    n = int(round(SECONDS / DT))
    tracks = [*tracks, (_standing((5.0, 5.0)), 0), (_standing((5.0, -5.0)), 0)]
    here = [[i for i, (_, k0) in enumerate(tracks) if k >= k0] for k in range(n + 1)]
    pos = [np.array([tracks[i][0][k] for i in ids]).reshape(-1, 2) for k, ids in enumerate(here)]
    return Course(np.zeros(2), np.asarray(goal, float), 0.3, 0.3, 1.2, DT, n, np.zeros((0, 2, 2)), pos,
                  [np.full(len(ids), 0.3) for ids in here], [np.array(ids, int) for ids in here],
                  [np.zeros(len(ids), bool) for ids in here])


def _clearance(path: np.ndarray, track: np.ndarray, k0: int) -> float:
    """Smallest centre distance less both radii between the path and a person there from step k0, m."""
    return float(np.hypot(*(path[k0:] - track[k0:len(path)]).T).min()) - 0.6


def _assert_no_jumps(path: np.ndarray) -> None:
    assert np.hypot(*np.diff(path, axis=0).T).max() <= 0.85 * 1.2 * DT * np.sqrt(2) + 1e-9


def test_knowing_everyone_from_the_start_it_is_the_any_robot_witness() -> None:
    walker = np.array([[5.0, -4.0]]) + np.arange(201)[:, None] * DT * np.array([[0.0, 0.8]])  # crosses the line
    course = _course([(walker, 0)])
    path, plans = sensing_path(course, CFG, sensor_range_m=50.0)
    known = roomy_path(course, CFG, 0.85, 0.1)
    assert plans == 1
    np.testing.assert_array_equal(path[:len(known)], known)
    assert np.all(path[len(known):] == known[-1])  # it waits at the goal afterwards


def test_someone_who_appears_later_is_unknown_before_and_avoided_after() -> None:
    k0 = 30  # appears at 3 s, standing on the straight line 2 m ahead of where the robot then is
    person = _standing((5.0, 0.0))
    course = _course([(person, k0)])
    path, plans = sensing_path(course, CFG, sensor_range_m=10.0)
    alone = roomy_path(_course([]), CFG, 0.85, 0.1)
    omniscient = roomy_path(course, CFG, 0.85, 0.1)
    assert plans == 2
    np.testing.assert_array_equal(path[:k0 + 1], alone[:k0 + 1])  # nothing known of the person before 3 s
    assert _clearance(path, person, k0) > 0.0  # avoided once sensed
    assert not np.array_equal(omniscient[:k0 + 1], alone[:k0 + 1])  # the any-robot witness already steered round
    _assert_no_jumps(path)


@pytest.mark.parametrize(("range_m", "plans"), [(3.0, 2), (50.0, 1)])
def test_someone_beyond_the_sensor_range_is_sensed_only_within_it(range_m: float, plans: int) -> None:
    person = _standing((6.0, 0.2))
    course = _course([(person, 0)])
    path, n = sensing_path(course, CFG, sensor_range_m=range_m)
    assert n == plans
    if range_m < 6.0:  # goes as if nobody were there until 3 m away
        first = int(np.argmax(np.hypot(*(path - person).T) <= range_m))
        np.testing.assert_array_equal(path[:first + 1], roomy_path(_course([]), CFG, 0.85, 0.1)[:first + 1])
    assert _clearance(path, person, 0) > 0.0
    _assert_no_jumps(path)


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="sensor_range_m"):
        sensing_path(_course([]), CFG, sensor_range_m=0.0)
