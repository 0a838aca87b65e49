"""CrowdNav's ORCA crowd (`envs.crowds.orca`), the `orca` policy and the suites crowdnav-classic / crowdnav-plusplus."""

from __future__ import annotations

import ast
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.cli import main
from envs.crowds.crowd import rows_of
from envs.crowds.orca import OrcaCrowd, OrcaCrowdConfig
from envs.crowds.rvo import OrcaParams, load_pyrvo, orca_velocities, pref_velocity
from envs.evaluation.suite import load_suite, parse_suite
from envs.policies import ENV_MPC, PolicyConfig, decide, make_policy
from planner import RobotConfig

ROOT = Path(__file__).resolve().parents[2]
HOLONOMIC = RobotConfig(model="holonomic", radius_m=0.3, max_speed_mps=1.0, max_accel_mps2=1000.0)


def classic(**kw) -> CrowdNavConfig:
    base = dict(scenario="circle_crossing", crowd_model="orca", n_pedestrians=5, robot_visible=False,
                scenario_options=(("radius_m", 4.0),), dt_s=0.05, warmup_s=0.0, time_limit_s=25.0, robot=HOLONOMIC)
    return CrowdNavConfig(**{**base, **kw})


def run_episode(env: CrowdNavEnv, seed: int, policy: str = "orca") -> tuple[dict, np.ndarray]:
    """The episode's metrics and the robot's positions (steps, 2)."""
    pol = make_policy(policy, env)
    env.reset(seed=seed)
    pol.reset(seed)
    path, done = [env.robot_state[:2].copy()], False
    while not done:
        _, _, term, trunc, info = env.step_decision(decide(pol, env))
        path.append(env.robot_state[:2].copy())
        done = term or trunc
    return info["episode_metrics"], np.array(path)


def test_only_envs_rvo_imports_pyrvo():
    importers = []
    for path in ROOT.glob("*/**/*.py"):
        if ".venv" in path.parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            if any(n.split(".")[0] == "pyrvo" for n in names):
                importers.append(path.relative_to(ROOT).as_posix())
    assert sorted(set(importers)) == ["envs/crowds/rvo.py"]


def test_circle_crossing_places_humans_as_crowdnav_does():
    crowd = OrcaCrowd(classic(n_pedestrians=10))
    for seed in range(20):
        state = crowd.reset(seed)
        start, goal = crowd.robot_route(np.random.default_rng(0))
        np.testing.assert_array_equal(start, [0.0, -4.0])
        np.testing.assert_array_equal(goal, [0.0, 4.0])
        np.testing.assert_array_equal(state.goal, -state.pos)  # each human heads for the opposite point
        dist = np.linalg.norm(state.pos, axis=1)
        assert np.all((dist > 4.0 - 0.5 * np.sqrt(2) - 1e-9) & (dist < 4.0 + 0.5 * np.sqrt(2) + 1e-9))
        others = np.vstack([state.pos, state.goal, [start, goal]])
        for i, p in enumerate(state.pos):  # clear of every start and goal but its own (0.3 + 0.3 + 0.2 m)
            gaps = np.linalg.norm(others - p, axis=1)
            gaps[i] = np.inf
            assert gaps.min() >= 0.8 - 1e-9 or np.isclose(gaps.min(), np.linalg.norm(2 * p))
        assert np.all(state.vel == 0) and np.all(state.group_id == np.arange(10))  # at rest, everyone alone


def test_orca_humans_cross_an_empty_circle_to_their_goals_without_touching():
    crowd = OrcaCrowd(classic(n_pedestrians=8))
    state = crowd.reset(4)
    closest = np.inf
    for _ in range(int(20.0 / crowd.dt_s)):
        state = crowd.step()
        d = np.linalg.norm(state.pos[:, None] - state.pos[None], axis=-1) + np.eye(8) * 1e9
        closest = min(closest, float(d.min()) - 0.6)
    assert np.all(np.linalg.norm(state.pos - state.goal, axis=1) < 0.05)  # all arrived, and stay
    assert closest > -0.01  # no two humans overlapped by more than 1 cm (ORCA's discrete steps)
    assert np.all(np.linalg.norm(state.vel, axis=1) <= 1.0 + 1e-6)


def test_orca_velocities_keep_v_pref_when_nobody_is_near_and_slow_down_at_the_goal():
    pos = np.array([[0.0, 0.0], [50.0, 50.0]])
    goal = np.array([[10.0, 0.0], [50.3, 50.0]])
    v = orca_velocities(pos, np.zeros((2, 2)), pref_velocity(pos, goal, np.ones(2)), np.full(2, 0.3), np.ones(2),
                        OrcaParams())
    np.testing.assert_allclose(v, [[1.0, 0.0], [0.3, 0.0]], atol=1e-6)


def test_the_same_seed_gives_the_same_episode_and_another_seed_another():
    env = CrowdNavEnv(classic())
    a, path_a = run_episode(env, 7)
    b, path_b = run_episode(env, 7)
    _, path_c = run_episode(env, 8)
    assert a == b
    np.testing.assert_array_equal(path_a, path_b)
    assert path_a.shape != path_c.shape or not np.array_equal(path_a, path_c)


def test_the_oracle_future_is_what_happens_when_the_crowd_does_not_see_the_robot():
    env = CrowdNavEnv(classic())
    pol = make_policy("orca", env)
    env.reset(seed=7)  # an episode that lasts 10.7 s
    pol.reset(7)
    for _ in range(7):  # off the 0.25 s decision grid on purpose
        env.step_decision(decide(pol, env))
    view = env.view(future=True)
    happened = []
    for k in range(1, 97):  # 4.8 s at 0.05 s
        _, _, term, trunc, _ = env.step_decision(decide(pol, env))
        if k % 8 == 0:
            happened.append(rows_of(env._state, view.pedestrians.ped_id))
        assert not (term or trunc), "the check needs an episode that lasts 4.8 s more"
    np.testing.assert_array_equal(view.future, np.array(happened))


def test_humans_who_see_the_robot_make_way_and_those_who_do_not_walk_through():
    outcomes = {}
    for visible in (True, False):
        env = CrowdNavEnv(classic(robot_visible=visible))
        stats = [run_episode(env, s)[0] for s in range(8)]
        outcomes[visible] = [m["outcome"] for m in stats]
    assert outcomes[True].count("success") == 8  # reciprocity holds: ORCA meets ORCA
    assert outcomes[False].count("collision") >= 2  # the invisible setting where ORCA fails (SARL, Table I)


def test_the_orca_robot_takes_the_straight_line_at_v_pref_in_an_empty_scene():
    env = CrowdNavEnv(classic(n_pedestrians=1, scenario_options=(("radius_m", 4.0),)))
    env.reset(seed=0)
    env.crowd.pos = np.array([[30.0, 30.0]])  # far away; it walks to (-30, -30), nowhere near the route
    env.crowd.goal = -env.crowd.pos
    pol = make_policy("orca", env)
    pol.reset(0)
    done = False
    while not done:
        _, _, term, trunc, info = env.step_decision(decide(pol, env))
        assert abs(env.robot_state[0]) < 1e-9
        done = term or trunc
    m = info["episode_metrics"]
    # 7 m at 1 m/s, then CrowdNav's last metre: the remaining vector as the preferred velocity (0.75 of the gap is
    # left after each 0.25 s step) until within the 0.3 m goal radius: 8.0-8.25 s
    assert m["success"] and 8.0 <= m["time_to_goal_s"] <= 8.3


def test_bad_crowd_settings_raise_one_clear_error():
    with pytest.raises(ValueError, match=r"unknown crowd model 'orcas'; did you mean 'orca'\? valid names: social"):
        CrowdNavConfig(crowd_model="orcas", scenario="circle_crossing")
    with pytest.raises(ValueError, match=r"only scenario circle_crossing .*walls.*'corridor'"):
        CrowdNavConfig(crowd_model="orca", scenario="corridor")
    with pytest.raises(ValueError, match="whole multiple of dt_s"):
        classic(dt_s=0.1)
    with pytest.raises(ValueError, match="robot_route"):
        OrcaCrowdConfig(robot_route="circle")
    assert CrowdNavConfig().crowd_model == "social-force"  # the default crowd is unchanged


def test_a_missing_pyrvo_is_one_line_and_exit_2_with_nothing_written(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "pyrvo", None)
    with pytest.raises(ValueError, match=r"need the package pyrvo.*pip install --no-deps"):
        load_pyrvo()
    out = tmp_path / "bench"
    assert main(["benchmark", "--suite", "crowdnav-classic", "--policy", "orca", "--out", str(out),
                 "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pyrvo" in err
    assert not out.exists()


def test_the_suites_hold_crowdnavs_settings():
    c = load_suite("crowdnav-classic").cells[0]
    cfg = c.env_config(c.seeds[0])
    assert (cfg.crowd_model, cfg.n_pedestrians, cfg.robot_visible, cfg.robot.model) == ("orca", 5, False, "holonomic")
    assert (cfg.robot.radius_m, cfg.robot.max_speed_mps, cfg.time_limit_s, len(c.seeds)) == (0.3, 1.0, 25.0, 500)
    assert dict(cfg.scenario_options)["radius_m"] == 4.0 and cfg.orca == OrcaCrowdConfig()
    p = load_suite("crowdnav-plusplus").cells[0]
    pcfg = p.env_config(p.seeds[0])
    assert (pcfg.n_pedestrians, pcfg.time_limit_s, len(p.seeds)) == (20, 50.0, 500)
    assert np.isclose(dict(pcfg.scenario_options)["radius_m"], 6 * np.sqrt(2)) and pcfg.orca.robot_route == "random"
    for cell in load_suite("crowdnav-v1").cells:  # the existing suites are built as before
        if not cell.is_real:
            assert cell.env_config(0).crowd_model == "social-force"


def test_a_suite_with_unknown_orca_fields_or_crowd_model_is_refused():
    cell = {"name": "x", "scenario": "circle_crossing", "crowd_model": "orca", "n_pedestrians": 5,
            "robot_visible": False, "episodes": 1, "seed0": 0}
    with pytest.raises(ValueError, match=r"unknown: \['horizon_s'\]; valid: .*time_horizon_s"):
        parse_suite({"name": "s", "version": 1, "cells": [{**cell, "orca": {"horizon_s": 5}}]})
    with pytest.raises(ValueError, match="valid names: social-force, orca"):
        parse_suite({"name": "s", "version": 1, "cells": [{**cell, "crowd_model": "rvo"}]})
    suite = parse_suite({"name": "s", "version": 1, "defaults": {"dt_s": 0.05},
                         "cells": [{**cell, "robot": {"model": "holonomic"}}]})
    assert suite.cells[0].env_config(0).robot == replace(RobotConfig(), model="holonomic")


@pytest.mark.parametrize("name", ["crowdnav-classic", "crowdnav-plusplus"])
def test_each_crowdnav_setting_has_a_tuning_suite_with_the_same_episodes_rules_at_other_seeds(name: str) -> None:
    """crowdnav-classic-tune / crowdnav-plusplus-tune: the reported cell's settings and defaults exactly, at seeds that
    the reported suite never uses."""
    reported, tune = load_suite(name), load_suite(f"{name}-tune")
    (ref,), (cell,) = reported.cells, tune.cells
    assert cell.defaults == ref.defaults
    assert cell.spec | {"name": "", "seed0": 0, "episodes": 0} == ref.spec | {"name": "", "seed0": 0, "episodes": 0}
    assert min(cell.seeds) > max(ref.seeds)
    assert cell.env_config(cell.seeds[0]) == ref.env_config(cell.seeds[0])  # one seed, one episode, in either suite
    assert (tune.replan_every_steps, tune.mpc) == (reported.replan_every_steps, reported.mpc)  # the planner's too


def test_a_suites_planner_defaults_reach_the_planner_policies_and_the_command_line_overrides_them():
    from envs.cli import build_parser
    from envs.cli_options import policy_configs

    cell = {"name": "x", "scenario": "circle_crossing", "n_pedestrians": 5, "robot_visible": False, "episodes": 1,
            "seed0": 0}
    suite = parse_suite({"name": "s", "version": 1, "cells": [cell],
                         "planner": {"replan_every_steps": 5, "mpc": {"clearance_growth_mps": 0.0}}})
    parse = build_parser().parse_args
    cv, sf = policy_configs(parse(["benchmark", "--suite", "s", "--out", "x", "--policy", "mpc-cv", "social-force"]),
                            suite)
    assert (cv.replan_every_steps, cv.mpc.clearance_growth_mps) == (5, 0.0)
    assert cv.mpc == replace(ENV_MPC, clearance_growth_mps=0.0)  # nothing else changes
    assert sf == PolicyConfig("social-force")  # a policy that reads neither keeps its defaults, and no error
    (cv,) = policy_configs(parse(["benchmark", "--suite", "s", "--out", "x", "--policy", "mpc-cv", "--replan-every",
                                  "2", "--mpc", "clearance_growth_mps=0.1", "--mpc", "safety_margin_m=0.4"]), suite)
    assert (cv.replan_every_steps, cv.mpc.clearance_growth_mps, cv.mpc.safety_margin_m) == (2, 0.1, 0.4)
    for bad, needle in [({"mpc": {"robot": {}}}, "unknown or fixed"), ({"mpc": {"dt_s": -1.0}}, "dt_s"),
                        ({"replan_every_steps": 0}, "integer >= 1"), ({"policy": 1}, "planner must map")]:
        with pytest.raises(ValueError, match=needle):
            parse_suite({"name": "s", "version": 1, "cells": [cell], "planner": bad})
