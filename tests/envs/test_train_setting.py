"""Training in a benchmark suite's cell: the cell's env, seeds disjoint from every suite's, and the decision period
(the wrapper in training, the saved agent in the harness, the demonstrations)."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv, ObservationConfig
from envs.cli import main
from envs.evaluation.suite import load_suite, suite_names
from envs.rl.setting import TRAIN_SEED_OFFSET, DecisionPeriod, suite_seed_ranges
from envs.rl.train import TrainConfig, train

CLASSIC = TrainConfig(suite="crowdnav-classic", envs=2, n_steps=64, batch_size=64, n_epochs=1, total_steps=128,
                      eval_every_steps=128, eval_episodes=1, checkpoint_every_steps=128, demo_policy="mpc-cv",
                      demo_episodes=1, bc_epochs=1, dagger_rounds=1, dagger_episodes=1, decision_every_steps=5)


def test_a_suite_cell_is_the_env_the_suite_runs():
    cell = load_suite("crowdnav-classic").cell("classic-circle5-invisible")
    cfg = TrainConfig(suite="crowdnav-classic").env_config()  # the suite's only cell
    assert cfg == cell.env_config(cell.seeds[0])  # default observation and rewards: exactly the benchmark's env
    assert (cfg.crowd_model, cfg.robot.model, cfg.dt_s, cfg.time_limit_s) == ("orca", "holonomic", 0.05, 25.0)
    assert (cfg.scenario, cfg.n_pedestrians, cfg.robot_visible, cfg.robot.max_accel_mps2) == \
        ("circle_crossing", 5, False, 1000.0)
    tuned = TrainConfig(suite="crowdnav-classic", cell="classic-circle5-invisible", max_pedestrians=8,
                        wall_rays=4, rewards=(("collision", -25.0),)).env_config()
    assert tuned.observation == replace(cfg.observation, max_pedestrians=8, wall_rays=4)
    assert tuned.rewards == replace(cfg.rewards, collision=-25.0)
    assert replace(tuned, observation=cfg.observation, rewards=cfg.rewards) == cfg  # nothing else changes
    plain = TrainConfig()  # without a suite: the scenario fields and their defaults, as before
    assert (plain.scenario, plain.pedestrians, plain.invisible, plain.time_limit_s) == \
        ("circle_crossing", 5, True, 40.0)
    assert TrainConfig.from_json(json.loads(json.dumps(CLASSIC.to_json()))) == CLASSIC


def test_no_run_draws_a_suite_episode(monkeypatch):
    """Every seed a run resets with (training envs, evaluation, demonstrations) lies outside every suite's seeds."""
    from envs.rl.train import make_model, make_vec_env

    ranges = [r for _, r in suite_seed_ranges()]
    assert {name.split("/")[0] for name, _ in suite_seed_ranges()} == set(suite_names())
    assert range(0, 500) in ranges and range(1000, 1100) in ranges and range(5000, 5050) in ranges
    for cfg in (TrainConfig(warm_start="dagger"), replace(CLASSIC, warm_start="dagger", seed=3, envs=4)):
        drawn = cfg.seed_ranges()
        assert sum(map(len, drawn.values())) == cfg.envs + cfg.eval_episodes + cfg.demo_episodes \
            + cfg.dagger_rounds * cfg.dagger_episodes
        for seeds in drawn.values():
            assert not any(s in r for s in seeds for r in ranges)
    seen: list[int | None] = []
    real = CrowdNavEnv.reset

    def spy(self, *, seed=None, options=None):
        seen.append(seed)
        return real(self, seed=seed, options=options)

    monkeypatch.setattr(CrowdNavEnv, "reset", spy)
    cfg = replace(CLASSIC, seed=3)
    vec = make_vec_env(cfg)
    try:
        make_model(cfg, vec)  # SB3's PPO(seed=) re-seeds the envs: the offset must survive it
        vec.reset()
    finally:
        vec.close()
    assert seen == [TRAIN_SEED_OFFSET + 3, TRAIN_SEED_OFFSET + 4]


def _spied(env: CrowdNavEnv) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """Record (action, reward, robot velocity) of every env step."""
    calls, real = [], env.step

    def step(action):
        out = real(action)
        calls.append((np.array(action), out[1], env.robot_state[2:4].copy()))
        return out

    env.step = step
    return calls


def test_the_decision_wrapper_holds_the_action_and_sums_the_rewards():
    cfg = TrainConfig(suite="crowdnav-classic").env_config()
    inner = CrowdNavEnv(cfg)
    calls = _spied(inner)
    env = DecisionPeriod(inner, every=5)
    env.reset(seed=TRAIN_SEED_OFFSET)
    for action in (np.array([0.6, 0.0], np.float32), np.array([0.0, -0.8], np.float32)):
        start = len(calls)
        _, reward, terminated, truncated, _ = env.step(action)
        period = calls[start:]
        assert len(period) == 5 and not (terminated or truncated)
        assert all(np.array_equal(a, action) for a, _, _ in period)
        velocity = [v for _, _, v in period]  # a holonomic robot at 1000 m/s^2: the commanded velocity at once
        assert all(np.allclose(v, action * cfg.robot.max_speed_mps) for v in velocity)
        assert reward == pytest.approx(sum(r for _, r, _ in period))
    short = CrowdNavEnv(replace(cfg, time_limit_s=0.35))  # 7 env steps: the second decision ends after 2
    calls = _spied(short)
    env = DecisionPeriod(short, every=5)
    env.reset(seed=TRAIN_SEED_OFFSET)
    assert env.step(np.zeros(2, np.float32))[3] is False and len(calls) == 5
    assert env.step(np.zeros(2, np.float32))[3] is True and len(calls) == 7
    with pytest.raises(ValueError, match="every must be an integer >= 1"):
        DecisionPeriod(short, every=0)


def _agent(tmp_path, cfg: CrowdNavConfig, meta: dict | None) -> str:
    from stable_baselines3 import PPO

    from envs.policies.sb3_files import save_agent
    from envs.rl.extractor import CrowdAttentionExtractor

    path = tmp_path / f"agent{len(list(tmp_path.iterdir()))}.zip"
    save_agent(PPO("MultiInputPolicy", CrowdNavEnv(cfg), n_steps=64, batch_size=32, device="cpu", seed=0,
                   policy_kwargs={"features_extractor_class": CrowdAttentionExtractor}), path, cfg, meta)
    return f"sb3:{path}"


def test_the_harness_runs_a_saved_agent_at_its_decision_period(tmp_path):
    from envs.evaluation.episode import run_episode
    from envs.policies import PolicyConfig, decide, make_policy

    cfg = replace(TrainConfig(suite="crowdnav-classic").env_config(), time_limit_s=1.0)  # 20 env steps
    env = CrowdNavEnv(cfg)
    old = make_policy(PolicyConfig(_agent(tmp_path, cfg, None)), env)
    assert old.decision_every_steps == 1  # an agent saved without the field decides every step
    agent = make_policy(PolicyConfig(_agent(tmp_path, cfg, {"decision_every_steps": 3})), env)
    assert agent.decision_every_steps == 3
    calls, predict, fast = [], agent.model.predict, agent._fast  # count forward passes, whichever path runs
    agent.model.predict = lambda obs, **kw: (calls.append(1), predict(obs, **kw))[1]
    if fast is not None:
        agent._fast = lambda obs: (calls.append(1), fast(obs))[1]
    env.reset(seed=TRAIN_SEED_OFFSET)
    agent.reset(TRAIN_SEED_OFFSET)
    actions = []
    for _ in range(9):
        decision = decide(agent, env)
        actions.append(decision.action)
        env.step_decision(decision)
    assert len(calls) == 3  # steps 0, 3, 6
    for block in (actions[0:3], actions[3:6], actions[6:9]):
        assert all(np.array_equal(a, block[0]) for a in block)
    assert not np.array_equal(actions[0], actions[3]) or not np.array_equal(actions[3], actions[6])
    calls.clear()
    result = run_episode(cfg, "", TRAIN_SEED_OFFSET + 1, env=env, policy=agent)  # the benchmark's episode loop
    assert len(calls) == math.ceil(result.metrics["steps"] / 3)


def test_demonstrations_decide_at_the_decision_period():
    from envs.policies import PolicyConfig, make_policy
    from envs.rl.imitation import _episode

    cfg = replace(TrainConfig(suite="crowdnav-classic").env_config(), time_limit_s=1.2)  # 24 env steps
    env = CrowdNavEnv(cfg)
    calls = _spied(env)
    expert = make_policy(PolicyConfig("mpc-cv", replan_every_steps=5), env)
    obs, labels, returns, _ = _episode(env, expert, TRAIN_SEED_OFFSET, gamma=0.9, every=5)
    n = len(calls)
    assert len(labels) == len(returns) == len(obs["robot"]) == math.ceil(n / 5)
    assert expert.stats.counts["calls"] == len(labels)  # the planner planned at the decision steps only
    for k, label in enumerate(labels):  # the labelled action is the one executed, held for the period
        assert all(np.array_equal(a, label) for a, _, _ in calls[5 * k:5 * k + 5])
    period_rewards = [sum(r for _, r, _ in calls[5 * k:5 * k + 5]) for k in range(len(labels))]
    assert returns[-1] == pytest.approx(period_rewards[-1], abs=1e-5)
    assert returns[-2] == pytest.approx(period_rewards[-2] + 0.9 * period_rewards[-1], abs=1e-5)


@pytest.mark.parametrize("argv, message", [
    (["--suite", "nowhere"], "unknown suite 'nowhere'; valid names: crowdnav-classic"),
    (["--suite", "crowdnav-v1"], "suite crowdnav-v1 has 25 cells; name one with --cell: plaza-low-visible"),
    (["--suite", "crowdnav-classic", "--cell", "bogus"], "unknown cell 'bogus' in suite crowdnav-classic; valid names"),
    (["--suite", "crowdnav-v1", "--cell", "real-eth"], "replays recorded crowds"),
    (["--suite", "crowdnav-classic", "--scenario", "corridor"], "--scenario would be ignored"),
    (["--suite", "crowdnav-classic", "--pedestrians", "5", "--no-invisible"], "--pedestrians, --invisible would be"),
    (["--suite", "crowdnav-classic", "--time-limit-s", "10"], "--time-limit-s would be ignored"),
    (["--cell", "classic-circle5-invisible"], "needs its suite"),
    (["--decision-every-steps", "0"], "decision_every_steps must be an integer >= 1"),
    (["--eval-seed", "0"], "include the reported episodes 0..29 of suite cell crowdnav-classic/"),
    (["--warm-start", "bc", "--demo-seed", "1050"], "crowdnav-classic-tune/tune-classic-circle5-invisible"),
    (["--warm-start", "bc", "--eval-seed", "200010"], "share seeds"),
    (["--seed", "-10000001"], "must lie in 0.."),
])
def test_suite_and_seed_misuse_is_one_line_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "run"
    assert main(["train", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_demonstrations_of_reported_episodes_or_another_period_are_refused(tmp_path, capsys):
    from envs.rl.imitation import Demos

    p = ObservationConfig().max_pedestrians
    obs = {"robot": np.zeros((2, 7), np.float32), "pedestrians": np.zeros((2, p, 5), np.float32),
           "pedestrian_mask": np.zeros((2, p), np.float32), "group_ids": np.zeros((2, p), np.float32)}
    z = np.zeros(2, np.float32)
    for name, demos, message in [
        ("reported.npz", Demos(obs, np.zeros((2, 2), np.float32), z, np.array(["success"]), np.array([7])),
         "seeds [7] are reported by a benchmark suite"),
        ("period.npz", Demos(obs, np.zeros((2, 2), np.float32), z, np.array(["success"]), np.array([300_000])),
         "recorded deciding every 1 env steps, this run every 5"),
    ]:
        demos.save(tmp_path / name)
        argv = ["train", "--warm-start", "bc", "--demos", str(tmp_path / name), "--out", str(tmp_path / "run")]
        if name == "period.npz":
            argv += ["--decision-every-steps", "5"]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
    back = Demos(obs, np.zeros((2, 2), np.float32), z, np.array(["success"]), np.array([300_000]), 5)
    back.save(tmp_path / "five.npz")
    assert Demos.load(tmp_path / "five.npz").decision_every_steps == 5


@pytest.mark.slow
def test_an_agent_trained_in_a_suite_cell_keeps_its_decision_period_in_the_benchmark(tmp_path):
    """DAgger from mpc-cv and PPO in crowdnav-classic at 5 env steps per decision; the saved agent runs the suite's
    episode (the benchmark's task path) deciding every 5 steps."""
    from envs.evaluation.episode import EpisodeTask, run_task
    from envs.policies import PolicyConfig
    from envs.policies.sb3_files import read_agent

    out = tmp_path / "run"
    cfg = replace(CLASSIC, warm_start="dagger")
    assert train(cfg, out) == 0
    walls = [float(r["wall_s"]) for r in csv.DictReader((out / "eval.csv").open())]
    assert walls == sorted(walls)  # the warm start's time counted once (it was twice in the step-0 row)
    _, layout = read_agent(out / "final.zip")
    assert layout["meta"]["decision_every_steps"] == 5 and layout["meta"]["train_config"]["suite"] == "crowdnav-classic"
    assert TrainConfig.from_json(json.loads((out / "config.json").read_text())) == cfg
    from envs.rl.imitation import Demos

    demos = Demos.load(out / "dagger.npz")
    assert demos.decision_every_steps == 5 and min(demos.episode_seed) >= cfg.demo_seed
    _, kept = read_agent(out / "dagger_learner.zip")  # each round's learner is kept with its labels
    assert (kept["meta"]["dagger_round"], kept["meta"]["labels"]) == (1, len(demos.actions))
    assert kept["meta"]["decision_every_steps"] == 5
    cell = load_suite("crowdnav-classic").cell("classic-circle5-invisible")
    record = run_task(EpisodeTask(cell.env_config(0), PolicyConfig(f"sb3:{out / 'final.zip'}"), 0,
                                  cell=cell.name))["record"]
    assert record.outcome != "error" and record.steps >= 1
    from envs.evaluation.episode import _CACHE

    mine = [r.policy for r in _CACHE.values() if r.policy_name == f"sb3:{out / 'final.zip'}"]  # other tests' too
    assert [p.decision_every_steps for p in mine] == [5]


def test_the_demonstrating_mpc_runs_the_suites_planner_settings():
    """In a suite the expert is the MPC that `crowdnav benchmark` runs there (crowdnav-classic: a fixed clearance)."""
    from envs.policies import ENV_MPC
    from envs.rl.train import expert_mpc

    assert expert_mpc(TrainConfig()) is None  # no suite: the env's MPC
    mpc = expert_mpc(TrainConfig(suite="crowdnav-classic"))
    assert mpc == replace(ENV_MPC, clearance_growth_mps=0.0) and ENV_MPC.clearance_growth_mps > 0


@pytest.mark.parametrize("agent, suite, succeed, collide", [
    ("ppo-crowdnav-classic", "crowdnav-classic", 11, 1),  # RESULTS: 500 of 500 in the suite
    ("ppo-crowdnav-20", "crowdnav-plusplus", 10, 2),      # RESULTS: 0.936 / 0.064 in the suite
])
def test_a_packaged_holonomic_agent_reaches_its_goals_in_its_suite_and_only_there(agent, suite, succeed, collide):
    """The agent loads by name in its suite's env, acts every 5 env steps (0.25 s) and reaches the goal in at least
    `succeed` of 12 unseen episodes, colliding in at most `collide` (seeds 400000+: no suite, training, selection or
    demonstration seed). The unicycle env refuses it, naming the robot model."""
    from envs.evaluation.evaluate import evaluate
    from envs.policies import PolicyConfig, make_policy

    cfg = load_suite(suite).cells[0].env_config(0)
    res = evaluate(PolicyConfig(agent), cfg, episodes=12, seed=400_000, record=0, progress=False)
    assert res["success_rate"] >= succeed / 12 and res["collision_rate"] <= collide / 12
    assert make_policy(agent, CrowdNavEnv(cfg)).decision_every_steps == 5
    with pytest.raises(ValueError, match="robot_model 'holonomic' \\(agent\\) vs 'unicycle' \\(env\\)"):
        make_policy(agent, CrowdNavEnv(CrowdNavConfig()))
