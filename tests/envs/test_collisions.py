"""Collision attribution: who moved into whom, decided by speeds and the relative velocity at contact."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from envs import CrowdNavEnv
from envs.crowds.replay import ReplayConfig
from envs.scoring.collisions import STOPPED_MPS, collision_kind
from tests.envs.test_env import place_robot


def _tracks(tmp_path: Path, tracks: dict[int, list[tuple[int, float, float]]]) -> ReplayConfig:
    """A recording from explicit (frame step, x, y) knots per pedestrian (0.4 s per step)."""
    rows = sorted((10 * t, pid, x, y) for pid, knots in tracks.items() for t, x, y in knots)
    path = tmp_path / "tracks.txt"
    path.write_text("\n".join(f"{f}\t{p}\t{x}\t{y}" for f, p, x, y in rows) + "\n")
    return ReplayConfig(path=path, start_mode="fixed")


def _stand_still(env: CrowdNavEnv, steps: int = 300) -> dict:
    for _ in range(steps):
        _, _, term, trunc, info = env.step(env.control_to_action(np.zeros(2)))
        if term or trunc:
            return info["episode_metrics"]
    raise AssertionError("episode did not end")


@pytest.mark.parametrize(("robot_vel", "ped_vel", "kind"), [
    ((1.0, 0.0), (0.0, 0.0), "robot"),          # robot drives into a standing person
    ((0.0, 0.0), (-1.0, 0.0), "pedestrian"),    # a person walks into a standing robot
    ((0.05, 0.0), (-1.0, 0.0), "pedestrian"),   # ... one creeping slower than STOPPED_MPS counts as stopped
    ((0.0, 0.0), (0.3, 0.5), "pedestrian"),     # a stopped robot moved into nobody, whatever the contact did
    ((-0.5, 0.0), (0.2, 0.0), "robot"),         # backing away from someone also moving away: the robot's doing
    ((-0.5, 0.0), (-1.2, 0.0), "pedestrian"),   # ... or backing away, but not fast enough
    ((0.5, 0.0), (-1.0, 0.0), "robot"),         # head-on: the robot closed the gap too
    ((0.0, 0.8), (-1.0, 0.0), "pedestrian"),    # robot moving sideways (not towards), person walks in
])
def test_kind_from_speeds_and_relative_velocity(robot_vel, ped_vel, kind):
    assert STOPPED_MPS == 0.1
    assert collision_kind(np.zeros(2), np.array(robot_vel), np.array([0.5, 0.0]), np.array(ped_vel), False) == kind


def test_a_new_track_is_a_spawn_whatever_the_velocities():
    assert collision_kind(np.zeros(2), np.array([1.0, 0.0]), np.array([0.3, 0.0]), np.zeros(2), True) == "spawn"


def _robot_waits_at_origin(tmp_path: Path, track: list[tuple[int, float, float]]) -> tuple[CrowdNavEnv, dict]:
    """Pedestrian 1 follows `track` (plus one far away) while the robot stands at the origin; the final metrics."""
    far = [(t, 30.0, 30.0) for t in range(40)]
    env = CrowdNavEnv(scenario="replay", replay=_tracks(tmp_path, {1: track, 2: far}))
    env.reset(seed=0)
    place_robot(env, (0.0, 0.0), (-6.0, 0.0))
    return env, _stand_still(env)


def test_env_pedestrian_walks_into_a_stopped_robot(tmp_path):
    # pedestrian 1 walks from x = 6 towards the robot at the origin at 1 m/s (0.4 m per 0.4 s step)
    _, m = _robot_waits_at_origin(tmp_path, [(t, 6.0 - 0.4 * t, 0.0) for t in range(40)])
    assert m["collision"] and m["at_fault"] == "pedestrian"


def test_env_track_that_starts_on_the_robot_is_a_spawn(tmp_path):
    # pedestrian 1 appears at step 20 (8 s), 0.3 m from where the robot waits
    env, m = _robot_waits_at_origin(tmp_path, [(t, 0.3, 0.0) for t in range(20, 40)])
    assert m["collision"] and m["at_fault"] == "spawn"
    assert m["collision_time_s"] == pytest.approx(20 * 0.4 - env.config.warmup_s, abs=0.11)


def test_env_track_that_begins_just_before_contact_is_a_spawn(tmp_path):
    # pedestrian 1 appears at step 20, 1.0 m from the robot's centre, and runs at it at 2 m/s (0.8 m per 0.4 s
    # step): contact within one prediction step of its first annotation, before its velocity could be seen
    _, m = _robot_waits_at_origin(tmp_path, [(t, 1.0 - 0.8 * (t - 20), 0.0) for t in range(20, 24)])
    assert m["collision"] and m["at_fault"] == "spawn"


def test_env_track_seen_for_a_while_is_not_a_spawn(tmp_path):
    # the same run-in, but the track began 3 steps (1.2 s) earlier, standing still 1.0 m away
    track = [(t, 1.0, 0.0) for t in range(17, 21)] + [(t, 1.0 - 0.8 * (t - 20), 0.0) for t in range(21, 24)]
    _, m = _robot_waits_at_origin(tmp_path, track)
    assert m["collision"] and m["at_fault"] == "pedestrian"


def _robot_waits_with_spawns_allowed(tmp_path: Path, track: list[tuple[int, float, float]]) -> dict:
    far = [(t, 30.0, 30.0) for t in range(60)]
    env = CrowdNavEnv(scenario="replay", replay=_tracks(tmp_path, {1: track, 2: far}), spawn_contact_ends_episode=False,
                      time_limit_s=16.0)
    env.reset(seed=0)
    place_robot(env, (0.0, 0.0), (-6.0, 0.0))
    return _stand_still(env)


def test_a_spawn_contact_need_not_end_the_episode(tmp_path):
    # pedestrian 1 appears 0.3 m from the waiting robot at step 20, stands there 1.2 s, then walks off along +y
    track = [(t, 0.3, 0.0) for t in range(20, 24)] + [(t, 0.3, 0.6 * (t - 23)) for t in range(24, 40)]
    m = _robot_waits_with_spawns_allowed(tmp_path, track)
    assert not m["collision"] and m["timeout"] and m["spawn_contacts"] == 1
    assert m["min_distance_m"] > 0  # the spawn contact is left out of the distances, not just of the outcome


def test_sliding_off_and_back_on_is_the_same_spawn_contact(tmp_path):
    # the spawned pedestrian edges to 0.1 m clear of the robot's surface (under the 0.2 m discomfort distance),
    # touches it again, then walks off: one encounter, no collision
    track = ([(t, 0.3, 0.0) for t in range(20, 23)] + [(23, 0.65, 0.0), (24, 0.4, 0.0)]
             + [(t, 0.4, 0.6 * (t - 24)) for t in range(25, 40)])
    m = _robot_waits_with_spawns_allowed(tmp_path, track)
    assert not m["collision"] and m["spawn_contacts"] == 1


def test_after_a_spawn_contact_clears_a_new_contact_counts(tmp_path):
    # the same spawn, then the pedestrian walks 3 m away and comes back into the (stopped) robot
    away = [(t, 0.3, 0.6 * (t - 23)) for t in range(24, 29)]
    back = [(t, 0.3, 3.0 - 0.6 * (t - 28)) for t in range(29, 40)]
    m = _robot_waits_with_spawns_allowed(tmp_path, [(t, 0.3, 0.0) for t in range(20, 24)] + away + back)
    assert m["collision"] and m["at_fault"] == "pedestrian" and m["spawn_contacts"] == 1


def test_replay_track_age(tmp_path):
    env = CrowdNavEnv(scenario="replay", replay=_tracks(tmp_path, {1: [(t, 5.0, 0.0) for t in range(10, 40)],
                                                                  2: [(t, 30.0, 30.0) for t in range(40)]}))
    env.reset(seed=0)
    crowd = env.crowd
    assert crowd.track_age_s(2) == pytest.approx(crowd.recording_time_s)
    assert crowd.track_age_s(1) == pytest.approx(crowd.recording_time_s - 10 * 0.4)
    with pytest.raises(KeyError):
        crowd.track_age_s(99)
