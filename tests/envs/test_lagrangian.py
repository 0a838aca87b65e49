"""Constrained PPO (`envs.rl.lagrangian`, `envs.rl.cost`): the multiplier, the cost GAE, the update against plain PPO
and towards cheap actions, the env's cost signal, and `crowdnav train --constraint` end to end."""

from __future__ import annotations

import csv
import json

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces

from envs import CrowdNavConfig, CrowdNavEnv
from envs.cli import main
from envs.rl.cost import ConstraintCost, decision_costs, wrap_for_cost
from envs.rl.lagrangian import CostRolloutBuffer, PPOLagrangian, combined_advantage, gae, next_multiplier
from envs.rl.monitor import EVAL_FIELDS
from envs.rl.train import TrainConfig, make_model, make_vec_env, train

torch.set_num_threads(1)
BOTH = (("collision", 1.0), ("group_intrusion", 1.0))
SMALL = TrainConfig(pedestrians=5, time_limit_s=4.0, envs=2, n_steps=32, batch_size=32, n_epochs=2)


class Toll(gym.Env):
    """One-step episodes: action a in [-1, 1], reward 0.5 a (right pays), and intruding (costly) when a > 0."""

    observation_space = spaces.Dict({"x": spaces.Box(-1.0, 1.0, (1,), np.float32)})
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        return {"x": np.zeros(1, np.float32)}, {}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        a = float(action[0])
        return {"x": np.zeros(1, np.float32)}, 0.5 * a, True, False, {"intruding": a > 0}


def toll_model(multiplier: float, seed: int = 0) -> PPOLagrangian:
    from stable_baselines3.common.env_util import make_vec_env as sb3_vec

    venv = sb3_vec(lambda: wrap_for_cost(Toll(), {"group_intrusion": 1.0}, dt_s=1.0), n_envs=4, seed=seed)
    return PPOLagrangian("MultiInputPolicy", venv, n_steps=32, batch_size=64, n_epochs=4, learning_rate=3e-3,
                         seed=seed, device="cpu", cost_budget=0.5, lambda_lr=1e-9, lambda_init=multiplier)


def test_the_multiplier_rises_over_the_budget_and_falls_to_no_lower_than_zero():
    assert next_multiplier(1.0, 0.5, 0.2, 0.1) == pytest.approx(1.03)  # 0.3 over the budget
    assert next_multiplier(1.0, 0.0, 0.2, 0.1) == pytest.approx(0.98)  # 0.2 under it
    assert next_multiplier(0.01, 0.0, 0.2, 0.1) == 0.0  # never negative
    lam, path = 0.0, []
    for cost in (1.0, 1.0, 0.0, 0.0, 0.0, 0.0):
        lam = next_multiplier(lam, cost, 0.5, 0.4)
        path.append(lam)
    assert path == pytest.approx([0.2, 0.4, 0.2, 0.0, 0.0, 0.0])
    model = toll_model(0.3)  # J_c: this rollout's finished episodes, else the recent ones, else none
    assert model.episode_cost is None
    model._measure_episode_cost([1.0, 0.0, 0.0, 1.0])
    assert model.episode_cost == 0.5
    model._measure_episode_cost([])
    assert model.episode_cost == 0.5
    model._measure_episode_cost([1.0])
    assert model.episode_cost == 1.0 and list(model.recent_episode_costs) == [1.0, 0.0, 0.0, 1.0, 1.0]
    state = model.lagrangian_state()
    fresh = toll_model(0.0)
    fresh.load_lagrangian_state(json.loads(json.dumps(state)))
    assert fresh.lagrangian_state() == state and fresh.lagrange_multiplier == 0.3
    np.testing.assert_allclose(combined_advantage(np.array([1.0, -2.0]), np.array([4.0, 0.0]), 3.0), [-2.75, -0.5])


def test_cost_gae_equals_a_hand_computation_and_sb3s_gae():
    from stable_baselines3.common.buffers import RolloutBuffer

    space = spaces.Dict({"x": spaces.Box(-1.0, 1.0, (1,), np.float32)})
    buf = CostRolloutBuffer(4, space, spaces.Box(-1.0, 1.0, (1,), np.float32), gamma=0.9, gae_lambda=0.8, n_envs=1)
    buf.reset()
    buf.costs[:, 0] = [0.0, 1.0, 0.0, 0.5]  # an episode ends after step 1 (step 2 starts the next)
    buf.cost_values[:, 0] = [0.2, 0.4, 0.1, 0.3]
    buf.episode_starts[:, 0] = [1.0, 0.0, 1.0, 0.0]
    buf.compute_cost_advantage(torch.tensor([[0.6]]), np.array([False]))
    # t3: 0.5 + 0.9 0.6 - 0.3 = 0.74; t2: 0.9 0.3 - 0.1 + 0.72 0.74 = 0.7028; t1 (its episode's end): 1 - 0.4;
    # t0: 0.9 0.4 - 0.2 + 0.72 0.6 = 0.592
    np.testing.assert_allclose(buf.cost_advantages[:, 0], [0.592, 0.6, 0.7028, 0.74], rtol=1e-6)
    np.testing.assert_allclose(buf.cost_returns[:, 0], [0.792, 1.0, 0.8028, 1.04], rtol=1e-6)
    rng = np.random.default_rng(0)  # and the reward GAE of SB3's own buffer, on random rollouts of 3 envs
    ref = RolloutBuffer(6, spaces.Box(-1.0, 1.0, (1,)), spaces.Box(-1.0, 1.0, (1,)), gamma=0.95, gae_lambda=0.9,
                        n_envs=3)
    ref.rewards, ref.values = rng.normal(size=(6, 3)).astype(np.float32), rng.normal(size=(6, 3)).astype(np.float32)
    ref.episode_starts = (rng.random((6, 3)) < 0.3).astype(np.float32)
    last, dones = rng.normal(size=3).astype(np.float32), np.array([True, False, False])
    ref.compute_returns_and_advantage(torch.as_tensor(last), dones)
    adv, ret = gae(ref.rewards, ref.values, ref.episode_starts, last, dones, 0.95, 0.9)
    np.testing.assert_allclose(adv, ref.advantages, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(ret, ref.returns, rtol=1e-6, atol=1e-7)


def _trained_weights(cfg: TrainConfig, steps: int = 192) -> dict[str, torch.Tensor]:
    model = make_model(cfg, make_vec_env(cfg))
    model.learn(steps)
    return model.policy.state_dict()


def test_with_the_multiplier_at_zero_training_is_ppo_bit_for_bit():
    """A constrained run whose cost is zero keeps lambda 0, and then every PPO weight after three updates equals plain
    PPO's with the same seed (the same actions, minibatches and updates); with lambda 1 the weights differ."""
    ppo = _trained_weights(SMALL)
    zero = TrainConfig.from_json({**SMALL.to_json(), "constraint": {"collision": 0.0}, "cost_budget": 0.1})
    constrained = _trained_weights(zero)
    assert set(constrained) - set(ppo) == {f"cost_net.{i}.{p}" for i in (0, 2, 4) for p in ("weight", "bias")}
    assert all(torch.equal(ppo[k], constrained[k]) for k in ppo)
    pulled = _trained_weights(TrainConfig.from_json({**zero.to_json(), "lambda_init": 1.0}))
    assert not all(torch.equal(ppo[k], pulled[k]) for k in ppo)


def test_a_large_multiplier_turns_the_policy_to_the_cheap_action(tmp_path):
    """Toll: going right (a > 0) pays 0.5 a and costs 1. Without the multiplier PPO goes right; with lambda 50 the
    same start (same seed) goes left, and the cost critic learns the cost (the logged loss falls)."""
    from stable_baselines3.common.logger import configure

    obs = {"x": np.zeros(1, np.float32)}
    mean = {}
    for lam in (0.0, 50.0):
        model = toll_model(lam)
        model.set_logger(configure(str(tmp_path / str(lam)), ["csv"]))
        start = float(model.predict(obs, deterministic=True)[0][0])
        model.learn(4 * 32 * 6)
        mean[lam] = float(model.predict(obs, deterministic=True)[0][0])
        rows = list(csv.DictReader((tmp_path / str(lam) / "progress.csv").open()))
        assert [float(r["constraint/lagrange_multiplier"]) for r in rows] == pytest.approx([lam] * 6, abs=1e-6)
        costs = [float(r["constraint/episode_cost"]) for r in rows]  # one-step episodes: the share going right
        assert all(0.0 <= c <= 1.0 for c in costs)
        loss = [float(r["train/cost_value_loss"]) for r in rows[1:]]  # SB3 logs an update in the next row
        assert loss[-1] < loss[0]
    assert mean[0.0] > start + 0.1 and mean[50.0] < start - 0.1
    assert costs[-1] < 0.5  # lambda 50: most actions go left


def _chase(env: CrowdNavEnv) -> np.ndarray:
    """The action that runs at full speed at the nearest pedestrian (a holonomic robot)."""
    d = env.pedestrians().pos - env.robot_state[:2]
    k = int(np.argmin((d ** 2).sum(1)))
    return env.control_to_action(d[k] / np.linalg.norm(d[k]) * env.config.robot.max_speed_mps)


def test_the_env_cost_counts_a_collision_once_and_intrusion_seconds_summed_over_a_decision():
    from envs.rl.setting import DecisionPeriod
    from planner import RobotConfig

    cfg = CrowdNavConfig(scenario="circle_crossing", n_pedestrians=6, robot=RobotConfig(model="holonomic"))
    every, actions, steps = 4, [], []
    env = ConstraintCost(CrowdNavEnv(cfg), dict(BOTH), cfg.dt_s)
    _, info = env.reset(seed=0)
    assert info["episode_cost"] == 0.0
    total, done = 0.0, False
    while not done:  # env steps, the action chosen every 4th and held
        if len(steps) % every == 0:
            actions.append(_chase(env.unwrapped))
        _, _, term, trunc, info = env.step(actions[-1])
        collided = bool(info.get("episode_metrics", {}).get("collision"))
        steps.append(info["episode_cost"] - total)
        assert steps[-1] == pytest.approx(float(collided) + cfg.dt_s * info["intruding"])
        total, done = info["episode_cost"], term or trunc
    assert collided and steps[-1] >= 1.0 and sum(s > 0 for s in steps[:-1]) > 0  # it intruded before colliding
    only = ConstraintCost(CrowdNavEnv(cfg), {"collision": 1.0}, cfg.dt_s)
    only.reset(seed=0)
    costs = [only.step(a)[4]["episode_cost"] for a in np.repeat(actions, every, axis=0)[:len(steps)]]
    assert costs[-1] == 1.0 and max(costs[:-1]) == 0.0  # a collision: cost 1 on its step, and only there
    held = DecisionPeriod(ConstraintCost(CrowdNavEnv(cfg), dict(BOTH), cfg.dt_s), every)
    held.reset(seed=0)
    previous, decisions = np.zeros(1), []
    for a in actions:
        totals = np.array([held.step(a)[4]["episode_cost"]])
        decisions.append(float(decision_costs(totals, previous, np.array([not decisions]))[0]))
        previous = totals
    expected = [sum(steps[i:i + every]) for i in range(0, len(steps), every)]
    assert decisions == pytest.approx(expected) and sum(decisions) == pytest.approx(total)


def test_the_discomfort_cost_is_the_depth_into_the_comfort_zone_and_comes_before_a_collision():
    from planner import RobotConfig

    cfg = CrowdNavConfig(scenario="circle_crossing", n_pedestrians=6, robot=RobotConfig(model="holonomic"))
    env = ConstraintCost(CrowdNavEnv(cfg), {"discomfort": 1.0}, cfg.dt_s)
    env.reset(seed=0)
    total, done, steps = 0.0, False, []
    while not done:  # chase the nearest pedestrian into contact
        _, _, term, trunc, info = env.step(_chase(env.unwrapped))
        gap = info["min_surface_distance_m"]
        depth = min(max(cfg.discomfort_distance_m - gap, 0.0), cfg.discomfort_distance_m) / cfg.discomfort_distance_m
        steps.append(info["episode_cost"] - total)
        assert steps[-1] == pytest.approx(cfg.dt_s * depth)  # 0 outside 0.2 m, dt_s at contact
        total, done = info["episode_cost"], term or trunc
    assert info["episode_metrics"]["collision"] and steps[-1] == pytest.approx(cfg.dt_s)
    near = [s for s in steps[:-1] if s > 0]
    assert near and 0 < min(near) < cfg.dt_s  # near misses cost before the contact, less than a contact's step
    with pytest.raises(KeyError, match="'discomfort' needs the env's step info key 'min_surface_distance_m'"):
        wrap_for_cost(Toll(), {"discomfort": 1.0}, dt_s=1.0).step(np.ones(1, np.float32))


@pytest.mark.parametrize("argv, message", [
    (["--constraint", "bogus=1", "--cost-budget", "0.1"], "unknown constraint term 'bogus'; valid: collision"),
    (["--constraint", "collision"], "expected TERM=WEIGHT"),
    (["--constraint", "collision=-1", "--cost-budget", "0.1"], "must be a finite number >= 0"),
    (["--constraint", "collision=1"], "needs a cost budget"),
    (["--constraint", "collision=1", "--cost-budget", "-0.5"], "cost_budget and lambda_init must be >= 0"),
    (["--constraint", "collision=1", "--cost-budget", "nan"], "cost_budget must be a finite number"),
    (["--constraint", "collision=1", "--cost-budget", "0.1", "--lambda-lr", "0"], "lambda_lr > 0"),
    (["--constraint", "collision=1", "--cost-budget", "0.1", "--lambda-init", "inf"], "lambda_init must be a finite"),
    (["--cost-budget", "0.1", "--lambda-lr", "0.2"], "--cost-budget, --lambda-lr only apply to constrained PPO"),
    (["--cost-source", "evaluation"], "--cost-source only apply to constrained PPO"),
    (["--constraint", "group_intrusion=1", "--cost-budget", "0.1", "--cost-source", "evaluation"],
     "measures collisions only"),
])
def test_constraint_misuse_is_one_line_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "run"
    assert main(["train", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not out.exists()
    with pytest.raises(SystemExit) as done:  # argparse's own one line for a name not among the choices
        main(["train", "--constraint", "collision=1", "--cost-budget", "0.1", "--cost-source", "evals"])
    err = capsys.readouterr().err
    assert done.value.code == 2 and "invalid choice" in err and len(err.strip().splitlines()) == 1


def test_a_constraint_from_a_toml_file_and_flags(tmp_path):
    from crowdsim.cli import OneLineParser
    from envs.rl.train import add_arguments, config_from_args

    parser = OneLineParser()
    add_arguments(parser)
    path = tmp_path / "run.toml"
    path.write_text("cost_budget = 0.2\n[constraint]\ncollision = 2\n")
    cfg, _, _ = config_from_args(parser.parse_args(["--config", str(path), "--constraint", "group_intrusion=0.5"]))
    assert cfg.constraint == (("collision", 2.0), ("group_intrusion", 0.5)) and cfg.cost_budget == 0.2
    assert TrainConfig.from_json(json.loads(json.dumps(cfg.to_json()))) == cfg
    cfg, _, _ = config_from_args(parser.parse_args(["--constraint", "collision=1,group_intrusion=1",
                                                    "--cost-budget", "0.05", "--lambda-lr", "0.2"]))
    assert (cfg.constraint, cfg.cost_budget, cfg.lambda_lr, cfg.lambda_init) == (BOTH, 0.05, 0.2, 0.0)


def test_a_constrained_agent_saves_and_loads_safely_with_its_cost_critic(tmp_path):
    from envs.policies import PolicyConfig, act, make_policy
    from envs.policies.sb3_files import agent_class, load_agent, read_agent, save_agent

    cfg = TrainConfig.from_json({**SMALL.to_json(), "constraint": dict(BOTH), "cost_budget": 0.1})
    model = make_model(cfg, make_vec_env(cfg))
    model.lagrange_multiplier = 0.75
    path = tmp_path / "agent.zip"
    save_agent(model, path, cfg.env_config())
    assert read_agent(path)[1]["algorithm"] == "PPOLagrangian"
    env = CrowdNavEnv(cfg.env_config())
    loaded = load_agent(path, "PPO", env)
    assert type(loaded) is PPOLagrangian and loaded.lagrange_multiplier == 0.75
    saved, back = model.policy.state_dict(), loaded.policy.state_dict()
    assert set(saved) == set(back) and all(torch.equal(saved[k], back[k]) for k in saved)
    agent = make_policy(PolicyConfig(f"sb3:{path}"), env)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        np.testing.assert_array_equal(act(agent, env), model.predict(obs, deterministic=True)[0])
    with pytest.raises(ValueError, match="allow-list"):
        agent_class("PPO", {"algorithm": "Sneaky"})
    with pytest.raises(ValueError, match="not a kind of SAC"):
        agent_class("SAC", {"algorithm": "PPOLagrangian"})


def _progress(out) -> dict[int, dict[str, str]]:
    return {int(r["time/total_timesteps"]): r for r in csv.DictReader((out / "tb" / "progress.csv").open())}


def test_crowdnav_train_constraint_logs_lambda_resumes_with_it_and_the_agent_benchmarks(tmp_path, capsys):
    """One rollout of a constrained run, then --resume for one more: the resumed rollout runs with the saved
    multiplier (not --lambda-init), the update follows lambda <- max(0, lambda + lr (J_c - budget)), and the agent
    runs in `crowdnav evaluate` and `crowdnav benchmark`."""
    cfg = TrainConfig(pedestrians=5, time_limit_s=4.0, total_steps=128, envs=2, n_steps=64, batch_size=64,
                      n_epochs=2, eval_every_steps=128, eval_episodes=1, checkpoint_every_steps=128, constraint=BOTH,
                      cost_budget=0.123, lambda_lr=0.5, lambda_init=1.0)
    out = tmp_path / "run"
    assert train(cfg, out) == 0
    first = _progress(out)[128]
    assert float(first["constraint/lagrange_multiplier"]) == 1.0
    saved = json.loads((out / "checkpoints" / "state.json").read_text())["lagrangian"]["multiplier"]
    assert saved == max(0.0, 1.0 + 0.5 * (float(first["constraint/episode_cost"]) - 0.123)) != 1.0
    assert "lambda 1.000" in capsys.readouterr().out
    assert main(["train", "--resume", str(out), "--steps", "256"]) == 0
    second = _progress(out)[256]
    before = {int(r["time/total_timesteps"]) for r in csv.DictReader((out / "tb" / "progress.part1.csv").open())}
    assert 128 in before and 256 not in before  # the rows logged before the resume are kept beside the new ones
    assert float(second["constraint/lagrange_multiplier"]) == saved
    state = json.loads((out / "checkpoints" / "state.json").read_text())
    assert state["steps"] == 256 and state["lagrangian"]["multiplier"] == \
        max(0.0, saved + 0.5 * (float(second["constraint/episode_cost"]) - 0.123))
    assert tuple(csv.DictReader((out / "eval.csv").open()).fieldnames) == EVAL_FIELDS  # its columns, as PPO's
    agent = f"sb3:{out / 'final.zip'}"
    assert main(["evaluate", "--policy", agent, "--scenario", "circle_crossing", "--pedestrians", "5", "--episodes",
                 "1", "--workers", "1", "--record", "0", "--no-progress", "--out", str(tmp_path / "eval")]) == 0
    assert main(["benchmark", "--suite", "smoke", "--cells", "circle-low-invisible", "--first-episodes", "1",
                 "--policy", agent, "--out", str(tmp_path / "bench"), "--workers", "1", "--no-progress"]) == 0
    assert "| circle-low-invisible |" in capsys.readouterr().out
    capsys.readouterr()
    assert main(["train", "--resume", str(out), "--constraint", "collision=2"]) == 2
    assert "only --steps may change" in capsys.readouterr().err


def test_ctrl_c_during_an_update_saves_the_multiplier_of_the_rollouts_start(tmp_path):
    """The update after a rollout changes the multiplier with the weights; Ctrl-C there saves the state as of the
    rollout's start (`TrainMonitor.save_interrupted`), the multiplier included, so a resume repeats that update once."""
    from envs.rl.monitor import TrainMonitor

    cfg = TrainConfig.from_json({**SMALL.to_json(), "n_steps": 64, "constraint": dict(BOTH), "cost_budget": 0.123,
                                 "lambda_lr": 0.5, "lambda_init": 1.0})
    model, monitor = make_model(cfg, make_vec_env(cfg)), TrainMonitor(cfg, tmp_path)
    model.learn(128, callback=monitor)  # one rollout and its update
    assert model.lagrange_multiplier != 1.0 and model.num_timesteps == 128
    monitor.safe_steps = None  # as if Ctrl-C came before the update had finished
    assert monitor.save_interrupted(model) == 0
    state = json.loads((tmp_path / "checkpoints" / "state.json").read_text())
    assert state["steps"] == 0 and state["lagrangian"]["multiplier"] == model.lagrange_multiplier == 1.0


def test_with_the_evaluation_as_cost_source_only_evaluations_step_the_multiplier(tmp_path, capsys):
    """--cost-source evaluation: a rollout leaves the multiplier as it is (its J_c is still logged), each evaluation
    of the deterministic policy steps it on the weighted collision rate; a run saves the multiplier those steps
    give from the evaluations it logged."""
    from stable_baselines3.common.env_util import make_vec_env as sb3_vec

    venv = sb3_vec(lambda: wrap_for_cost(Toll(), {"group_intrusion": 1.0}, dt_s=1.0), n_envs=4, seed=0)
    model = PPOLagrangian("MultiInputPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu",
                          cost_budget=0.1, lambda_lr=2.0, lambda_init=0.5, cost_source="evaluation")
    model.learn(64)
    assert model.episode_cost is not None and model.episode_cost > 0.1 and model.lagrange_multiplier == 0.5
    model.observe_evaluation_cost(0.3)
    assert model.lagrange_multiplier == pytest.approx(0.9)  # 0.2 over the budget
    model.observe_evaluation_cost(0.0)
    assert model.lagrange_multiplier == pytest.approx(0.7)
    model.observe_evaluation_cost(float("nan"))  # an evaluation without episodes changes nothing
    assert model.lagrange_multiplier == pytest.approx(0.7)
    rollout = toll_model(0.5)
    rollout.observe_evaluation_cost(3.0)  # the default source ignores evaluations
    assert rollout.lagrange_multiplier == 0.5
    with pytest.raises(ValueError, match="unknown cost_source"):
        PPOLagrangian("MultiInputPolicy", venv, cost_budget=0.1, cost_source="eval")
    cfg = TrainConfig(pedestrians=5, time_limit_s=4.0, total_steps=128, envs=2, n_steps=64, batch_size=64,
                      n_epochs=2, eval_every_steps=64, eval_episodes=2, checkpoint_every_steps=64,
                      constraint=(("collision", 2.0),), cost_budget=0.25, lambda_lr=1.5, lambda_init=0.2,
                      cost_source="evaluation")
    out = tmp_path / "run"
    assert train(cfg, out) == 0
    rows = [r for r in csv.DictReader((out / "eval.csv").open()) if int(r["steps"]) > 0]
    assert rows and "lagrange multiplier" in capsys.readouterr().out
    lam = 0.2
    for r in rows:
        lam = next_multiplier(lam, 2.0 * float(r["collision"]), 0.25, 1.5)
    saved = json.loads((out / "checkpoints" / "state.json").read_text())["lagrangian"]["multiplier"]
    assert saved == pytest.approx(lam)


def test_a_cost_source_not_among_the_choices_is_argparses_one_line(capsys):
    with pytest.raises(SystemExit) as done:
        main(["train", "--constraint", "collision=1", "--cost-budget", "0.1", "--cost-source", "evals"])
    err = capsys.readouterr().err
    assert done.value.code == 2 and "invalid choice" in err and len(err.strip().splitlines()) == 1
