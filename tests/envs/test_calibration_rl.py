"""An agent that reads calibrated predictions: the extractor's rows, the training flags, saving and loading."""

from __future__ import annotations

import json
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch

from envs import CrowdNavConfig, CrowdNavEnv, ObservationConfig
from envs.rl.extractor import CrowdAttentionExtractor
from envs.rl.train import TrainConfig

CALIBRATED = ObservationConfig(predictions=True, prediction_calibration=True, predictor="constant-velocity",
                               n_prediction_samples=2)


def _batch(space: gym.spaces.Dict) -> dict[str, torch.Tensor]:
    space.seed(0)
    obs = {k: torch.as_tensor(np.stack([space[k].sample() for _ in range(3)])) for k in space.spaces}
    obs["pedestrian_mask"] = torch.tensor([[1.0] * 6 + [0.0] * 14, [1.0] * 20, [0.0] * 20])
    obs["group_ids"] = torch.randint(0, 3, (3, 20)).float()
    return obs


def test_the_extractor_reads_each_rows_calibration_as_a_set():
    torch.manual_seed(0)
    space = CrowdNavEnv(CrowdNavConfig(observation=CALIBRATED)).observation_space
    ext = CrowdAttentionExtractor(space, use_predictions=True, use_calibration=True)
    obs = _batch(space)
    out = ext(obs)
    assert out.shape == (3, ext.features_dim) and torch.isfinite(out).all()
    perm = torch.randperm(20)  # the rows reordered, every key the same way: the same features
    shuffled = {k: v[:, perm] for k, v in obs.items() if k not in ("robot", "predictions")}
    shuffled.update(robot=obs["robot"], predictions=obs["predictions"][:, :, :, perm])
    assert torch.allclose(ext(shuffled), out, atol=1e-5)
    junk = {k: v.clone() for k, v in obs.items()}  # padding rows carry no information
    junk["prediction_error"][0, 6:] = 7.0
    junk["prediction_error_count"][0, 6:] = 3.0
    assert torch.allclose(ext(junk), out, atol=1e-6)
    real = {k: v.clone() for k, v in obs.items()}  # a real row's calibration does count
    real["prediction_error"][0, 2] += 2.0
    assert not torch.allclose(ext(real)[0], out[0], atol=1e-4)
    assert torch.allclose(ext(real)[1:], out[1:])
    with pytest.raises(ValueError, match="use_calibration needs prediction_error"):
        CrowdAttentionExtractor(CrowdNavEnv(CrowdNavConfig(observation=ObservationConfig(predictions=True)))
                                .observation_space, use_calibration=True)


def test_the_training_flags_reach_the_observation_and_config_json():
    from crowdsim.cli import OneLineParser
    from envs.rl.train import add_arguments, config_from_args

    parser = OneLineParser()
    add_arguments(parser)
    argv = ["--predictions", "--calibration", "--prediction-source", "oracle", "--calibration-alpha", "0.2"]
    cfg, _, _ = config_from_args(parser.parse_args(argv))
    obs = cfg.env_config().observation
    assert (obs.predictions, obs.prediction_calibration, obs.prediction_source, obs.calibration_alpha) == \
        (True, True, "oracle", 0.2)
    saved = json.loads(json.dumps(cfg.to_json()))
    assert (saved["calibration"], saved["prediction_source"], saved["calibration_alpha"]) == (True, "oracle", 0.2)
    assert TrainConfig.from_json(saved) == cfg
    suite = TrainConfig(suite="crowdnav-v1", cell="plaza-low-visible", predictions=True, calibration=True,
                        predictor="constant-velocity").env_config().observation
    assert (suite.prediction_calibration, suite.predictor) == (True, "constant-velocity")
    with pytest.raises(ValueError, match="needs predictions=True"):
        TrainConfig(calibration=True)
    with pytest.raises(ValueError, match=r"unknown prediction_source 'truth'; valid names: predictor, oracle"):
        TrainConfig(predictions=True, prediction_source="truth")


def test_an_agent_with_calibrated_predictions_saves_loads_and_is_checked_at_evaluation(tmp_path):
    from stable_baselines3 import PPO

    from envs.policies import PolicyConfig, act, make_policy
    from envs.policies.sb3_files import save_agent

    cfg = CrowdNavConfig(scenario="circle_crossing", n_pedestrians=5, time_limit_s=4.0, observation=CALIBRATED)
    kwargs = {"features_extractor_class": CrowdAttentionExtractor, "net_arch": {"pi": [16], "vf": [16]},
              "features_extractor_kwargs": {"use_predictions": True, "use_calibration": True}}
    model = PPO("MultiInputPolicy", CrowdNavEnv(cfg), n_steps=32, batch_size=32, n_epochs=1, seed=0,
                policy_kwargs=kwargs, device="cpu")
    model.learn(32)
    path = tmp_path / "agent.zip"
    save_agent(model, path, cfg)
    env = CrowdNavEnv(cfg)
    agent = make_policy(PolicyConfig(f"sb3:{path}"), env)
    assert agent.model.policy.features_extractor.use_calibration
    assert agent._fast.traced  # the extractor has no branch on the data: `envs.policies.sb3_actor` traces it
    obs, _ = env.reset(seed=3)
    expected, _ = model.predict(obs, deterministic=True)
    np.testing.assert_allclose(act(agent, env), expected, atol=1e-5)
    others = {"key 'prediction_error' only in the agent's observation":
                  replace(CALIBRATED, prediction_calibration=False),
              "calibration_alpha 0.1 \\(agent\\) vs 0.3 \\(env\\)": replace(CALIBRATED, calibration_alpha=0.3),
              "prediction_source 'predictor' \\(agent\\) vs 'oracle' \\(env\\)":
                  replace(CALIBRATED, prediction_source="oracle")}
    for message, observation in others.items():
        with pytest.raises(ValueError, match=message):
            make_policy(PolicyConfig(f"sb3:{path}"), CrowdNavEnv(replace(cfg, observation=observation)))


def test_the_benchmark_observes_what_the_agent_was_trained_to_observe(tmp_path):
    """A benchmark cell observes no predictions; an agent trained on calibrated oracle predictions runs in it with
    them (its saved layout says what), and every other policy's episodes keep the cell's observation."""
    from stable_baselines3 import PPO

    from envs.evaluation.benchmark import plan_benchmark, run_benchmark
    from envs.evaluation.suite import load_suite
    from envs.policies import PolicyConfig
    from envs.policies.identity import agent_observation
    from envs.policies.sb3_files import save_agent

    suite = load_suite("smoke")
    cell = next(c for c in suite.cells if not c.is_real)
    seen = ObservationConfig(predictions=True, prediction_source="oracle", prediction_calibration=True,
                             calibration_alpha=0.2, n_prediction_samples=2)
    cfg = replace(cell.env_config(cell.seeds[0]), observation=seen)
    kwargs = {"features_extractor_class": CrowdAttentionExtractor, "net_arch": {"pi": [16], "vf": [16]},
              "features_extractor_kwargs": {"use_predictions": True, "use_calibration": True}}
    model = PPO("MultiInputPolicy", CrowdNavEnv(cfg), n_steps=32, batch_size=32, n_epochs=1, seed=0,
                policy_kwargs=kwargs, device="cpu")
    path = tmp_path / "agent.zip"
    save_agent(model, path, cfg, {"train_config": {"predictor": "constant-velocity"}})
    agent = PolicyConfig(f"sb3:{path}")
    assert agent_observation(agent) == {"predictions": True, "n_prediction_samples": 2,
                                        "prediction_source": "oracle", "predictor": "constant-velocity",
                                        "prediction_calibration": True, "calibration_alpha": 0.2}
    assert agent_observation(PolicyConfig("mpc-cv")) == {}
    plan = plan_benchmark(suite, [cell], [agent, PolicyConfig("mpc-cv")], tmp_path / "bench")
    by_policy = {t.policy.name: t.env.observation for t in plan.tasks}
    assert by_policy[agent.name].prediction_calibration and by_policy[agent.name].prediction_source == "oracle"
    assert by_policy["mpc-cv"] == cell.env_config(cell.seeds[0]).observation
    board = run_benchmark(suite, [cell], [agent], tmp_path / "bench", progress=False)
    assert board["run"]["episodes_run"] == len(cell.seeds)
    # the leaderboard names what the env predicted for the agent, not "none of these policies runs one"
    assert board["cells"][cell.name]["predictors"] == {agent.name: "oracle"}
    assert f"Predictors: {agent.name}: `oracle` (in the agent's observation)." in \
        (tmp_path / "bench" / "leaderboard.md").read_text()


def test_crowdnav_evaluate_observes_what_the_agent_was_trained_to_observe(tmp_path, capsys):
    from stable_baselines3 import PPO

    from envs.cli import main
    from envs.policies.sb3_files import save_agent

    seen = ObservationConfig(predictions=True, prediction_source="oracle", prediction_calibration=True,
                             n_prediction_samples=1)
    cfg = CrowdNavConfig(scenario="circle_crossing", n_pedestrians=5, time_limit_s=4.0, observation=seen)
    kwargs = {"features_extractor_class": CrowdAttentionExtractor, "net_arch": {"pi": [16], "vf": [16]},
              "features_extractor_kwargs": {"use_predictions": True, "use_calibration": True}}
    model = PPO("MultiInputPolicy", CrowdNavEnv(cfg), n_steps=32, batch_size=32, n_epochs=1, seed=0,
                policy_kwargs=kwargs, device="cpu")
    path = tmp_path / "agent.zip"
    save_agent(model, path, cfg)
    run = ["evaluate", "--policy", f"sb3:{path}", "mpc-cv", "--scenario", "circle_crossing", "--pedestrians", "5",
           "--time-limit", "4", "--episodes", "1", "--workers", "1", "--no-progress"]
    assert main([*run, "--out", str(tmp_path / "eval")]) == 0
    results = [json.loads(f.read_text()) for f in (tmp_path / "eval").glob("*.json") if f.stem != "comparison"]
    assert sorted(r["policy"][:3] for r in results) == ["mpc", "sb3"]  # both ran their episode
    assert all(r["completed"] == 1 and r["errors"] == 0 for r in results)
    capsys.readouterr()
    assert main([*run[:3], "--scenario", "circle_crossing", "--pedestrians", "5", "--wall-rays", "8", "--episodes",
                 "1", "--out", str(tmp_path / "rays")]) == 2  # contradicts the agent: refused, not overridden
    assert "walls" in capsys.readouterr().err
