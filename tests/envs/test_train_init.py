"""`crowdnav train --init-from AGENT`: a run that starts from a trained agent's policy (e.g. to fine-tune a shipped
agent under a constraint), loaded without unpickling."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from envs.policies import AGENTS_DIR
from envs.policies.sb3_files import load_agent, load_policy_weights
from envs.rl.config import TrainConfig
from envs.rl.train import main, make_model, make_vec_env

AGENT = "ppo-crowdnav-20"  # trained in crowdnav-plusplus, a decision every 5 env steps


def _cfg(**kw) -> TrainConfig:
    return TrainConfig(suite="crowdnav-plusplus", decision_every_steps=5, envs=1, init_from=AGENT, **kw)


@pytest.mark.parametrize("constraint", [(), (("collision", 1.0),)])
def test_the_run_starts_with_the_agents_actions(constraint):
    cfg = _cfg(constraint=constraint, cost_budget=0.02 if constraint else None)
    vec = make_vec_env(cfg)
    try:
        model = make_model(cfg, vec)
        obs = vec.reset()
        before, _ = model.predict(obs, deterministic=True)
        fresh = load_policy_weights(model, cfg.init_path(), cfg.env_config(), cfg.decision_every_steps)
        after, _ = model.predict(obs, deterministic=True)
        agent = load_agent(AGENTS_DIR / f"{AGENT}.zip", "PPO", vec.envs[0].unwrapped)
        want, _ = agent.predict(obs, deterministic=True)
    finally:
        vec.close()
    assert np.array_equal(after, want) and not np.array_equal(before, want)
    assert bool(fresh) == bool(constraint) and all(k.startswith("cost_net.") for k in fresh)


@pytest.mark.parametrize("every, pedestrians, says", [(1, 20, "decides every 5 env steps"),
                                                      (5, 10, "another observation layout")])
def test_another_decision_period_or_layout_is_refused(every, pedestrians, says):
    cfg = TrainConfig(suite="crowdnav-plusplus", decision_every_steps=every, envs=1, max_pedestrians=pedestrians)
    vec = make_vec_env(cfg)
    try:
        with pytest.raises(ValueError, match=says):
            load_policy_weights(make_model(cfg, vec), AGENTS_DIR / f"{AGENT}.zip", cfg.env_config(), every)
    finally:
        vec.close()


def test_a_warm_start_may_refit_the_agent_to_another_period():
    cfg = TrainConfig(suite="crowdnav-plusplus", decision_every_steps=1, envs=1)
    vec = make_vec_env(cfg)
    try:
        model = make_model(cfg, vec)
        load_policy_weights(model, AGENTS_DIR / f"{AGENT}.zip", cfg.env_config(), 1, any_period=True)
        obs = vec.reset()
        got, _ = model.predict(obs, deterministic=True)
        want, _ = load_agent(AGENTS_DIR / f"{AGENT}.zip", "PPO", vec.envs[0].unwrapped).predict(obs, deterministic=True)
    finally:
        vec.close()
    assert np.array_equal(got, want)


@pytest.mark.parametrize("args, says", [
    (["--init-from", "ppo-crowdnav-2"], "did you mean 'ppo-crowdnav-20'"),
    (["--init-from", "nope.zip"], "no such agent file"),
    (["--steps", "0"], "needs a policy to keep"),
    (["--init-from", AGENT, "--demo-mpc", "shield_horizon_s=0.5"], "needs warm_start bc or dagger"),
    (["--init-from", AGENT, "--warm-start", "dagger", "--demo-mpc", "shield_horizn_s=0.5"],
     "did you mean 'shield_horizon_s'"),
    (["--init-from", AGENT, "--warm-start", "dagger", "--demo-mpc", "shield_horizon_s=soon"], "is not a float"),
])
def test_init_from_misuse_is_one_line_and_writes_nothing(args, says, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["--suite", "crowdnav-plusplus", "--decision-every-steps", "5", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1 and not out.exists()


def test_an_agent_grows_prediction_inputs_and_starts_as_itself():
    """`--init-from` an agent trained without predictions into a run that observes them (here constant-velocity
    ones with their calibration): the new inputs enter with zero weight, so the grown policy acts as the agent did
    on the same scene, while its prediction encoders are fresh and the widened layer is named."""
    from envs.policies.sb3_files import GROWABLE_KEYS

    cfg = _cfg(predictions=True, predictor="constant-velocity", calibration=True)
    vec, plain = make_vec_env(cfg), make_vec_env(_cfg())
    try:
        model = make_model(cfg, vec)
        fresh = load_policy_weights(model, cfg.init_path(), cfg.env_config(), cfg.decision_every_steps)
        agent = load_agent(AGENTS_DIR / f"{AGENT}.zip", "PPO", plain.envs[0].unwrapped)
        obs = vec.reset()
        got, want, moved = [], [], []
        for _ in range(30):
            moved.append(np.abs(obs["predictions"]).max())
            got.append(model.predict(obs, deterministic=True)[0])
            want.append(agent.predict({k: v for k, v in obs.items() if k not in GROWABLE_KEYS}, deterministic=True)[0])
            obs, *_ = vec.step(got[-1])
        layer = model.policy.features_extractor.row_enc[0].weight.detach().numpy()
    finally:
        vec.close()
        plain.close()
    assert np.allclose(got, want, atol=1e-6) and max(moved) > 1.0  # the new inputs carried data meanwhile
    assert layer.shape[1] == 13 + 32 + 16 and not layer[:, 13:].any() and layer[:, :13].any()
    assert any(".pred_enc." in k for k in fresh) and any(".calib_enc." in k for k in fresh)
    assert "features_extractor.row_enc.0.weight" in fresh


def test_an_agent_expert_reads_only_its_own_keys_in_a_learners_env_with_predictions():
    """An agent (here the DAgger expert of a run that observes predictions) acts in an env that observes more than it
    was trained on: it reads its own keys only, so it decides as in its own env, step for step."""
    from envs.env import CrowdNavEnv
    from envs.policies import act, make_policy

    plain = _cfg().env_config()
    wide = _cfg(predictions=True, predictor="constant-velocity").env_config()
    runs = []
    for config in (plain, wide):
        env = CrowdNavEnv(config)
        policy = make_policy(AGENT, env)
        env.reset(seed=7)
        policy.reset(7)
        actions = []
        for _ in range(40):
            actions.append(act(policy, env))
            env.step(actions[-1])
        runs.append(np.array(actions))
    assert "predictions" in CrowdNavEnv(wide).observation_space.spaces
    assert np.array_equal(runs[0], runs[1]) and np.abs(runs[0]).max() > 0
