"""escape_clearance (envs/scoring/escape.py): what a constant command could have kept from a pedestrian who appeared."""

from __future__ import annotations

import json

import numpy as np
import pytest

from envs.scoring.escape import escape_clearance, escape_commands
from planner import RobotConfig

UNICYCLE = RobotConfig()  # 1.2 m/s, 1.5 m/s^2, 2 rad/s, radius 0.3 m
HOLONOMIC = RobotConfig(model="holonomic")
DT = 0.1


def _head_on(gap_m: float, steps: int, speed_mps: float = 1.3) -> np.ndarray:
    """A walker appearing gap_m (surface) ahead of a robot at the origin facing +x, walking at it along the x axis."""
    start = 0.3 + 0.3 + gap_m
    return np.stack([start - speed_mps * DT * np.arange(steps + 1), np.zeros(steps + 1)], axis=-1)


def _moving(model: str = "unicycle") -> np.ndarray:
    """The robot at the origin, heading +x at 1.2 m/s."""
    return np.array([0.0, 0.0, 0.0, 1.2, 0.0]) if model == "unicycle" else np.array([0.0, 0.0, 1.2, 0.0])


def test_a_walker_appearing_half_a_metre_ahead_cannot_be_escaped_and_one_far_away_can():
    near = escape_clearance(_moving(), UNICYCLE, DT, _head_on(0.5, 10), 0.3)
    far = escape_clearance(_moving(), UNICYCLE, DT, _head_on(6.0, 30), 0.3)
    assert near < 0.0 < far
    # a walker passing 2 m to the side leaves at least the straight run's clearance (about 1.4 m)
    side = _head_on(6.0, 60) + np.array([0.0, 2.0])
    assert escape_clearance(_moving(), UNICYCLE, DT, side, 0.3) >= 2.0 - 0.6 - 1e-9


def test_the_answer_grows_with_the_warning_and_a_holonomic_robot_escapes_sooner():
    values = [escape_clearance(_moving(), UNICYCLE, DT, _head_on(g, 25), 0.3) for g in (0.3, 1.0, 2.0, 4.0)]
    assert values == sorted(values) and values[0] < 0.0 < values[-1]
    # sideways at once, no turn to make: the holonomic robot keeps more than the unicycle from the same walker
    holo = escape_clearance(_moving("holonomic"), HOLONOMIC, DT, _head_on(1.0, 25), 0.3)
    assert holo > escape_clearance(_moving(), UNICYCLE, DT, _head_on(1.0, 25), 0.3)


def test_a_standing_robot_escapes_a_walker_who_stops_short_and_the_commands_include_braking():
    track = np.array([[1.5, 0.0]] * 10)  # someone standing 0.9 m (surface) in front of a robot at rest
    rest = np.array([0.0, 0.0, 0.0, 0.0, 0.0])
    assert escape_clearance(rest, UNICYCLE, DT, track, 0.3) == pytest.approx(0.9)
    assert np.any(np.all(escape_commands(UNICYCLE) == 0.0, axis=1))
    assert np.any(np.all(escape_commands(HOLONOMIC) == 0.0, axis=1))


@pytest.mark.parametrize("track", [np.zeros((1, 2)), np.zeros((5, 3)), np.array([[0.0, 0.0], [np.nan, 1.0]])])
def test_malformed_tracks_are_refused(track):
    with pytest.raises(ValueError, match=r"ped_track|finite"):
        escape_clearance(_moving(), UNICYCLE, DT, track, 0.3)


def test_escape_check_reruns_a_collision_and_refuses_a_missing_file(tmp_path, capsys, load_script):
    """scripts/escape_check.py: a crowdnav-tune replay episode (tune-zara03 at seed 1197, outside the suite's own 40:
    a walker who came into view 1.9 s before walks into the oracle's robot) is re-run to the same contact; a missing
    records file is one line on stderr and exit 2."""
    from envs.evaluation.suite import DEFAULT_DATA, load_suite

    cell = load_suite("crowdnav-tune").cell("tune-zara03")
    if not cell.files(DEFAULT_DATA)[0].exists():
        pytest.skip("../shared/datasets is not here")
    check = load_script("escape_check")
    records = tmp_path / "records.jsonl"
    record = {"cell": "tune-zara03", "seed": 1197, "policy": "mpc-oracle", "outcome": "collision",
              "collision_with": "pedestrian"}
    moved = {**record, "collision_time_s": 5.0}  # the same episode, another recorded contact: not this run's
    records.write_text("\n".join(json.dumps(x) for x in (record, {**record, "outcome": "success"}, moved)) + "\n")
    assert check.main(["crowdnav-tune", str(records), "--policy", "mpc-oracle", "--mpc", "time_budget_s=10"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3 and lines[0].startswith("tune-zara03 1197 at fault pedestrian: contact at 2.6 s")
    assert lines[1] == "tune-zara03 1197: the re-run did not end in the recorded pedestrian collision (left out)"
    lines = [lines[0], lines[2]]
    assert "first seen 1.9 s before, 1.18 m away; escape clearance +" in lines[0]
    assert lines[1].startswith("1 pedestrian collisions re-run: 0 with someone first seen < 1 s before; 0 not")
    assert check.main(["crowdnav-tune", str(tmp_path / "none.jsonl"), "--policy", "mpc-oracle"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("escape_check: ")
