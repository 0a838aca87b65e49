"""Cloning on turned scenes (`envs.rl.imitation.rotate_scene`): the turn is the env's own symmetry, and it teaches
an agent headings its demonstrations never showed."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from envs import CrowdNavConfig, CrowdNavEnv, ObservationConfig
from envs.observation import build_observation, observation_space
from envs.rl.imitation import Demos, behaviour_clone, check_rotatable, rotate_scene
from planner import RobotConfig

HOLO = CrowdNavConfig(robot=RobotConfig(model="holonomic"), scenario="circle_crossing", n_pedestrians=5,
                      observation=ObservationConfig(max_pedestrians=6, predictions=True, n_prediction_samples=2))


def _scene(rng: np.random.Generator, turn: float) -> dict[str, np.ndarray]:
    """The observation of one random scene, turned by `turn` rad about the robot (world positions turned)."""
    c, s = np.cos(turn), np.sin(turn)
    rot = np.array([[c, -s], [s, c]])
    here = np.array([1.0, -2.0])
    pos, vel = rng.uniform(-4, 4, (5, 2)) + here, rng.uniform(-1, 1, (5, 2))
    goal, robot_v = here + np.array([3.0, 1.5]), np.array([0.4, -0.3])
    samples = pos[None, None] + vel[None, None] * np.arange(1, 13)[None, :, None, None] * 0.4
    samples = np.repeat(samples, 2, axis=0)  # (K, 12, n, 2)

    def turned(p: np.ndarray) -> np.ndarray:
        return (p - here) @ rot.T + here

    state = np.concatenate([here, robot_v @ rot.T])
    return build_observation(HOLO, observation_space(HOLO), state, turned(goal), 0.7, turned(pos), vel @ rot.T,
                             np.full(5, 0.3), np.array([0, 0, 1, -1, 2]), turned(samples))


def test_a_turned_scene_is_observed_as_rotate_scene_says():
    rng = np.random.default_rng(3)
    for turn in (0.3, np.pi / 2, 2.5):
        seed = int(rng.integers(1 << 30))
        plain, turned = _scene(np.random.default_rng(seed), 0.0), _scene(np.random.default_rng(seed), turn)
        batch = {k: torch.as_tensor(v)[None] for k, v in plain.items()}
        action = torch.tensor([[0.6, -0.2]])
        out, act = rotate_scene(batch, action, torch.tensor([turn], dtype=torch.float32))
        for key in plain:
            np.testing.assert_allclose(out[key][0].numpy(), turned[key], atol=1e-5, err_msg=key)
        c, s = np.cos(turn), np.sin(turn)
        np.testing.assert_allclose(act[0].numpy(), [c * 0.6 + s * 0.2, s * 0.6 - c * 0.2], atol=1e-6)


def test_rotate_scene_turns_back_and_keeps_lengths():
    rng = np.random.default_rng(0)
    obs = {"robot": torch.as_tensor(rng.normal(size=(4, 7)), dtype=torch.float32),
           "pedestrians": torch.as_tensor(rng.normal(size=(4, 6, 5)), dtype=torch.float32)}
    actions = torch.as_tensor(rng.uniform(-0.7, 0.7, (4, 2)), dtype=torch.float32)
    theta = torch.as_tensor(rng.uniform(0, 6.3, 4), dtype=torch.float32)
    there, act = rotate_scene(obs, actions, theta)
    back, act_back = rotate_scene(there, act, -theta)
    for key in obs:
        torch.testing.assert_close(back[key], obs[key], atol=1e-5, rtol=0)
    torch.testing.assert_close(act_back, actions, atol=1e-6, rtol=0)
    torch.testing.assert_close(act.norm(dim=1), actions.norm(dim=1), atol=1e-6, rtol=0)
    torch.testing.assert_close(there["pedestrians"][..., 4], obs["pedestrians"][..., 4])  # radius stays


def test_rotations_are_refused_where_they_are_no_symmetry():
    with pytest.raises(ValueError, match="holonomic"):
        check_rotatable(CrowdNavConfig())
    with pytest.raises(ValueError, match="wall rays"):
        check_rotatable(CrowdNavConfig(robot=RobotConfig(model="holonomic"),
                                       observation=ObservationConfig(wall_rays=8)))
    with pytest.raises(ValueError, match="without walls"):
        check_rotatable(CrowdNavConfig(robot=RobotConfig(model="holonomic"), scenario="corridor"))
    check_rotatable(CrowdNavConfig(robot=RobotConfig(model="holonomic"), scenario="circle_crossing"))


@pytest.fixture
def one_thread():
    """One torch thread (two pytest workers share this 2-core machine); restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_cloning_on_turned_scenes_learns_headings_never_demonstrated(one_thread):
    """An expert that walks straight at its goal, demonstrated only with goals to the east: cloned on turned
    scenes, the agent walks north to a goal in the north; cloned plainly, it does not know where to go."""
    from stable_baselines3 import PPO

    from envs.rl.extractor import CrowdAttentionExtractor

    cfg = CrowdNavConfig(robot=RobotConfig(model="holonomic"), scenario="circle_crossing", n_pedestrians=5,
                         observation=ObservationConfig(max_pedestrians=2))
    rng = np.random.default_rng(1)
    n = 512
    robot = np.zeros((n, 7), np.float32)
    bearing = rng.uniform(-0.3, 0.3, n)  # goals roughly east
    dist = rng.uniform(2.0, 8.0, n)
    robot[:, 0], robot[:, 1], robot[:, 2] = dist * np.cos(bearing), dist * np.sin(bearing), dist
    robot[:, 5], robot[:, 6] = 0.3, 0.5
    actions = np.stack([np.cos(bearing), np.sin(bearing)], 1).astype(np.float32)
    obs = {"robot": robot, "pedestrians": np.zeros((n, 2, 5), np.float32),
           "pedestrian_mask": np.zeros((n, 2), np.float32), "group_ids": -np.ones((n, 2), np.float32)}
    demos = Demos(obs, actions, np.zeros(n, np.float32), np.array(["success"]), np.array([0]))
    north = {k: torch.as_tensor(v[:64]).clone() for k, v in obs.items()}
    north["robot"][:, 0], north["robot"][:, 1] = 0.0, north["robot"][:, 2]

    def heading_error(rotations: bool) -> float:
        model = PPO("MultiInputPolicy", CrowdNavEnv(cfg), seed=0, device="cpu",
                    policy_kwargs={"features_extractor_class": CrowdAttentionExtractor})
        behaviour_clone(model, demos, epochs=40, batch_size=64, rotations=rotations, detach_critic=True)
        with torch.no_grad():
            mean = model.policy.get_distribution(north).distribution.mean.clamp(-1, 1)
        return float((mean - torch.tensor([0.0, 1.0])).norm(dim=1).mean())

    assert heading_error(True) < 0.3 < heading_error(False)


@pytest.mark.parametrize("argv, message", [
    (["--bc-rotations"], "--bc-rotations is used only with --warm-start bc or dagger"),
    (["--bc-rotations", "--warm-start", "bc"], "needs the holonomic robot"),
    (["--suite", "crowdnav-plusplus", "--warm-start", "bc", "--bc-rotations", "--wall-rays", "8"], "wall rays"),
])
def test_rotations_misuse_is_one_line_and_writes_nothing(tmp_path, capsys, argv, message):
    from envs.cli import main

    assert main(["train", *argv, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()
