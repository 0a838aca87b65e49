"""The env in the RL ecosystem: Gymnasium vector envs and stable-baselines3 PPO."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs import CrowdNavConfig

SMALL = CrowdNavConfig(n_pedestrians=10, time_limit_s=6.0)


def make() -> gym.Env:
    return gym.make(envs.ENV_ID, config=SMALL)


@pytest.mark.parametrize("vector", ["sync", "async"])
def test_vector_envs_match_single_envs(vector):
    cls = gym.vector.SyncVectorEnv if vector == "sync" else gym.vector.AsyncVectorEnv
    vec = cls([make, make])
    try:
        obs, _ = vec.reset(seed=[11, 12])
        actions = np.array([[1.0, 0.2], [0.5, -0.3]], np.float32)
        for _ in range(5):
            obs, rew, *_ = vec.step(actions)
        assert obs["robot"].shape == (2, 7) and rew.shape == (2,)
        for k, seed in enumerate((11, 12)):  # each sub-env equals a single env stepped the same way
            env = make()
            single, _ = env.reset(seed=seed)
            for _ in range(5):
                single, r, *_ = env.step(actions[k])
            for key in single:
                np.testing.assert_array_equal(obs[key][k], single[key])
            assert rew[k] == pytest.approx(r)
    finally:
        vec.close()


@pytest.mark.slow
def test_ppo_multi_input_policy_trains():
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = make()
    model = PPO("MultiInputPolicy", env, n_steps=512, batch_size=128, n_epochs=2, seed=0, verbose=0, device="cpu")
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    assert any(not torch.equal(a, b) for a, b in zip(before, model.policy.parameters(), strict=True))
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action.astype(np.float32))
    assert len(model.ep_info_buffer) > 0  # episodes ended and were logged through the Monitor
