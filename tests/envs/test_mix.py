"""Training a generalist in a mix of suite cells (`envs.rl.mix`): which cell each episode seed plays, that the
mix never replays a reported recording, that every cell plays exactly as the suite's own env, and that the
benchmark shows a wall-ray agent its rays."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from envs import CrowdNavEnv
from envs.evaluation.benchmark import observed, plan_benchmark
from envs.evaluation.suite import load_suite
from envs.policies import PolicyConfig
from envs.rl import mix as mixmod
from envs.rl.mix import MIX_SEED_LOW, MixEnv, build_mix
from envs.rl.train import TrainConfig, main

RAYS = (("wall_rays", 8),)


def test_the_training_mix_plays_every_simulated_cell_and_real_crowds_a_third_of_the_time():
    mix = build_mix("crowdnav-v1-train", RAYS)
    simulated = [c.name for c in load_suite("crowdnav-v1").cells if not c.is_real]
    labels = [label for label, _ in mix.cells]
    assert labels == [f"crowdnav-v1/{n}" for n in simulated] + ["crowdnav-tune/tune-zara03",
                                                                "crowdnav-tune/tune-uni-examples"]
    assert len(mix.cycle) == 30
    for start in (100_000, 100_007, 200_013):  # any run of 30 consecutive seeds plays each cell by its weight
        counts = Counter(mix.cell_of(s)[0] for s in range(start, start + len(mix.cycle)))
        assert all(counts[f"crowdnav-v1/{n}"] == 1 for n in simulated)
        assert counts["crowdnav-tune/tune-zara03"] == counts["crowdnav-tune/tune-uni-examples"] == 5
    assert all(cfg.observation.wall_rays == 8 for _, cfg in mix.cells)


def test_a_mix_refuses_a_reported_recording_and_unknown_names(monkeypatch):
    monkeypatch.setitem(mixmod.MIXES, "leaky", (("crowdnav-tune", "tune-zara03", 1, 1),
                                                ("crowdnav-v1", "real-zara1", 1, 1)))
    build_mix.cache_clear()
    with pytest.raises(ValueError, match=r"real-zara1 replays .*crowds_zara01\.txt, which a benchmark suite reports"):
        build_mix("leaky")
    with pytest.raises(ValueError, match="unknown mix 'nope'; valid: crowdnav-v1-train"):
        build_mix("nope")
    monkeypatch.setitem(mixmod.MIXES, "two-robots", (("crowdnav-v1", "circle-low-invisible", 1, 1),
                                                     ("crowdnav-classic", "*", 1, 1)))
    with pytest.raises(ValueError, match="differ in robot"):
        build_mix("two-robots")
    monkeypatch.setitem(mixmod.MIXES, "dense-sim", (("crowdnav-v1", "circle-low-invisible", 1, 3),))
    with pytest.raises(ValueError, match="overlay 3 needs a replay cell"):
        build_mix("dense-sim")
    build_mix.cache_clear()


def test_each_mix_episode_is_its_cells_own_episode():
    """reset(seed=s) plays cell_of(s) exactly as that cell's env does, step for step; a seedless reset draws
    its episode from the env's own stream, the same after the same seed."""
    mix = build_mix("crowdnav-v1-train", RAYS)
    env = MixEnv(mix)
    for seed in (100_020, 100_021):  # a recorded crowd and a simulated cell
        label, cfg = mix.cell_of(seed)
        obs, info = env.reset(seed=seed)
        assert info["cell"] == label
        ref = CrowdNavEnv(cfg)
        ref_obs, _ = ref.reset(seed=seed)
        for _ in range(5):
            for k in ref_obs:
                np.testing.assert_array_equal(obs[k], ref_obs[k])
            obs, *_ = env.step(np.array([0.5, 0.1], np.float32))
            ref_obs, *_ = ref.step(np.array([0.5, 0.1], np.float32))
    env.reset(seed=7)
    first = [env.reset()[1]["cell"] for _ in range(4)]
    env.reset(seed=7)
    assert [env.reset()[1]["cell"] for _ in range(4)] == first
    assert env.env.config is not None and env._rng.integers(MIX_SEED_LOW, 2**32 - 1) >= MIX_SEED_LOW


def test_demonstrations_in_a_mix_come_from_each_seeds_cell():
    from envs.rl.imitation import collect_demos

    mix = build_mix("crowdnav-v1-train", RAYS)
    seeds = [s for s in range(300_000, 300_030) if mix.cell_of(s)[0] in
             ("crowdnav-tune/tune-zara03", "crowdnav-v1/circle-low-invisible")][:2]
    assert len(seeds) == 2
    demos = [collect_demos(mix, "social-force", 1, s) for s in seeds]
    for s, d in zip(seeds, demos, strict=True):
        first, _ = CrowdNavEnv(mix.config_for(s)).reset(seed=s)
        for k in first:
            np.testing.assert_array_equal(d.obs[k][0], first[k])
        assert list(d.episode_seed) == [s]


def test_the_run_settings_of_a_mix(tmp_path, capsys):
    cfg = TrainConfig(mix="crowdnav-v1-train", wall_rays=8, max_pedestrians=10, rewards=(("collision", -20.0),))
    for s in (0, 7, 29):
        c = cfg.mixture().config_for(s)
        assert c.observation.wall_rays == 8 and c.observation.max_pedestrians == 10 and c.rewards.collision == -20.0
    assert cfg.env_config() == cfg.mixture().cells[0][1] and cfg.env_cell == "crowdnav-v1-train"
    for argv, message in ((["--mix", "crowdnav-v1-train", "--suite", "crowdnav-classic"], "drop --suite"),
                          (["--mix", "crowdnav-v1-train", "--pedestrians", "5"], "--pedestrians would be ignored"),
                          (["--mix", "nope"], "unknown mix 'nope'")):
        assert main([*argv, "--out", str(tmp_path / "run")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "run").exists()


def test_the_benchmark_shows_a_wall_ray_agent_its_rays_and_nobody_else(tmp_path):
    from stable_baselines3 import PPO

    from envs.policies.sb3_files import save_agent
    from envs.rl.extractor import CrowdAttentionExtractor

    suite = load_suite("crowdnav-v1")
    cell = suite.cell("corridor-low-visible")
    cfg = observed(cell.env_config(0), {"wall_rays": 8})
    assert cfg.observation.wall_rays == 8 and observed(cfg, {}) is cfg and observed(cfg, {"wall_rays": 8}) is cfg
    path = tmp_path / "rays.zip"
    save_agent(PPO("MultiInputPolicy", CrowdNavEnv(cfg), n_steps=64, batch_size=32, device="cpu", seed=0,
                   policy_kwargs={"features_extractor_class": CrowdAttentionExtractor}), path, cfg)
    plan = plan_benchmark(suite, [cell], [PolicyConfig(f"sb3:{path}"), PolicyConfig("mpc-cv")], tmp_path / "out")
    rays = {t.policy.name: t.env.observation.wall_rays for t in plan.tasks}
    assert rays == {f"sb3:{path}": 8, "mpc-cv": 0}
    from envs.evaluation.episode import run_task

    task = next(t for t in plan.tasks if t.policy.name.startswith("sb3:"))
    record = run_task(replace(task, seed=0))["record"]
    assert record.outcome != "error" and record.steps >= 1


def test_the_packaged_generalist_sees_its_rays_in_the_benchmark_and_reaches_its_goals():
    """`ppo-crowdnav-mix` (RESULTS: 10 of 10 in plaza-low-visible) runs through the benchmark's own task path with
    the 16 rays it was trained with, and an env without rays refuses it."""
    from envs.evaluation.episode import run_task
    from envs.policies import make_policy
    from envs.policies.identity import agent_observation

    suite = load_suite("crowdnav-v1")
    cell = suite.cell("plaza-low-visible")
    agent = PolicyConfig("ppo-crowdnav-mix")
    assert agent_observation(agent) == {"wall_rays": 16}
    plan = plan_benchmark(suite, [cell], [agent], "/nonexistent-out")
    outcomes = [run_task(t)["record"].outcome for t in plan.tasks]
    assert len(outcomes) == 10 and outcomes.count("success") >= 8, outcomes
    with pytest.raises(ValueError, match="observation"):
        make_policy(agent, CrowdNavEnv(cell.env_config(0)))
