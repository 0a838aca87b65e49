"""The packaged agents' fast deterministic action (`envs.policies.sb3_actor`) is `model.predict`'s, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from envs import CrowdNavEnv
from envs.evaluation.benchmark import observed
from envs.evaluation.suite import load_suite
from envs.policies import PolicyConfig, make_policy
from envs.policies.identity import agent_observation
from envs.policies.sb3_actor import mean_actor

CASES = [("ppo-crowdnav", None, None), ("ppo-crowdnav-mix", "crowdnav-v1", "corridor-high-visible"),
         ("ppo-crowdnav-classic", "crowdnav-classic", "classic-circle5-invisible"),
         ("ppo-crowdnav-20-distilled", "crowdnav-plusplus", "plusplus-circle20-invisible")]


@pytest.mark.parametrize(("name", "suite", "cell"), CASES)
def test_mean_actor_equals_predict(name, suite, cell):
    cfg = PolicyConfig(name)
    env_cfg = None if suite is None else observed(load_suite(suite).cell(cell).env_config(0), agent_observation(cfg))
    env = CrowdNavEnv(env_cfg) if env_cfg is not None else CrowdNavEnv()
    policy = make_policy(cfg, env)
    fast = mean_actor(policy.model)
    assert fast is not None and policy._fast is not None
    assert fast.traced  # the TorchScript trace of the forward pass, checked here on an episode
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


def test_an_extractor_not_known_to_be_traceable_keeps_the_eager_pass():
    """A trace records one path through the forward pass: an extractor that branches on the data would be frozen
    into the branch of the probe. Only extractors marked `traceable` (and SB3's own) are traced."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.torch_layers import CombinedExtractor

    class Branchy(CombinedExtractor):
        def forward(self, obs):
            out = super().forward(obs)
            return out * 2.0 if bool((obs["pedestrian_mask"] > 0.5).any()) else out

    env = CrowdNavEnv()
    model = PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, policy_kwargs={"features_extractor_class": Branchy})
    fast = mean_actor(model)
    assert fast is not None and not fast.traced
    obs, _ = env.reset(seed=0)
    assert np.array_equal(fast(obs), model.predict(obs, deterministic=True)[0])
    assert mean_actor(PPO("MultiInputPolicy", env, n_steps=8, batch_size=8)).traced  # SB3's combined extractor
