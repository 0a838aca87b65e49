"""CrowdNav-v1: spaces, the step sequence, rewards, termination, determinism and bad input."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs import CrowdNavConfig, CrowdNavEnv, ObservationConfig
from envs.crowds.replay import ReplayConfig
from planner import step_robot

SMALL = CrowdNavConfig(n_pedestrians=12, time_limit_s=8.0)


def write_replay(tmp_path: Path, peds: dict[int, tuple[float, float]], steps: int = 200,
                 groups: list[list[int]] | None = None) -> ReplayConfig:
    """A recording of pedestrians standing still at the given points (ETH/UCY format, 0.4 s frames)."""
    rows = [f"{10 * t}\t{pid}\t{x}\t{y}" for t in range(steps) for pid, (x, y) in peds.items()]
    path = tmp_path / "still.txt"
    path.write_text("\n".join(rows) + "\n")
    gpath = None
    if groups is not None:
        gpath = tmp_path / "still.groups.txt"
        gpath.write_text("\n".join(" ".join(map(str, g)) for g in groups) + "\n")
    return ReplayConfig(path=path, groups_path=gpath, start_mode="fixed")


def place_robot(env: CrowdNavEnv, start: tuple[float, float], goal: tuple[float, float]) -> None:
    """Put the robot at start heading at goal, at rest."""
    env.robot_state = np.zeros(5)
    env.robot_state[:2] = start
    env.robot_state[2] = np.arctan2(goal[1] - start[1], goal[0] - start[0])
    env.goal = np.asarray(goal, float)


def drive_straight(env: CrowdNavEnv, max_steps: int = 200) -> tuple[list[dict], list[float]]:
    infos, rewards = [], []
    for _ in range(max_steps):
        _, r, term, trunc, info = env.step(np.array([1.0, 0.0], np.float32))
        infos.append(info)
        rewards.append(r)
        if term or trunc:
            break
    return infos, rewards


def test_registered_and_makes_the_env():
    assert envs.ENV_ID == "crowdnav/CrowdNav-v1" and envs.ENV_ID in gym.registry
    env = gym.make(envs.ENV_ID, config=SMALL)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert "goal_distance_m" in info
    env.close()


def test_v0_is_gone_and_gymnasium_points_at_v1():
    """v1's info["episode_metrics"] says at_fault where v0 said collision_kind: the old id must not make the new
    env silently."""
    assert "crowdnav/CrowdNav-v0" not in gym.registry
    with pytest.raises(gym.error.DeprecatedEnv, match="CrowdNav-v1"), pytest.warns(DeprecationWarning):
        gym.make("crowdnav/CrowdNav-v0", config=SMALL)


def test_gymnasium_env_checker_passes():
    from gymnasium.utils.env_checker import check_env

    check_env(CrowdNavEnv(SMALL), skip_render_check=True)
    check_env(CrowdNavEnv(replace(SMALL, robot_visible=False)), skip_render_check=True)


def test_sb3_env_checker_passes():
    from stable_baselines3.common.env_checker import check_env

    check_env(CrowdNavEnv(SMALL), warn=True)


def test_observations_stay_in_their_finite_float32_boxes_for_a_whole_episode():
    env = CrowdNavEnv(replace(SMALL, time_limit_s=20.0))
    for box in env.observation_space.spaces.values():
        assert box.dtype == np.float32 and np.all(np.isfinite(box.low)) and np.all(np.isfinite(box.high))
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    done = False
    while not done:
        assert env.observation_space.contains(obs)
        obs, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        done = term or trunc
    m = obs["pedestrian_mask"]
    assert set(np.unique(m)) <= {0.0, 1.0}
    assert np.all(obs["group_ids"][m == 0] == -1) and np.all(obs["pedestrians"][m == 0] == 0)


def test_observed_pedestrians_are_the_nearest_in_the_robot_frame():
    env = CrowdNavEnv(SMALL)
    obs, _ = env.reset(seed=1)
    p = env.pedestrians()
    n = int(obs["pedestrian_mask"].sum())
    rel = obs["pedestrians"][:n, :2]
    dist = np.linalg.norm(rel, axis=1)
    assert np.all(np.diff(dist) >= -1e-5)  # nearest first
    true = np.sort(np.linalg.norm(p.pos - env.robot_state[:2], axis=1))
    np.testing.assert_allclose(dist, true[:n], atol=1e-4)  # a rotation keeps distances
    goal = obs["robot"][:2]  # the robot faces its goal at the start: goal straight ahead
    assert goal[0] > 0 and abs(goal[1]) < 1e-4


def test_same_seed_same_rollout_and_different_seed_differs():
    def rollout(seed: int) -> list[np.ndarray]:
        env = CrowdNavEnv(SMALL)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(42)
        out = [np.concatenate([v.ravel() for v in obs.values()])]
        for _ in range(40):
            obs, r, term, trunc, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            out.append(np.concatenate([*[v.ravel() for v in obs.values()], [r]]))
            if term or trunc:
                break
        return out

    a, b, c = rollout(5), rollout(5), rollout(6)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])


def test_bad_actions_and_names():
    env = CrowdNavEnv(SMALL)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0], np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, np.float32))
    # out of the box: clipped to [-1, 1] (documented), same as the clipped action
    np.testing.assert_array_equal(env.action_to_control(np.array([5.0, -7.0])),
                                  env.action_to_control(np.array([1.0, -1.0])))
    with pytest.raises(ValueError, match=r"valid names: .*plaza"):
        CrowdNavConfig(scenario="mall")
    from envs.policies import make_policy

    with pytest.raises(ValueError, match=r"valid names: .*mpc-gpgraph"):
        make_policy("mpc-magic", env)


def test_action_scaling_round_trips_and_respects_acceleration_limits():
    env = CrowdNavEnv(SMALL)
    env.reset(seed=0)
    r = SMALL.robot
    u = env.action_to_control(np.array([1.0, 1.0]))  # from rest: one step of acceleration at most
    np.testing.assert_allclose(u, [r.max_accel_mps2 * SMALL.dt_s, r.max_yaw_accel_radps2 * SMALL.dt_s])
    np.testing.assert_allclose(env.control_to_action(np.array([r.max_speed_mps, -r.max_yaw_rate_radps])),
                               [1.0, -1.0])
    np.testing.assert_allclose(env.control_to_action(np.array([0.3, 0.5])),
                               [2 * 0.3 / r.max_speed_mps - 1, 0.5 / r.max_yaw_rate_radps], rtol=1e-6)


def test_success_terminates_with_the_success_term(tmp_path):
    env = CrowdNavEnv(scenario="replay", replay=write_replay(tmp_path, {1: (20.0, 20.0), 2: (21.0, 20.0)}))
    env.reset(seed=0)
    place_robot(env, (0.0, 0.0), (3.0, 0.0))
    infos, rewards = drive_straight(env)
    last = infos[-1]
    assert last["is_success"] and last["episode_metrics"]["outcome"] == "success"
    assert last["reward_terms"]["success"] == SMALL.rewards.success
    assert all("is_success" not in i for i in infos[:-1])
    for info, reward in zip(infos, rewards, strict=True):  # the reward is the sum of the named terms
        assert reward == pytest.approx(sum(info["reward_terms"].values()))
    progress = sum(i["reward_terms"]["progress"] for i in infos)
    assert progress == pytest.approx(3.0 - last["goal_distance_m"], abs=1e-9)
    m = last["episode_metrics"]
    assert m["path_length_m"] == pytest.approx(3.0 - last["goal_distance_m"], abs=0.02)
    assert m["time_to_goal_s"] == pytest.approx(len(infos) * SMALL.dt_s)


def test_collision_terminates_along_the_step(tmp_path):
    env = CrowdNavEnv(scenario="replay", replay=write_replay(tmp_path, {1: (3.0, 0.0), 2: (20.0, 20.0)}))
    env.reset(seed=0)
    place_robot(env, (0.0, 0.0), (6.0, 0.0))
    infos, _ = drive_straight(env)
    m = infos[-1]["episode_metrics"]
    assert m["collision"] and not m["success"] and infos[-1]["is_success"] is False
    assert m["collision_with"] == "pedestrian"
    assert m["at_fault"] == "robot"  # the robot drove into a standing person (envs.scoring.collisions)
    assert m["collision_time_s"] == pytest.approx(m["time_s"]) and m["collision_time_s"] > 1.0
    assert infos[-1]["reward_terms"]["collision"] == SMALL.rewards.collision
    # it stopped at first contact: centre distance near robot + pedestrian radius (0.3 + 0.25)
    assert 3.0 - env.robot_state[0] == pytest.approx(0.55, abs=0.13)
    assert m["min_distance_m"] < 0 and m["discomfort_frequency"] > 0


def test_group_intrusion_needs_a_group(tmp_path):
    peds = {1: (3.0, -1.0), 2: (3.0, 1.0), 3: (20.0, 20.0)}
    for groups, expect in (([[1, 2]], True), ([[3]], False), (None, None)):  # None: no labels, not measured
        env = CrowdNavEnv(scenario="replay", replay=write_replay(tmp_path, peds, groups=groups))
        env.reset(seed=0)
        place_robot(env, (0.0, 0.0), (6.0, 0.0))
        infos, _ = drive_straight(env)
        m = infos[-1]["episode_metrics"]
        assert m["success"]  # passes between the two without contact...
        assert m["group_intrusion"] is expect  # ...which intrudes only if they are a group
        assert (sum(i["reward_terms"]["group_intrusion"] for i in infos) < 0) is bool(expect)


def test_time_limit_truncates():
    env = CrowdNavEnv(replace(SMALL, time_limit_s=1.0))
    env.reset(seed=0)
    for k in range(10):
        _, _, term, trunc, info = env.step(np.array([-1.0, 0.0], np.float32))  # stand still
        assert not term and trunc is (k == 9)
    assert info["episode_metrics"]["timeout"] and info["is_success"] is False
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2, np.float32))


def test_invisible_robot_does_not_change_the_crowd():
    def crowd_after(action: float, visible: bool) -> list[np.ndarray]:
        env = CrowdNavEnv(replace(SMALL, robot_visible=visible))
        env.reset(seed=2)
        out = []
        for _ in range(40):
            _, _, term, trunc, _ = env.step(np.array([action, 0.0], np.float32))
            out.append(env.pedestrians().pos)
            if term or trunc:
                break
        return out

    for visible in (False, True):
        fast, still = crowd_after(1.0, visible), crowd_after(-1.0, visible)
        n = min(len(fast), len(still))
        assert n >= 10
        same = all(np.array_equal(a, b) for a, b in zip(fast[:n], still[:n], strict=True))
        assert same is (not visible)


def test_history_is_sampled_every_0_4_s():
    env = CrowdNavEnv(SMALL)
    env.reset(seed=0)
    assert env.is_planning_tick
    hist = env.history_window()
    p = env.pedestrians()
    assert hist.shape == (8, len(p.pos), 2)
    np.testing.assert_array_equal(hist[-1], p.pos)
    for _ in range(4):
        env.step(np.zeros(2, np.float32))
    hist2 = env.history_window()
    common = np.isin(env.pedestrians().ped_id, p.ped_id)
    old = {pid: k for k, pid in enumerate(p.ped_id)}
    rows = [old[pid] for pid in env.pedestrians().ped_id[common]]
    np.testing.assert_array_equal(hist2[-2, common], p.pos[rows])  # shifted by one 0.4 s step


def test_predicted_groups_and_predictions_in_the_observation():
    cfg = replace(SMALL, observation=ObservationConfig(group_source="predicted", predictions=True,
                                                       n_prediction_samples=2, predictor="constant-velocity"))
    env = CrowdNavEnv(cfg)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    n = int(obs["pedestrian_mask"].sum())
    assert obs["predictions"].shape == (2, 12, cfg.observation.max_pedestrians, 2)
    # the constant-velocity predictor puts everyone in their own group
    np.testing.assert_array_equal(obs["group_ids"][:n], np.arange(n))
    assert np.any(obs["predictions"][:, :, :n] != 0) and np.all(obs["predictions"][:, :, n:] == 0)


def test_flatten_observation_is_float32():
    env = gym.wrappers.FlattenObservation(CrowdNavEnv(SMALL))
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.float32 and env.observation_space.dtype == np.float32
    assert env.observation_space.contains(obs)


def test_history_between_ticks_is_interpolated_to_end_now():
    env = CrowdNavEnv(SMALL)
    env.reset(seed=0)
    at_tick = env.history_window()
    ids = env.pedestrians().ped_id
    env.step(np.zeros(2, np.float32))  # 0.1 s later: a quarter of the way to the next snapshot
    p = env.pedestrians()
    keep = np.isin(p.ped_id, ids)
    old = {pid: k for k, pid in enumerate(ids)}
    rows = [old[pid] for pid in p.ped_id[keep]]
    hist = env.history_window()
    np.testing.assert_array_equal(hist[-1], p.pos)
    expect = 0.75 * at_tick[:-1, rows] + 0.25 * at_tick[1:, rows]
    np.testing.assert_allclose(hist[:-1, keep], expect)


def test_history_counts_the_snapshots_a_pedestrian_appears_in():
    from envs.history import PedHistory

    hist = PedHistory(length=3)
    for k in range(5):  # ped 1 in every snapshot, ped 2 only in the last two, ped 3 only in the first (dropped)
        ids = [1, 2] if k >= 3 else ([1, 3] if k == 0 else [1])
        hist.record(np.array(ids), np.zeros((len(ids), 2)))
    assert (hist.times_seen(1), hist.times_seen(2), hist.times_seen(3), hist.times_seen(9)) == (3, 2, 0, 0)


@pytest.mark.parametrize("lookahead_s, expected_start", [(2.0, (0.0, -5.0)), (0.0, (0.0, 0.0))])
def test_route_start_is_not_in_the_path_of_a_walker(tmp_path, lookahead_s, expected_start):
    # pedestrian 1 walks along +x at 1 m/s (0.4 m per 0.4 s frame) and is 2 m short of the first candidate
    # start (0, 0) after the warm-up (1.45 m surface gap): clear now, reached within 2 s; the second candidate
    # (0, -5) stays clear
    path = tmp_path / "walker.txt"
    rows = [f"{10 * t}\t1\t{-2.0 + 0.4 * (t - 8)}\t0.0" for t in range(60)]  # frame 8 = after the warm-up
    rows += [f"{10 * t}\t2\t20.0\t20.0" for t in range(60)]
    path.write_text("\n".join(rows) + "\n")
    env = CrowdNavEnv(CrowdNavConfig(scenario="replay", start_lookahead_s=lookahead_s,
                                     replay=ReplayConfig(path=path, start_mode="fixed")))
    routes = iter([(np.array([0.0, 0.0]), np.array([10.0, 0.0])), (np.array([0.0, -5.0]), np.array([10.0, -5.0]))])
    env.crowd.robot_route = lambda rng: next(routes)
    env.reset(seed=0)
    walker = env.pedestrians().pos[env.pedestrians().ped_id == 1][0]
    assert walker == pytest.approx([-2.0, 0.0])
    np.testing.assert_allclose(env.robot_state[:2], expected_start)


def test_history_of_a_walker_who_just_came_into_view_is_extrapolated_back(tmp_path):
    # pedestrian 3 comes into view at frame 11 (1.2 s into the episode) walking at (1.0, 0.5) m/s; before,
    # the history padded it standing at its first position, so constant velocity and the predictors saw it still
    path = tmp_path / "arrival.txt"
    rows = [f"{10 * t}\t1\t20.0\t20.0" for t in range(40)]
    rows += [f"{10 * t}\t3\t{5.0 + 0.4 * (t - 11)}\t{5.0 + 0.2 * (t - 11)}" for t in range(11, 40)]
    path.write_text("\n".join(rows) + "\n")
    env = CrowdNavEnv(CrowdNavConfig(scenario="replay", replay=ReplayConfig(path=path, start_mode="fixed")))
    env.crowd.robot_route = lambda rng: (np.array([0.0, -5.0]), np.array([10.0, -5.0]))
    env.reset(seed=0)
    vel, step_s = np.array([1.0, 0.5]), env.timing.step_s
    checked = 0
    for _ in range(30):
        p = env.pedestrians()
        if 3 in p.ped_id:
            k = int(np.flatnonzero(p.ped_id == 3)[0])
            hist = env.history_window()[:, k]
            if not env.history.early_velocity(p.ped_id)[k].any():  # the instant it appears: no velocity yet
                np.testing.assert_allclose(hist, np.repeat(p.pos[k][None], len(hist), 0))
            else:  # every row on its straight path, rows before it came into view included
                lags = step_s * np.arange(len(hist) - 1, -1, -1)[:, None]
                np.testing.assert_allclose(hist, p.pos[k] - lags * vel, atol=1e-9)
                checked += 1
            np.testing.assert_array_equal(env.history_window()[:, p.ped_id == 1], 20.0)  # seen throughout
        env.step(np.zeros(2, np.float32))
    assert checked >= 12  # both between ticks and on them


def test_history_notes_each_arrival_and_its_early_velocity():
    from envs.history import EARLY_WINDOW_S, PedHistory, extrapolate_back

    hist = PedHistory(length=3)
    for k in range(8):  # ped 5 arrives at t = 0.2 s walking (2, 0) m/s; at 0.6 s (its window's end) it turns
        t = 0.1 * k
        ids = np.array([1, 5]) if k >= 2 else np.array([1])
        walker = [0.2 * (k - 2), 0.0] if k <= 6 else [0.8, 1.0]
        hist.observe(t, ids, np.array([[0.0, 0.0], walker][: len(ids)]))
        v = hist.early_velocity(np.array([5, 1]))
        np.testing.assert_allclose(v, [[0.0, 0.0] if k <= 2 else [2.0, 0.0], [0.0, 0.0]], atol=1e-12)
    assert EARLY_WINDOW_S == pytest.approx(0.4)
    hist.observe(0.8, np.array([1]), np.zeros((1, 2)))  # ped 5 leaves: forgotten
    assert not hist.early_velocity(np.array([5])).any()
    window = np.zeros((4, 2, 2))
    filled = extrapolate_back(window, np.array([2, 0]), np.array([[1.0, 1.0], [0.0, 0.0]]), np.array([0.1, 0.0]),
                              np.array([[1.0, 0.0], [5.0, 5.0]]), 0.4)
    np.testing.assert_allclose(filled[:, 0], [[0.3, 1.0], [0.7, 1.0], [0.0, 0.0], [0.0, 0.0]])  # rows 0-1 filled
    np.testing.assert_array_equal(filled[:, 1], 0.0)  # first seen in row 0: nothing to fill


def test_a_control_is_applied_as_it_is_and_an_action_through_its_scaling():
    """step_control applies a planner's control clipped to the robot's limits, without the float32 action round
    trip (crowdnav-v1 v6); step(action) and step_decision(Decision(action=...)) are the same step."""
    from envs.view import Decision

    control = np.array([0.123456789, 0.0987654321])  # reachable from rest in one step, not a float32 value
    a, b, c = (CrowdNavEnv(SMALL) for _ in range(3))
    for env in (a, b, c):
        env.reset(seed=0)
        env.robot_state[3:] = 0.0
    a.step_control(control)
    np.testing.assert_allclose(a.robot_state, step_robot(b.robot_state, control, SMALL.dt_s, SMALL.robot.model))
    b.step_decision(Decision(control=control))
    np.testing.assert_array_equal(a.robot_state, b.robot_state)
    c.step(c.control_to_action(control))
    assert not np.array_equal(c.robot_state, a.robot_state)  # the float32 round trip moves it
    np.testing.assert_allclose(c.robot_state, a.robot_state, atol=1e-6)
    with pytest.raises(ValueError, match="finite"):
        a.step_control(np.array([np.nan, 0.0]))


@pytest.mark.parametrize("name", ["plaza", "corridor", "circle_crossing"])
def test_a_builtin_scenarios_file_run_by_its_path_is_that_scenario(name, tmp_path):
    """`--scenario crowdsim/builtin_scenarios/plaza.toml` (or a byte-for-byte copy) is the built-in `plaza`: the
    same robot route and crowd; an edited copy without a [robot] table gets the generic side-to-side route."""
    import shutil

    from crowdsim.scenarios import BUILTIN_DIR, builtin_name

    path = tmp_path / f"{name}.toml"
    shutil.copy(BUILTIN_DIR / f"{name}.toml", path)
    assert builtin_name(str(path)) == name and builtin_name(name) == name
    by_name = CrowdNavEnv(CrowdNavConfig(scenario=name, n_pedestrians=8)).reset(seed=3)[0]
    by_path = CrowdNavEnv(CrowdNavConfig(scenario=str(path), n_pedestrians=8)).reset(seed=3)[0]
    for key in by_name:
        np.testing.assert_array_equal(by_path[key], by_name[key])
    path.write_text(path.read_text() + "\n# edited\n")
    assert builtin_name(str(path)) is None
