"""`NAME+shield` and `NAME+route`: the MPC's safety shield and global route around any policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from envs import CrowdNavEnv
from envs.cli_options import flags_read, reads_observation
from envs.crowds.replay import ReplayConfig
from envs.policies import PolicyConfig, decide, make_policy
from envs.policies.identity import artifact_files, policy_identity
from envs.policies.shielded import ShieldedPolicy
from envs.policies.wrappers import split_wrappers
from envs.view import Decision, action_command
from planner import CROWD_MPC, MPCConfig, RobotConfig
from tests.envs.test_env import place_robot


class FullAhead:
    """Drives straight ahead at full speed, whatever it sees (a policy that never learnt about people)."""

    name = "full-ahead"
    reads_history = False

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, view) -> Decision:
        return Decision(action=np.array([1.0, 0.0], np.float32))


def _scene(tmp_path: Path, ped_xy: tuple[float, float]) -> CrowdNavEnv:
    """Robot at the origin heading for (8, 0); one person standing at ped_xy for the whole recording."""
    rows = [f"{10 * t}\t1\t{ped_xy[0]}\t{ped_xy[1]}" for t in range(60)]
    path = tmp_path / "standing.txt"
    path.write_text("\n".join(rows) + "\n")
    env = CrowdNavEnv(scenario="replay", replay=ReplayConfig(path=path, start_mode="fixed"))
    env.reset(seed=0)
    place_robot(env, (0.0, 0.0), (8.0, 0.0))
    return env


def _run(env: CrowdNavEnv, policy) -> tuple[dict, list[np.ndarray]]:
    policy.reset(0)
    actions = []
    for _ in range(400):
        decision = decide(policy, env)
        actions.append(env.action_for(decision))
        _, _, term, trunc, info = env.step_decision(decision)
        if term or trunc:
            return info["episode_metrics"], actions
    raise AssertionError("episode did not end")


def _shield_config(env: CrowdNavEnv) -> MPCConfig:
    from dataclasses import replace

    return replace(CROWD_MPC, robot=env.config.robot)


def test_the_shield_keeps_a_blind_policy_off_a_standing_person(tmp_path):
    metrics, _ = _run(_scene(tmp_path, (3.0, 0.0)), FullAhead())
    assert metrics["collision"] and metrics["at_fault"] == "robot"  # unshielded: straight into them
    env = _scene(tmp_path, (3.0, 0.0))
    shielded = ShieldedPolicy(FullAhead(), _shield_config(env))
    metrics, _ = _run(env, shielded)
    assert not metrics["collision"]
    assert metrics["min_distance_m"] > 0.0  # surface distance: it never touched them
    assert shielded.stats.counts["shielded"] > 0
    assert shielded.stats.counts["calls"] == len(shielded.stats.solve_times_s) > 0


def test_with_nobody_in_reach_the_decisions_pass_unchanged(tmp_path):
    _, plain = _run(_scene(tmp_path, (30.0, 30.0)), FullAhead())
    env = _scene(tmp_path, (30.0, 30.0))
    shielded = ShieldedPolicy(FullAhead(), _shield_config(env))
    metrics, actions = _run(env, shielded)
    assert metrics["success"] and shielded.stats.counts["shielded"] == 0
    assert len(actions) == len(plain) and all(np.array_equal(a, b) for a, b in zip(actions, plain, strict=True))


def test_action_command_is_the_env_scaling():
    robot = RobotConfig(min_speed_mps=0.4)
    assert np.allclose(action_command(-1.0, 1.0, robot), [-0.4, 2.0])
    assert np.allclose(action_command(1.0, -2.0, robot), [1.2, -2.0])  # clipped to [-1, 1] first
    assert np.allclose(action_command(0.5, -0.5, RobotConfig(model="holonomic")), [0.6, -0.6])


def test_names_configs_and_files():
    assert split_wrappers("ppo-crowdnav-mix+shield") == ("ppo-crowdnav-mix", ("+shield",))
    assert split_wrappers("ppo-crowdnav-mix+route+shield") == ("ppo-crowdnav-mix", ("+route", "+shield"))
    assert split_wrappers("ppo-crowdnav-mix") == ("ppo-crowdnav-mix", ())
    for bad in ("+shield", "random+shield+shield", "mpc-cv+shield", "mpc-gpgraph+shield", "random+shield+route",
                "mpc-cv+route"):
        with pytest.raises(ValueError):
            PolicyConfig(bad)
    with pytest.raises(ValueError, match="unknown policy"):
        PolicyConfig("no-such+shield")
    cfg = PolicyConfig("ppo-crowdnav-mix+shield")
    assert artifact_files(cfg) == artifact_files(PolicyConfig("ppo-crowdnav-mix"))
    assert policy_identity(cfg) != policy_identity(PolicyConfig("ppo-crowdnav-mix"))  # resume never mixes them
    assert "--mpc" in flags_read(cfg.name) and "--threads" in flags_read(cfg.name)
    assert reads_observation(cfg.name) and not reads_observation("mpc-cv")


def test_make_policy_wraps_and_refuses_a_shield_turned_off():
    env = CrowdNavEnv()
    policy = make_policy(PolicyConfig("random+shield"), env)
    assert isinstance(policy, ShieldedPolicy) and policy.name == "random+shield"
    assert policy.config.robot == env.config.robot
    from dataclasses import replace

    with pytest.raises(ValueError, match="shield_horizon_s"):
        make_policy(PolicyConfig("random+shield", mpc=replace(CROWD_MPC, shield_horizon_s=0.0)), env)


class Probe:
    """Records every view it is handed; stands still."""

    name = "probe"
    reads_history = False

    def __init__(self) -> None:
        self.views = []

    def reset(self, seed: int | None = None) -> None:
        self.views = []

    def act(self, view) -> Decision:
        self.views.append(view)
        return Decision(action=np.array([-1.0, 0.0], np.float32))


def _door_env() -> CrowdNavEnv:
    from envs.evaluation.suite import load_suite

    cell = load_suite("crowdnav-tune").cell("tune-door-low-visible")
    env = CrowdNavEnv(cell.env_config(1002))
    env.reset(seed=1002)  # robot in the room at (5.6, 5.7), goal beyond the door at (11, 3.5)
    return env


def test_route_gives_the_policy_a_subgoal_it_can_see_through_the_door():
    from envs.observation import build_observation
    from envs.policies.routed import RoutedPolicy
    from planner.route import in_sight

    env = _door_env()
    cfg = _shield_config(env)
    goal, here = env.goal.copy(), env.robot_state[:2].copy()
    walls = env.view().walls
    assert not in_sight(here, goal[None], walls, cfg.wall_clearance_m, 0.1)[0]  # the goal is behind the wall
    probe = Probe()
    routed = RoutedPolicy(probe, cfg, env)
    routed.reset(0)
    routed.act(env.view())
    seen = probe.views[-1]
    assert not np.array_equal(seen.goal, goal) and np.array_equal(env.goal, goal)  # the env keeps the real goal
    assert in_sight(here, seen.goal[None], walls, cfg.wall_clearance_m, 0.1)[0]
    expected = build_observation(env.config, env.observation_space, env.robot_state, seen.goal, 1.0, np.zeros((0, 2)),
                                 np.zeros((0, 2)), np.zeros(0), np.zeros(0, int), None, walls)["robot"]
    assert np.allclose(seen.obs["robot"][:3], expected[:3], atol=1e-5)
    assert np.array_equal(seen.obs["robot"][3:], env.view().obs["robot"][3:])  # speed, radius, time left unchanged
    assert routed.name == "probe+route"


def test_route_without_walls_passes_the_view_unchanged():
    from envs.policies.routed import RoutedPolicy

    env = CrowdNavEnv()
    env.reset(seed=0)
    probe = Probe()
    routed = RoutedPolicy(probe, _shield_config(env), env)
    view = env.view()
    routed.act(view)
    assert probe.views[-1] is view


def test_route_takes_a_wall_blind_policy_through_the_door():
    """social-force heads straight for the goal and slides along the wall; with +route it goes through the door.
    (crowdnav-tune's door cell at seed 1004 with 5 people: the goal is behind the room's wall.)"""
    from dataclasses import replace

    from envs.evaluation.episode import run_episode
    from envs.evaluation.suite import load_suite

    cfg = replace(load_suite("crowdnav-tune").cell("tune-door-low-visible").env_config(1004), n_pedestrians=5)
    assert run_episode(cfg, "social-force", 1004).metrics["outcome"] == "timeout"
    assert run_episode(cfg, "social-force+route", 1004).metrics["outcome"] == "success"
