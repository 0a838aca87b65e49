"""mpc-oracle: the MPC fed the pedestrians' true future. The env computes that future for it alone (a fork of the
simulation, or the recording read ahead); no other policy can see it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.crowds.crowd import rows_of
from envs.crowds.replay import ReplayConfig
from envs.policies import POLICIES, act, make_policy
from planner import RobotConfig

ACTION = np.array([0.4, 0.1], np.float32)


@pytest.mark.parametrize("scenario, n", [("circle_crossing", 8), ("corridor", 20)])
def test_the_forked_crowd_foresees_what_happens_and_the_crowd_is_left_as_it_was(scenario, n):
    cfg = CrowdNavConfig(scenario=scenario, n_pedestrians=n, robot_visible=False)
    seen, blind = CrowdNavEnv(cfg), CrowdNavEnv(cfg)
    for env in (seen, blind):
        env.reset(seed=3)
        for _ in range(3):
            env.step(ACTION)
    view = seen.view(future=True)
    assert view.future.shape == (12, len(view.pedestrians.pos), 2)
    happened = []
    for k in range(1, 49):  # the crowds themselves, 4.8 s on (the env would stop at a contact with the robot)
        state, other = seen.crowd.step(), blind.crowd.step()
        np.testing.assert_array_equal(state.pos, other.pos)  # forking changed nothing in the crowd
        if k % 4 == 0:
            happened.append(rows_of(state, view.pedestrians.ped_id))
    happened = np.array(happened)
    np.testing.assert_array_equal(np.isnan(view.future), np.isnan(happened))
    np.testing.assert_allclose(view.future, happened, atol=1e-9)  # with an invisible robot: exactly the future


def _recording(tmp_path, name: str, step_into_the_route_after_s: float | None) -> ReplayConfig:
    """Walker 1 crosses the robot's route from y = 3 southwards at x = 5; walker 2 walks far away; walker 3 stands
    in a far corner (so that both copies span the same box: the replay draws the robot's route from it). In the
    altered copy, walker 1 stands on the route at x = 3 from `step_into_the_route_after_s` on."""
    rows = []
    for f in range(80):  # 0.4 s frames, 32 s
        t = 0.4 * f
        x1, y1 = 5.0, 3.0 - 0.25 * t
        if step_into_the_route_after_s is not None and t > step_into_the_route_after_s:
            x1, y1 = 3.0, 0.0
        rows += [(10 * f, 1, x1, y1), (10 * f, 2, -20.0 + 0.3 * t, 20.0), (10 * f, 3, 12.0, -8.0)]
    path = tmp_path / name
    path.write_text("".join(f"{f}\t{p}\t{x:.3f}\t{y:.3f}\n" for f, p, x, y in rows))
    return ReplayConfig(path=path, start_mode="fixed")


def _robot_for(name: str) -> RobotConfig:
    """The robot a registry policy runs: a packaged agent's robot model (its file records it), else the default."""
    from envs.policies.registry import AGENTS_DIR
    from envs.policies.sb3_files import read_agent

    path = AGENTS_DIR / f"{name}.zip"
    model = read_agent(path)[1]["signature"]["robot_model"] if path.is_file() else RobotConfig().model
    return replace(RobotConfig(), model=model)


def _for(name: str, config: CrowdNavConfig) -> CrowdNavConfig:
    """`config` with the robot a registry policy runs and the wall rays a packaged agent was trained with."""
    from envs.evaluation.benchmark import observed
    from envs.policies import PolicyConfig
    from envs.policies.identity import agent_observation

    return observed(replace(config, robot=_robot_for(name)), agent_observation(PolicyConfig(name)))


def _actions(replay: ReplayConfig, name: str, steps: int) -> np.ndarray:
    env = CrowdNavEnv(_for(name, CrowdNavConfig(scenario="replay", replay=replay, warmup_s=0.0, time_limit_s=20.0)))
    policy = make_policy(name, env)
    env.reset(seed=0)
    policy.reset(0)
    env.robot_state[:3] = [0.0, 0.0, 0.0]
    env.goal = np.array([9.0, 0.0])
    out = []
    for _ in range(steps):
        action = act(policy, env)
        out.append(action)
        if any(env.step(action)[2:4]):
            break
    return np.array(out)


def test_only_the_oracle_sees_the_recording_ahead(tmp_path):
    """Rows of the recording after t = 3.2 s changed: every other policy acts identically before t; the oracle,
    which sees 4.8 s ahead, does not."""
    t_change, steps = 3.2, 32  # 32 env steps of 0.1 s: everything before t
    original = _recording(tmp_path, "a.txt", None)
    altered = _recording(tmp_path, "b.txt", t_change)
    for name in POLICIES:
        if name in ("mpc-oracle", "mpc-oracle-paths", "mpc-gpgraph"):
            continue  # mpc-gpgraph: the history path of mpc-oracle-groups, which is checked, without the true groups
        np.testing.assert_array_equal(_actions(original, name, steps), _actions(altered, name, steps), err_msg=name)
    for name in ("mpc-oracle", "mpc-oracle-paths"):
        oracle_a, oracle_b = _actions(original, name, steps), _actions(altered, name, steps)
        assert not np.array_equal(oracle_a[: len(oracle_b)], oracle_b[: len(oracle_a)]), name


def test_the_view_holds_the_future_only_for_a_policy_that_reads_it():
    env = CrowdNavEnv(CrowdNavConfig(scenario="circle_crossing", n_pedestrians=5, robot_visible=False))
    env.reset(seed=0)
    envs = {n: CrowdNavEnv(_for(n, env.config)) for n in POLICIES}
    readers = [n for n in POLICIES if getattr(make_policy(n, envs[n]), "reads_future", False)]
    assert readers == ["mpc-oracle", "mpc-oracle-paths"]
    assert env.view().future is None
    oracle = make_policy("mpc-oracle", env)
    oracle.reset(0)
    decision = oracle.act(env.view(future=True))
    assert decision.predictions.shape == (1, 12, 5, 2)  # one sample: the truth
    assert np.isfinite(decision.predictions).all()
    np.testing.assert_array_equal(decision.predicted_group_id, env.pedestrians().group_id)  # the true groups
    with pytest.raises(ValueError, match="view"):
        oracle.act(replace(env.view(), future=None))


def test_the_halves_take_one_output_each_from_the_truth():
    """mpc-oracle-paths: the true future with mpc-gpgraph's groups; mpc-oracle-groups: mpc-gpgraph's samples (same
    seed, same draws) with the true groups."""
    from envs.policies.registry import oracle_prediction

    env = CrowdNavEnv(CrowdNavConfig(scenario="circle_crossing", n_pedestrians=6, robot_visible=False))
    env.reset(seed=3)
    for _ in range(10):
        env.step(np.zeros(2, np.float32))
    view = env.view(history=True, future=True)
    paths, groups, gpgraph = (make_policy(n, env) for n in ("mpc-oracle-paths", "mpc-oracle-groups", "mpc-gpgraph"))
    for policy in (paths, groups, gpgraph):
        policy.reset(0)
    truth, predicted = oracle_prediction(view), gpgraph._predict(view)
    half_paths, half_groups = paths._predict(view), groups._predict(view)
    np.testing.assert_array_equal(half_paths.positions, truth.positions)
    np.testing.assert_array_equal(half_paths.group_ids, predicted.group_ids)
    np.testing.assert_array_equal(half_groups.positions, predicted.positions)
    np.testing.assert_array_equal(half_groups.group_ids, view.pedestrians.group_id)
    assert len(np.unique(view.pedestrians.group_id)) < len(view.pedestrians.group_id)  # real groups in this crowd


def test_an_oracle_that_plans_farther_than_the_predictor_sees_its_whole_horizon():
    """mpc-oracle with a 12 s horizon (--mpc horizon_steps=30) reads 30 rows of the true future, the first 12 the
    same as the default oracle's (the fork is deterministic); the default horizon (4 s) keeps the predictor's 12."""
    from envs.policies import PolicyConfig
    from envs.policies.registry import ENV_MPC

    env = CrowdNavEnv(CrowdNavConfig(scenario="corridor", n_pedestrians=10, robot_visible=False))
    env.reset(seed=2)
    for _ in range(5):
        env.step(ACTION)
    short = make_policy("mpc-oracle", env)
    far = make_policy(PolicyConfig("mpc-oracle", mpc=replace(ENV_MPC, horizon_steps=30)), env)
    assert short.future_s == pytest.approx(4.0) and far.future_s == pytest.approx(12.0)
    near_view = env.view(future=True, future_s=short.future_s)
    far_view = env.view(future=True, future_s=far.future_s)
    assert near_view.future.shape[0] == 12 and far_view.future.shape[0] == 30
    np.testing.assert_array_equal(far_view.future[:12], near_view.future)
    far.reset(0)
    decision = far.act(far_view)
    assert decision.predictions.shape[1] == 30 and decision.plan.shape == (31, 2)


def test_the_oracles_read_as_far_as_the_foresight_search_looks():
    """With the foresight search (planner/foresight.py) on, mpc-oracle and mpc-oracle-paths read the true future over
    its whole view (10 s), not only the MPC's 4 s horizon; mpc-oracle-groups reads none."""
    from envs.policies import PolicyConfig
    from envs.policies.registry import ENV_MPC, oracle_future_s
    from planner import ForesightConfig

    seeing = replace(ENV_MPC, foresight=ForesightConfig(horizon_s=10.0))
    assert oracle_future_s(ENV_MPC) == pytest.approx(4.0) and oracle_future_s(seeing) == pytest.approx(10.0)
    assert oracle_future_s(replace(seeing, horizon_steps=30)) == pytest.approx(12.0)  # the longer of the two
    env = CrowdNavEnv(CrowdNavConfig(scenario="corridor", n_pedestrians=10, robot_visible=False))
    env.reset(seed=2)
    assert make_policy(PolicyConfig("mpc-oracle", mpc=seeing), env).future_s == pytest.approx(10.0)
    paths = make_policy(PolicyConfig("mpc-oracle-paths", mpc=seeing, predictor="constant-velocity"), env)
    groups = make_policy(PolicyConfig("mpc-oracle-groups", mpc=seeing, predictor="constant-velocity"), env)
    assert paths.future_s == pytest.approx(10.0) and not groups.reads_future
