"""Distillation (`crowdnav train --init-from AGENT --warm-start dagger --demo-policy AGENT+shield`): DAgger continues
from a trained agent, its expert may be an agent (deciding at the learner's period) behind the safety shield with its
own settings (`--demo-mpc`), and `--steps 0` keeps the warm start's policy without PPO."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import torch

from envs.env import CrowdNavEnv
from envs.policies import AGENTS_DIR, PolicyConfig, make_policy
from envs.policies.sb3_files import load_agent
from envs.rl.config import TrainConfig
from envs.rl.imitation import decide_every
from envs.rl.train import expert_mpc, main, make_vec_env

AGENT = "ppo-crowdnav-20"  # trained in crowdnav-plusplus, a decision every 5 env steps


def test_an_agent_expert_decides_at_the_learners_period_and_a_planner_is_untouched():
    env = CrowdNavEnv(TrainConfig(suite="crowdnav-plusplus").env_config())
    shielded = make_policy(PolicyConfig(name=f"{AGENT}+shield"), env)
    assert shielded.inner.decision_every_steps == 5  # its recorded period
    assert decide_every(shielded, 1) is shielded and shielded.inner.decision_every_steps == 1
    planner = make_policy(PolicyConfig(name="mpc-cv", replan_every_steps=3), env)
    assert decide_every(planner, 1).replan_every_steps == 3 and not hasattr(planner, "decision_every_steps")


def test_demo_mpc_sets_the_experts_shield_on_top_of_the_suites_settings():
    base = TrainConfig(suite="crowdnav-plusplus", warm_start="dagger")
    cfg = TrainConfig(suite="crowdnav-plusplus", warm_start="dagger", demo_mpc=("shield_horizon_s=0.5",))
    assert expert_mpc(base).shield_horizon_s != 0.5 and expert_mpc(cfg).shield_horizon_s == 0.5
    assert expert_mpc(cfg) == expert_mpc(base).__class__(**{**expert_mpc(base).__dict__, "shield_horizon_s": 0.5})
    assert TrainConfig.from_json(cfg.to_json()) == cfg  # config.json keeps it (a JSON list)


def test_dagger_continues_from_the_agent_and_steps_0_keeps_its_policy(tmp_path):
    """The expert is the agent itself at its own period: the labels are the agent's actions, so cloning from the
    agent moves it a little (the clone is not the agent bit for bit: it was trained), and it stays near the agent,
    where a fresh network is far from it."""
    out = tmp_path / "run"
    assert main(["--suite", "crowdnav-plusplus", "--decision-every-steps", "5", "--init-from", AGENT,
                 "--warm-start", "dagger", "--demo-policy", AGENT, "--demo-episodes", "2", "--bc-epochs", "1",
                 "--dagger-rounds", "1", "--dagger-episodes", "1", "--steps", "0", "--eval-episodes", "2",
                 "--envs", "1", "--out", str(out)]) == 0
    assert (out / "final.zip").is_file() and not (out / "checkpoints" / "best.zip").exists()
    vec = make_vec_env(TrainConfig(suite="crowdnav-plusplus", decision_every_steps=5, envs=1))
    try:
        env = vec.envs[0].unwrapped
        obs = [vec.reset()] + [vec.step(np.zeros((1, 2), np.float32))[0] for _ in range(15)]
        batch = {k: np.concatenate([o[k] for o in obs]) for k in obs[0]}
        agent = load_agent(AGENTS_DIR / f"{AGENT}.zip", "PPO", env).predict(batch, deterministic=True)[0]
        clone = load_agent(out / "final.zip", "PPO", env).predict(batch, deterministic=True)[0]
        fresh = load_agent(out / "final.zip", "PPO", env)
        for p in fresh.policy.parameters():
            p.data.normal_(0.0, 0.1, generator=torch.Generator().manual_seed(0))
        far = fresh.predict(batch, deterministic=True)[0]
    finally:
        vec.close()
    # mean |action difference| over 16 observations (actions in [-1, 1])
    near, away = np.abs(clone - agent).mean(), np.abs(far - agent).mean()
    assert 0.0 < near < 0.1 * away


def test_the_packaged_distilled_agent_decides_every_env_step_and_records_its_recipe():
    from envs.policies.sb3_files import decision_period, read_agent

    _, layout = read_agent(AGENTS_DIR / "ppo-crowdnav-20-distilled.zip")
    recipe = layout["meta"]["train_config"]
    assert decision_period(layout) == 1 and decision_period(read_agent(AGENTS_DIR / f"{AGENT}.zip")[1]) == 5
    keys = ("init_from", "warm_start", "demo_policy", "demo_mpc", "total_steps")
    assert [recipe[k] for k in keys] == [AGENT, "dagger", f"{AGENT}+shield", ["shield_horizon_s=0.5"], 0]
    env = CrowdNavEnv(TrainConfig(suite="crowdnav-plusplus").env_config())
    assert make_policy(PolicyConfig(name="ppo-crowdnav-20-distilled"), env).decision_every_steps == 1
