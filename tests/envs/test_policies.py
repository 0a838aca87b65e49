"""Planner-in-the-loop policies: they reach the goal, keep clearance, re-plan on the 0.4 s grid."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.evaluation.episode import run_episode
from envs.policies import POLICIES, PolicyConfig, act, make_policy

CFG = CrowdNavConfig(n_pedestrians=16, time_limit_s=30.0)


def test_registry_names():
    assert {"mpc-gpgraph", "mpc-cv", "mpc-none", "social-force"} <= set(POLICIES)


@pytest.mark.parametrize(("name", "crowd"), [("mpc-cv", 16), ("social-force", 2)])
def test_policy_reaches_the_goal_without_collision(name, crowd):
    env = CrowdNavEnv(replace(CFG, n_pedestrians=crowd, groups=replace(CFG.groups, max_size=2)))
    policy = make_policy(name, env)
    for seed in (0, 1):
        res = run_episode(env.config, name, seed, env=env, policy=policy)
        assert res.metrics["outcome"] == "success", (seed, res.metrics)
        assert res.metrics["min_distance_m"] > 0.0
        assert np.linalg.norm(res.robot_xy[-1] - res.goal) < CFG.goal_tolerance_m


@pytest.mark.parametrize("every", [1, 4])
def test_mpc_replans_at_its_interval_and_holds_the_control_in_between(every):
    env = CrowdNavEnv(replace(CFG, time_limit_s=4.0))
    policy = make_policy("mpc-cv", env)
    policy.replan_every_steps = every
    res = run_episode(env.config, "mpc-cv", 3, env=env, policy=policy)
    steps = res.metrics["steps"]
    assert res.metrics["plans"] == -(-steps // every)
    assert len(res.solve_times_ms) == res.metrics["plans"] - res.metrics["fallbacks"]


def test_mpc_gpgraph_uses_the_models_groups_and_samples():
    env = CrowdNavEnv(replace(CFG, time_limit_s=2.0))
    policy = make_policy("mpc-gpgraph", env)
    env.reset(seed=0)
    policy.reset(0)
    act(policy, env)
    frame = env.frame()
    n = frame.n_peds
    assert frame.predictions.shape == (20, 12, n, 2)
    assert frame.predicted_group_id.shape == (n,)
    assert frame.plan.shape == (env_steps := 11, 2) and env_steps == 11
    # samples start near the current positions (first predicted step is 0.4 s ahead)
    step0 = np.linalg.norm(frame.predictions[:, 0] - frame.ped_pos[None], axis=-1)
    assert np.median(step0) < 1.0


def test_same_seed_same_episode_for_the_mpc():
    env = CrowdNavEnv(replace(CFG, time_limit_s=6.0))
    a = run_episode(env.config, "mpc-cv", 4, env=env, policy=make_policy("mpc-cv", env))
    b = run_episode(env.config, "mpc-cv", 4, env=CrowdNavEnv(env.config))
    np.testing.assert_array_equal(a.robot_xy, b.robot_xy)


def _awkward_scene(tmp_path):
    """Nobody for the first 4 s, then one pedestrian seen for a single annotation frame, one walking past the
    route and leaving mid-plan, and one crossing late (0.4 s frames, ETH/UCY format)."""
    from envs.crowds.replay import ReplayConfig

    rows = [(10 * 10, 1, 2.0, 0.6)]  # seen once, at t = 4 s, near the robot's line
    rows += [(10 * t, 2, 1.0 + 0.3 * (t - 12), 1.5) for t in range(12, 22)]  # leaves after 8.4 s
    rows += [(10 * t, 3, 4.0, -4.0 + 0.4 * (t - 15)) for t in range(15, 45)]  # crosses the route later
    rows += [(0, 4, 30.0, 30.0), (10 * 60, 5, -30.0, -30.0)]  # single far-away frames: the recording's extent
    path = tmp_path / "awkward.txt"
    path.write_text("\n".join(f"{f}\t{p}\t{x:.3f}\t{y:.3f}" for f, p, x, y in sorted(rows)) + "\n")
    return ReplayConfig(path=path, start_mode="fixed")


@pytest.mark.parametrize("name", ["mpc-gpgraph", "mpc-cv", "mpc-none", "social-force", "random"])
def test_every_policy_handles_an_empty_scene_a_one_tick_pedestrian_and_one_leaving_mid_plan(name, tmp_path):
    cfg = CrowdNavConfig(scenario="replay", replay=_awkward_scene(tmp_path), time_limit_s=14.0, warmup_s=0.0)
    env = CrowdNavEnv(cfg)
    policy = make_policy(name, env)
    env.reset(seed=0)
    policy.reset(0)
    env.robot_state[:3] = [0.0, 0.0, 0.0]
    env.goal = np.array([8.0, 0.0])
    seen, done, info = set(), False, {}
    while not done:  # never raises; every step's action is valid
        action = act(policy, env)
        assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)
        seen.add(len(env.pedestrians().pos))
        _, _, term, trunc, info = env.step(action)
        done = term or trunc
    assert 0 in seen and 1 in seen  # the empty scene and the lone pedestrians really happened
    assert info["episode_metrics"]["outcome"] in ("success", "collision", "timeout")
    stats = getattr(policy, "stats", None)
    if name.startswith("mpc"):
        assert stats.counts["calls"] == info["episode_metrics"]["steps"]


def test_public_api_and_clashing_names_give_clear_errors():
    import crowdsim
    import envs
    from planner import PLANNERS, make_planner

    assert envs.make_policy is make_policy and "mpc-cv" in envs.POLICIES and envs.PolicyConfig is PolicyConfig
    with pytest.raises(TypeError, match=r"planner\.RobotConfig"):
        envs.CrowdNavConfig(robot=crowdsim.RobotSlot())
    with pytest.raises(ValueError, match="valid names: mpc, mpc-cv, mpc-none, social-force"):
        make_planner("mpc_cv")  # one spelling: the planners' names are the env policies' names
    assert all(name in envs.POLICIES for name in PLANNERS if name != "mpc")


@pytest.mark.parametrize("name", ["mpc-gpgraph", "mpc-cv", "mpc-none", "social-force", "random", "ppo-crowdnav"])
def test_a_policy_decides_from_the_view_alone(name):
    """A policy built for one env, handed the view of another env in another state, decides exactly as a policy
    built for that other env: nothing it returns comes from calling back into the env it was built with."""
    from envs.view import Decision

    cfg = replace(CFG, scenario="circle_crossing", n_pedestrians=5, robot_visible=False)
    built_for, other = CrowdNavEnv(cfg), CrowdNavEnv(cfg)
    built_for.reset(seed=7)
    other.reset(seed=3)
    for _ in range(3):
        other.step(np.array([0.5, 0.1], np.float32))
    stranger, native = make_policy(name, built_for), make_policy(name, other)
    stranger.reset(0)
    native.reset(0)
    view = other.view()
    a, b = stranger.act(view), native.act(other.view())
    assert isinstance(a, Decision) and isinstance(b, Decision)
    for key in ("control", "action", "plan", "predictions", "predicted_group_id"):
        x, y = getattr(a, key), getattr(b, key)
        assert (x is None) == (y is None), key
        if x is not None:
            np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(view.robot_state, other.robot_state)  # the view is what the env holds now


def test_a_decision_holds_exactly_one_of_control_and_action():
    from envs.view import Decision

    with pytest.raises(ValueError, match="exactly one"):
        Decision()
    with pytest.raises(ValueError, match="exactly one"):
        Decision(control=np.zeros(2), action=np.zeros(2))
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        Decision(control=np.zeros(3))
    assert not Decision(action=np.zeros(2)).annotated and Decision(control=np.zeros(2), plan=np.zeros((3, 2))).annotated



def test_learned_agents_skip_the_history_window_and_planners_get_it():
    env = CrowdNavEnv(replace(CFG, scenario="circle_crossing", n_pedestrians=5, robot_visible=False))
    env.reset(seed=0)
    seen = {}
    for name in ("ppo-crowdnav", "random", "mpc-cv"):
        policy = make_policy(name, env)
        real_act = policy.act
        policy.act = lambda view, real_act=real_act, name=name: seen.setdefault(name, view) and real_act(view)
        policy.reset(0)
        act(policy, env)
    assert seen["ppo-crowdnav"].history is None and seen["random"].history is None  # obs-only: not computed
    np.testing.assert_array_equal(seen["mpc-cv"].history, env.history_window())


def test_mpc_gpgraph_groups_by_its_rule_on_the_pedestrians_track():
    """With a rule that reads a track (`+coherent-motion-track`), mpc-gpgraph's groups come from each pedestrian's
    last 19.2 s (`view.track`), not the 8 history rows alone; the default predictor and mpc-cv get no track."""
    from envs.prediction import load_predictor_spec, predict
    from predictor.group_rules import get_rule

    env = CrowdNavEnv(replace(CFG, time_limit_s=20.0))
    env.reset(seed=2)
    gp = make_policy(PolicyConfig("mpc-gpgraph", predictor="gpgraph-stgcnn-synthetic+coherent-motion-track"), env)
    default, cv = make_policy("mpc-gpgraph", env), make_policy("mpc-cv", env)
    assert gp.reads_track and not default.reads_track and not getattr(cv, "reads_track", False)
    seen = {}
    real_act = gp.act
    gp.act = lambda view: seen.__setitem__("view", view) or real_act(view)
    gp.reset(0)
    for _ in range(60):  # tracks longer than the window, shorter than 48 rows
        env.step(act(gp, env))
    view = seen["view"]
    assert view.track.shape == (48, len(view.pedestrians.pos), 2)
    assert view.track[-8:].tobytes() == view.history.tobytes()
    seen_rows = (~np.isnan(view.track[..., 0])).sum(axis=0)  # per pedestrian; NaN only before it was first seen
    assert 8 < seen_rows.max() <= len(env.track_history) < 48  # what was recorded since reset, on the 0.4 s grid
    assert (seen_rows > 8).sum() > len(seen_rows) // 2
    np.testing.assert_array_equal(env.frame().predicted_group_id, get_rule("coherent-motion-track")(view.track))
    with pytest.raises(ValueError, match="reads no track"):
        predict(load_predictor_spec("gpgraph-stgcnn-synthetic"), view.history, 4, np.random.default_rng(0), 12,
                view.track)
