"""Suite socnav-scenarios: Francis et al.'s (2023) standard scenarios as scenario files. Every file says what it tests,
the robot's start and goal lie in free space joined by a route, every cell builds and runs, and the encounters and
groups each scenario promises are there when the robot sets off."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crowdsim.scenarios import make_scenario, scenario_file
from envs.env import CrowdNavEnv
from envs.evaluation.suite import SUITES_DIR, load_suite, suite_names
from envs.policies import decide, make_policy
from planner import RobotConfig
from planner.config import RouteConfig
from planner.route import grid_route
from planner.scene import wall_clearance

SUITE = load_suite("socnav-scenarios")
FILES = sorted((SUITES_DIR / "socnav").glob("*.toml"))
RADIUS = RobotConfig().radius_m


def _rect_points(rect: tuple[float, float, float, float]) -> np.ndarray:
    """The corners and the centre of a rectangle, (5, 2) m."""
    x0, y0, x1, y1 = rect
    return np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1], [(x0 + x1) / 2, (y0 + y1) / 2]])


def _inside(points: np.ndarray, bounds: tuple[float, float, float, float]) -> bool:
    x0, y0, x1, y1 = bounds
    return bool(np.all((points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)))


def test_the_suite_is_registered_and_says_what_is_in_and_out():
    assert "socnav-scenarios" in suite_names() and SUITE.version == 1
    assert "Francis et al. 2023" in SUITE.description
    assert "Left out: join group and leave group" in SUITE.description
    assert {Path(c.scenario) for c in SUITE.cells} == set(FILES)  # every file has cells, every cell its file
    assert all(c.seeds == tuple(range(10)) for c in SUITE.cells)
    by_name = {c.name: c for c in SUITE.cells}
    for cell in SUITE.cells:  # visible and invisible twins, identical otherwise
        stem, _, seen = cell.name.rpartition("-")
        twin = by_name[f"{stem}-{'invisible' if seen == 'visible' else 'visible'}"]
        assert cell.spec["robot_visible"] == (seen == "visible") != twin.spec["robot_visible"]
        assert {**cell.spec, "name": "", "robot_visible": None} == {**twin.spec, "name": "", "robot_visible": None}


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_each_file_describes_itself_and_joins_start_to_goal_through_free_space(path):
    described = scenario_file(str(path)).description
    assert described and "\n" not in described and described.split(":")[0].strip()  # "scenario: what it tests"
    scen = make_scenario(str(path))
    walls = scen.walls.reshape(-1, 4)
    assert scen.robot_start is not None
    for rect in (scen.robot_start, scen.robot_goal):
        pts = _rect_points(rect)
        assert _inside(pts, scen.bounds)
        assert wall_clearance(pts, walls).min() >= RADIUS + 0.05  # the whole area: the robot's body clears every wall
    start, goal = _rect_points(scen.robot_start)[-1], _rect_points(scen.robot_goal)[-1]
    route = grid_route(start, goal, walls, RouteConfig(), RADIUS)
    assert route is not None and _inside(route, scen.bounds)  # a way through the scene, not round its open ends
    assert wall_clearance(route[1:-1], walls).min() >= RADIUS


def _people_at_start(cell_name: str, seed: int) -> tuple[CrowdNavEnv, np.ndarray]:
    env = CrowdNavEnv(SUITE.cell(cell_name).env_config(seed))
    env.reset(seed=seed)
    heading = env.goal - env.robot_state[:2]
    return env, heading / np.linalg.norm(heading)


@pytest.mark.parametrize("cell", [c for c in SUITE.cells if c.name.endswith("-visible")], ids=lambda c: c.name)
def test_every_cell_builds_resets_and_runs_a_few_steps(cell):
    env = CrowdNavEnv(cell.env_config(cell.seeds[0]))
    policy = make_policy("social-force", env)
    env.reset(seed=cell.seeds[0])
    policy.reset(cell.seeds[0])
    start = env.robot_state[:2].copy()
    for _ in range(10):
        _, _, terminated, _, _ = env.step_decision(decide(policy, env))
        assert not terminated  # nothing can end an episode in its first second
    assert len(env.pedestrians().pos) >= 1 and np.linalg.norm(env.robot_state[:2] - start) > 0.1


# (cell, people, the sizes of their groups): the group variants hold exactly their group at every seed
GROUPS = [("hallway-pair-visible", [2]), ("hallway-four-visible", [4]), ("overtaking-group-visible", [3]),
          ("doorway-group-visible", [3])]


@pytest.mark.parametrize("name,sizes", GROUPS)
def test_group_cells_hold_their_group_at_every_seed(name, sizes):
    for seed in SUITE.cell(name).seeds:
        env, _ = _people_at_start(name, seed)
        groups = env.pedestrians().group_id
        assert sorted(np.unique(groups, return_counts=True)[1].tolist()) == sizes, seed


def test_the_doorway_group_stands_in_a_circle_beside_the_door():
    for seed in SUITE.cell("doorway-group-visible").seeds:
        env, _ = _people_at_start("doorway-group-visible", seed)
        still = np.array([-1.0, 0.0], np.float32)  # the robot stays put (speed 0)
        for _ in range(20):
            env.step(still)
        before = env.pedestrians().pos  # 2 s in: the last members have found their places
        for _ in range(30):
            env.step(still)
        p = env.pedestrians()
        assert np.linalg.norm(p.pos - before, axis=1).max() < 0.35  # standing (shuffling a little) for 3 s
        assert len(env.crowd.sim.book.stops) == 1  # crowdsim's stop: an F-formation
        centre = p.pos.mean(axis=0)
        assert 8.0 < centre[0] < 11.0 and 4.6 < centre[1] < 6.4  # beside the door's far side (x = 8, y 3.4-4.6)
        spread = np.linalg.norm(p.pos - centre, axis=1)
        assert np.ptp(spread) < 0.3  # on a circle round the o-space centre, not a line


# cells whose one person must be walking at the robot (ahead, coming towards it) or after it (behind, same way)
ENCOUNTERS = {"frontal-visible": "towards", "hallway-visible": "towards", "doorway-visible": "towards",
              "blind-corner-visible": "towards-after-the-turn", "overtaking-visible": "behind"}


@pytest.mark.parametrize("name", sorted(ENCOUNTERS))
def test_the_encounter_is_set_up_when_the_robot_sets_off(name):
    for seed in SUITE.cell(name).seeds[:3]:
        env, heading = _people_at_start(name, seed)
        p = env.pedestrians()
        offset = p.pos[0] - env.robot_state[:2]
        if ENCOUNTERS[name] == "towards":
            assert offset @ heading > 5.0 and p.vel[0] @ heading < -0.8  # ahead, walking at the robot
        elif ENCOUNTERS[name] == "behind":
            assert offset @ heading < -2.0 and p.vel[0] @ heading > 0.8  # behind, walking its way
        else:  # coming down the hallway the robot turns into, above the junction
            assert p.pos[0][1] > 6.0 and p.vel[0][1] < -0.8 and env.goal[1] > 6.0


def test_a_cell_sets_its_crowds_groups_and_behaviour_and_misspellings_are_refused():
    from envs.evaluation.suite import parse_suite

    cell = SUITE.cell("doorway-group-visible").env_config(0)
    assert (cell.groups.size_poisson_rate, cell.groups.max_size) == (30.0, 3)  # max_size stays min(5, people)
    assert cell.behaviour.stop_rate_hz > 0 and cell.sim_config().behaviour == cell.behaviour
    assert SUITE.cell("frontal-visible").env_config(0).behaviour.stop_rate_hz == 0  # default: nobody stops
    base = {"name": "x", "scenario": "corridor", "n_pedestrians": 4, "robot_visible": True, "episodes": 1, "seed0": 0}
    for key, bad in (("crowd_groups", {"size_rate": 3.0}), ("behaviour", {"stop_hz": 1.0})):
        with pytest.raises(ValueError, match=f"{key} must map .*unknown: \\['{next(iter(bad))}'\\]"):
            parse_suite({"name": "s", "version": 1, "cells": [{**base, key: bad}]})
    replay = {"name": "r", "replay": ["a.txt"], "frame_step_s": 0.4, "episodes": 1, "seed0": 0,
              "crowd_groups": {"max_size": 2}}
    with pytest.raises(ValueError, match="a replay cell takes no"):
        parse_suite({"name": "s", "version": 1, "cells": [replay]})


def test_benchmark_first_episodes_runs_the_first_seeds_only(tmp_path):
    from envs.cli import main
    from envs.evaluation.records import read_records

    out = tmp_path / "run"
    assert main(["benchmark", "--suite", "socnav-scenarios", "--cells", "frontal-invisible", "--first-episodes", "2",
                 "--policy", "random", "--out", str(out), "--workers", "1", "--no-progress"]) == 0
    assert sorted(r.seed for r in read_records(out / "records.jsonl")) == [0, 1]
    assert main(["benchmark", "--suite", "socnav-scenarios", "--cells", "frontal-invisible", "--first-episodes", "0",
                 "--policy", "random", "--out", str(out), "--no-progress"]) == 2
