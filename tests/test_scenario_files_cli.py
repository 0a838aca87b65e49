"""`--scenario PATH.toml` on the command lines: the scenario file docs/crowdsim.md shows runs as written in
`crowdsim generate` and `crowdnav evaluate`; a bad file is one line naming the file and the key, exit 2, nothing
written; `crowdsim scenarios` lists the built-in files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from crowdsim.cli import main as crowdsim_main
from crowdsim.scenarios import SCENARIOS
from envs.cli import main as crowdnav_main
from tests.cli_helpers import run_cli
from tests.test_readme import toml_block


@pytest.fixture
def room(tmp_path: Path) -> Path:
    path = tmp_path / "my_room.toml"
    path.write_text(toml_block())
    return path


def test_the_documented_file_is_small_and_complete(room):
    text = room.read_text()
    assert len(text.splitlines()) <= 30
    for part in ("[[walls]]", "polygon", "[[flows]]", "stop_areas", "[options]", "[robot]"):
        assert part in text


def test_generate_runs_the_documented_file(room, tmp_path, capsys):
    out = tmp_path / "rec"
    code = crowdsim_main(["generate", "--scenario", str(room), "--pedestrians", "6", "--duration", "2",
                          "--warmup", "0", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    meta = json.loads((out / "my_room_n6_s0.json").read_text())
    assert meta["scenario"] == str(room) and meta["scenario_name"] == "my_room" and len(meta["scenario_sha256"]) == 64
    code = crowdsim_main(["generate", "--scenario", str(room), "--option", "width_m=12", "--pedestrians", "6",
                          "--duration", "2", "--out", str(tmp_path / "wide")])
    assert code == 0, capsys.readouterr().err


@pytest.mark.slow
def test_evaluate_runs_the_documented_file(room, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = crowdnav_main(["evaluate", "--policy", "social-force", "--scenario", "my_room.toml", "--pedestrians", "6",
                          "--episodes", "1", "--time-limit", "4", "--record", "0", "--no-progress", "--out", "ev"])
    assert code == 0, capsys.readouterr().err
    config = json.loads(Path("ev/social-force.json").read_text())["config"]
    assert config["scenario"] == "my_room.toml" and len(config["scenario_sha256"]) == 64


BAD = [
    ('bounds = [', 'bouns = [', "my_room.toml: bouns: unknown key; did you mean 'bounds'?"),
    ('[[flows]]  # west -> east', '[[flows]  # west -> east', "my_room.toml: malformed TOML"),
    ('polygon = [[4.5, 5.0], [5.5, 5.0], [5.5, 6.0], [4.5, 6.0]]', 'polygon = [[4.5, 5.0], [5.5, 5.0]]',
     "my_room.toml: walls[2].polygon: expected at least 3 points"),
    ('"width_m - 1.5"', '"widht_m - 1.5"', "my_room.toml: flows[1].spawn[0]: unknown name 'widht_m'"),
    ('width_m = 10.0', 'width_m = "10"', "my_room.toml: options.width_m: expected a number or true/false"),
    ('both_ways = true', 'both_ways = "yes"', "my_room.toml: robot.both_ways: expected true or false"),
    ('spawn = [0.3, 3.4, 1.5, 4.6]', 'spawn = [4.0, 5.4, 6.0, 5.6]',  # across the pillar
     "my_room.toml: scenario my_room: flow 0 spawn area (4.0, 5.4, 6.0, 5.6) lies across the wall"),
]


@pytest.mark.parametrize("old, new, message", BAD)
@pytest.mark.parametrize("command", ["crowdsim", "crowdnav", "train"])
def test_a_bad_file_is_one_line_exit_2_nothing_written(room, tmp_path, capsys, old, new, message, command):
    text = room.read_text()
    assert text.count(old) >= 1
    room.write_text(text.replace(old, new, 1))
    out = tmp_path / "out"
    if command == "crowdsim":
        code, err = run_cli(crowdsim_main, ["generate", "--scenario", str(room), "--out", str(out)], capsys)
    elif command == "crowdnav":
        code, err = run_cli(crowdnav_main, ["evaluate", "--policy", "social-force", "--scenario", str(room),
                                            "--episodes", "1", "--out", str(out)], capsys)
    else:
        code, err = run_cli(crowdnav_main, ["train", "--scenario", str(room), "--out", str(out)], capsys)
    assert code == 2 and not out.exists()
    assert err.count("\n") == 1 and message in err and "Traceback" not in err, err


def test_unknown_scenario_names_the_file_form(tmp_path, capsys):
    code, err = run_cli(crowdsim_main, ["generate", "--scenario", "plaz", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "did you mean 'plaza'?" in err and ".toml scenario file" in err
    code, err = run_cli(crowdsim_main, ["generate", "--scenario", str(tmp_path / "nope.toml"), "--out",
                                        str(tmp_path / "o")], capsys)
    assert code == 2 and "nope.toml: cannot read the scenario file: no such file or directory" in err


def test_scenarios_lists_the_builtin_files(capsys):
    assert crowdsim_main(["scenarios"]) == 0
    out = capsys.readouterr().out
    for name, file in SCENARIOS.items():
        assert f"{name}  {file.source}\n    {file.description}" in out and Path(file.source).is_file()


def test_a_suite_cell_runs_a_scenario_file_and_its_bytes_enter_the_fingerprint(room):
    from envs.evaluation.benchmark import episode_fingerprint
    from envs.evaluation.suite import SUITES_DIR, load_suite, parse_suite
    from envs.policies import PolicyConfig

    def suite(path: str):
        return parse_suite({"name": "mine", "version": 1, "cells": [
            {"name": "room", "scenario": path, "n_pedestrians": 6, "robot_visible": True, "episodes": 2, "seed0": 0,
             "options": {"width_m": 11.0}}]})

    cell = suite(str(room)).cells[0]
    config = cell.env_config(0)
    assert config.scenario == str(room) and config.scenario_options == (("width_m", 11.0),)
    policy = PolicyConfig("social-force")
    before = episode_fingerprint(suite(str(room)), cell, policy)
    room.write_text(room.read_text().replace("width_m = 10.0", "width_m = 10.5"))
    assert episode_fingerprint(suite(str(room)), suite(str(room)).cells[0], policy) != before
    with pytest.raises(ValueError) as info:  # a relative path starts in the suites' folder
        suite("rooms/nowhere.toml")
    assert str(info.value).startswith(f"{SUITES_DIR / 'rooms/nowhere.toml'}: cannot read the scenario file")
    smoke = load_suite("smoke")
    for c in smoke.cells:  # built-in cells keep the fingerprints their records hold
        assert c.fingerprint_spec is c.spec


def test_the_robot_table_places_the_robot(room):
    import numpy as np

    from crowdsim import SimConfig
    from envs.crowds.crowd import SimCrowd

    crowd = SimCrowd(SimConfig(scenario=str(room), n_pedestrians=6))
    rng = np.random.default_rng(0)
    starts = np.array([crowd.robot_route(rng)[0] for _ in range(40)])
    west = (starts[:, 0] >= 1.0) & (starts[:, 0] <= 2.0)
    east = (starts[:, 0] >= 8.0) & (starts[:, 0] <= 9.0)
    assert (west | east).all() and west.any() and east.any()  # both_ways: from either end
    assert ((starts[:, 1] >= 1.0) & (starts[:, 1] <= 2.5)).all()
