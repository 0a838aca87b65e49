"""The packaged agents' fast deterministic action (`envs.policies.sb3_actor`) is `model.predict`'s, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from envs import CrowdNavEnv
from envs.evaluation.benchmark import observed
from envs.evaluation.suite import load_suite
from envs.policies import PolicyConfig, make_policy
from envs.policies.identity import agent_wall_rays
from envs.policies.sb3_actor import mean_actor

CASES = [("ppo-crowdnav", None, None), ("ppo-crowdnav-mix", "crowdnav-v1", "corridor-high-visible"),
         ("ppo-crowdnav-classic", "crowdnav-classic", "classic-circle5-invisible")]


@pytest.mark.parametrize(("name", "suite", "cell"), CASES)
def test_mean_actor_equals_predict(name, suite, cell):
    cfg = PolicyConfig(name)
    env_cfg = None if suite is None else observed(load_suite(suite).cell(cell).env_config(0), agent_wall_rays(cfg))
    env = CrowdNavEnv(env_cfg) if env_cfg is not None else CrowdNavEnv()
    policy = make_policy(cfg, env)
    fast = mean_actor(policy.model)
    assert fast is not None and policy._fast is not None
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for step in range(60):  # states along an episode, and random observations off it
        probe = obs if step % 2 == 0 else env.observation_space.sample()
        expected, _ = policy.model.predict(probe, deterministic=True)
        assert np.array_equal(fast(probe), expected)
        obs, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        if term or trunc:
            obs, _ = env.reset(seed=step)


def test_agents_outside_the_fast_path_keep_predict():
    from stable_baselines3 import SAC

    env = CrowdNavEnv()
    assert mean_actor(SAC("MultiInputPolicy", env, buffer_size=10, learning_starts=0)) is None
