"""Scenario files (`crowdsim.scenario_files`): the built-in files build exactly the scenarios the Python builders
built before (every recorded episode depends on it), and bad files fail with one line naming the file and key."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.scenario_files import ScenarioFileError, parse_scenario
from crowdsim.scenarios import SCENARIO_OPTIONS, SCENARIOS, make_scenario
from tests.crowdsim.scenarios_before_files import BUILDERS

# defaults, the options the suites, tests, presets and benchmarks use, and a few odd ones
SETTINGS = {
    "corridor": [{}, {"length_m": 14.0}, {"length_m": 40.0, "width_m": 8.0}, {"length_m": 20.0, "width_m": 3.0},
                 {"width_m": 3.4999}, {"width_m": 5.37}, {"length_m": 80.0, "width_m": 6.0},
                 {"periodic": 1.0, "length_m": 10.0, "width_m": 3.0, "density": 1.45 * 0.7},
                 {"periodic": 1.0}, {"periodic": 0.0, "density": 2.0}, {"length_m": 7.3, "width_m": 2.9}],
    "crossing": [{}, {"half_length_m": 6.0}, {"half_length_m": 4.0, "width_m": 3.0}, {"width_m": 7.7},
                 {"half_length_m": 5.9, "width_m": 4.1}, {"half_length_m": 13.37}],
    "bottleneck": [{}, {"door_m": 2.0, "continuous": 0}, {"density": 4.0, "continuous": 0.0, "room_m": 8.0},
                   {"room_m": 5.3, "door_m": 0.7}, {"room_m": 12.0, "door_m": 1.3, "density": 0.0}],
    "plaza": [{}, {"size_m": 16.0}, {"size_m": 26.0}, {"size_m": 6.0}, {"size_m": 23.456, "gate_m": 3.3},
              {"size_m": 5.0, "gate_m": 1.1}, {"size_m": 17.0, "gate_m": 2.9}],
    "circle_crossing": [{}, {"radius_m": 4.0}, {"radius_m": 6 * np.sqrt(2)}, {"radius_m": 3.3}, {"radius_m": 9.1}],
    "open": [{}, {"size_m": 10.0}, {"size_m": 12.34}],
}


def _bits(value):
    """Every number in a nest of tuples, flows and dicts as the hex of its float (np.float64 or float alike)."""
    if isinstance(value, dict):
        return {k: _bits(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return tuple(_bits(v) for v in value)
    if hasattr(value, "spawn"):
        return _bits((value.spawn, value.target))
    if isinstance(value, str | bool) or value is None:
        return value
    return float(value).hex()


def test_every_builtin_is_a_file_and_covered():
    assert list(SCENARIOS) == list(BUILDERS) == list(SETTINGS)
    for name, file in SCENARIOS.items():
        assert file.name == name and file.source.endswith(f"builtin_scenarios/{name}.toml") and file.description


@pytest.mark.parametrize("name, options", [(n, o) for n, opts in SETTINGS.items() for o in opts])
def test_builtin_files_build_the_scenarios_of_the_python_builders_bit_for_bit(name, options):
    new, old = make_scenario(name, options), BUILDERS[name](dict(options))
    assert new.walls.dtype == old.walls.dtype and new.walls.shape == old.walls.shape
    assert np.array_equal(new.walls, old.walls) and new.walls.tobytes() == old.walls.tobytes()
    for field in ("name", "bounds", "flows", "on_arrival", "continuous", "periodic_x", "exit_radius_m", "dense_spawn",
                  "interior", "stop_areas", "pois", "options"):
        a, b = getattr(new, field), getattr(old, field)
        assert a == b, (field, a, b)
        assert _bits(a) == _bits(b), (field, a, b)  # the same floats, bit for bit (0.0 is not -0.0)
    assert new.robot_start is None and new.robot_goal is None


def test_option_defaults_come_from_the_files():
    assert SCENARIO_OPTIONS == {
        "corridor": {"length_m": 20.0, "width_m": 4.0, "periodic": 0.0, "density": 0.0},
        "crossing": {"half_length_m": 10.0, "width_m": 6.0},
        "bottleneck": {"room_m": 8.0, "door_m": 1.0, "density": 0.0, "continuous": 1.0},
        "plaza": {"size_m": 20.0, "gate_m": 4.0},
        "circle_crossing": {"radius_m": 6.0},
        "open": {"size_m": 30.0},
    }
    assert SCENARIOS["corridor"].flags == ("periodic",) and SCENARIOS["bottleneck"].flags == ("continuous",)


ROOM = b'''
name = "room"
bounds = [0.0, 0.0, "size_m", "size_m"]
[options]
size_m = 10.0
[[walls]]
polygon = [[0.0, 0.0], ["size_m", 0.0], ["size_m", "size_m"], [0.0, "size_m"]]
[[flows]]
spawn = [1.0, 1.0, 2.0, 9.0]
target = [8.0, 1.0, 9.0, 9.0]
'''


def _build(text: bytes, options=None):
    return parse_scenario(text, "room.toml").fields(options or {})


def test_a_closed_polygon_and_expressions():
    fields = _build(ROOM, {"size_m": 12.0})
    assert fields["walls"].tolist() == [[[0, 0], [12, 0]], [[12, 0], [12, 12]], [[12, 12], [0, 12]], [[0, 12], [0, 0]]]
    assert fields["bounds"] == (0.0, 0.0, 12.0, 12.0)
    text = ROOM.replace(b"[[walls]]", b'[let]\nh = "max(size_m / 2.0, 1) - -1"\n[[walls]]')
    assert _build(text.replace(b"target = [8.0", b'target = ["h"'))["flows"][0][1] == (6.0, 1.0, 9.0, 9.0)


@pytest.mark.parametrize("change, message", [
    ((b"bounds =", b"bouns ="), "room.toml: bouns: unknown key; did you mean 'bounds'?"),
    ((b"[[flows]]", b"[[flows]\n"), "room.toml: malformed TOML"),
    ((b"spawn = [1.0", b"spwan = [1.0"), "room.toml: flows[0].spwan: unknown key; did you mean 'spawn'?"),
    ((b'polygon = [[0.0, 0.0], ["size_m", 0.0], ["size_m", "size_m"], [0.0, "size_m"]]',
      b'polygon = [[0.0, 0.0], ["size_m", 0.0]]'), "room.toml: walls[0].polygon: expected at least 3 points"),
    ((b'"size_m", "size_m"]\n[options]', b'"size_m", "sise_m"]\n[options]'),
     "room.toml: bounds[3]: unknown name 'sise_m' in 'sise_m'; did you mean 'size_m'?"),
    ((b"size_m = 10.0", b'size_m = "ten"'), "room.toml: options.size_m: expected a number or true/false"),
    ((b"target = [8.0", b"target = [true"), "room.toml: flows[0].target[0]: expected a number or an expression"),
    ((b"target = [8.0", b'target = ["__import__(\'os\')"'), "room.toml: flows[0].target[0]: "),
    ((b"target = [8.0", b'target = ["size_m ** 2"'), "is not allowed in 'size_m ** 2'"),
    ((b"target = [8.0", b'target = ["size_m > 2"'), "is not allowed in 'size_m > 2'"),
    ((b"target = [8.0, 1.0, 9.0, 9.0]", b"target = [8.0, 1.0, 9.0]"), "flows[0].target: expected a rectangle"),
    ((b"target = [8.0, 1.0, 9.0, 9.0]", b"target = [9.0, 1.0, 8.0, 9.0]"), "with xmin <= xmax"),
    ((b'name = "room"', b"name = 3"), "room.toml: name: expected a string"),
    ((b"[[flows]]", b"[[flows]]\nwhen = 'size_m >'"), "room.toml: flows[0].when: cannot parse"),
])
def test_a_bad_file_is_one_line_naming_the_file_and_key(change, message):
    with pytest.raises(ScenarioFileError) as info:
        _build(ROOM.replace(*change))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_flow_area_across_a_wall_names_the_file(tmp_path):
    path = tmp_path / "room.toml"
    path.write_bytes(ROOM.replace(b"target = [8.0, 1.0", b"target = [8.0, -1.0"))
    with pytest.raises(ScenarioFileError, match=r"room.toml: scenario room: flow 0 target .* lies across the wall"):
        make_scenario(str(path))
    path.write_bytes(ROOM)
    assert make_scenario(str(path), {"size_m": 11.0}).bounds == (0.0, 0.0, 11.0, 11.0)
    with pytest.raises(ValueError, match=r"room.toml' has no option 'width_m'; valid options: size_m"):
        make_scenario(str(path), {"width_m": 2.0})
