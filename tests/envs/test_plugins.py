"""Plug-ins: the README's policy example, a predictor plug-in, SB3 agents, and plug-ins that fail."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.cli import main
from envs.evaluation.evaluate import evaluate
from envs.policies import PolicyConfig, act, make_policy

README = Path(__file__).resolve().parents[2] / "README.md"
SMALL = CrowdNavConfig(scenario="corridor", n_pedestrians=6, time_limit_s=4.0)
TINY = ["--episodes", "2", "--workers", "1", "--record", "0", "--no-progress", "--pedestrians", "4",
        "--time-limit", "4", "--scenario", "corridor"]

PREDICTOR_PLUGIN = '''
import numpy as np
from types import SimpleNamespace


class Straight:
    """Constant velocity from the last two rows; pairs of neighbours (ids 2k, 2k+1) are one group."""

    def predict(self, history, n_samples, rng):
        v = history[-1] - history[-2]
        steps = np.arange(1, 13)[:, None, None]
        mean = history[-1][None] + steps * v[None]
        return SimpleNamespace(samples=np.repeat(mean[None], n_samples, axis=0),
                               group_id=np.arange(history.shape[1]) // 2)


def make():
    return Straight()


class Slow(Straight):
    step_s = 0.8


def make_slow():
    return Slow()
'''

FAILING_POLICY = '''
import numpy as np


class Flaky:
    name = "flaky"

    def reset(self, env, seed=None):
        self.seed = seed

    def act(self, obs, env):
        if self.seed == 1 and env.steps == 5:
            raise RuntimeError("flaky policy gave up")
        return np.zeros(2, np.float32)


def make(config, env):
    return Flaky()


def broken(config, env):
    raise ValueError("cannot build")
'''


@pytest.fixture
def plugin_dir(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("my_policies", "pred_plugin", "flaky_plugin"):
        sys.modules.pop(name, None)


def _readme_plugin() -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    found = [b for b in blocks if b.startswith("# my_policies.py")]
    assert len(found) == 1, "the README's policy plug-in example is missing"
    return found[0]


def test_readme_policy_example_runs_as_written(plugin_dir, capsys):
    source = _readme_plugin()
    assert len(source.splitlines()) <= 30
    (plugin_dir / "my_policies.py").write_text(source)
    out = plugin_dir / "out"
    assert main(["evaluate", "--policy", "my_policies:make_cautious", *TINY, "--out", str(out)]) == 0
    saved = json.loads((out / "my_policies_make_cautious.json").read_text())
    assert saved["policy"] == "my_policies:make_cautious" and saved["completed"] == 2 and saved["errors"] == 0
    assert any(e["path_length_m"] > 0.5 for e in saved["episode_list"])  # its actions drive the robot


def test_predictor_plugin_feeds_the_mpc(plugin_dir):
    (plugin_dir / "pred_plugin.py").write_text(PREDICTOR_PLUGIN)
    env = CrowdNavEnv(SMALL)
    policy = make_policy(PolicyConfig("mpc-gpgraph", predictor="pred_plugin:make", n_samples=3), env)
    env.reset(seed=0)
    policy.reset(0)
    act(policy, env)
    frame = env.frame()
    n = frame.n_peds
    assert frame.predictions.shape == (3, 12, n, 2)
    assert np.array_equal(frame.predicted_group_id, np.arange(n) // 2)
    # a predictor on another time step is refused before it can mislead the planner
    with pytest.raises(ValueError, match=r"step_s=0\.8"):
        make_policy(PolicyConfig("mpc-gpgraph", predictor="pred_plugin:make_slow"), env)


def test_a_policy_that_raises_is_recorded_as_an_error_and_the_run_goes_on(plugin_dir):
    (plugin_dir / "flaky_plugin.py").write_text(FAILING_POLICY)
    out = plugin_dir / "out"
    r = evaluate(PolicyConfig("flaky_plugin:make"), SMALL, episodes=3, seed=0, record=0, out_dir=out, progress=False)
    outcomes = [e["outcome"] for e in r["episode_list"]]
    assert outcomes[1] == "error" and outcomes[0] != "error" and outcomes[2] != "error"
    assert r["errors"] == 1 and r["completed"] == 2
    assert "flaky policy gave up" in r["episode_list"][1]["error"]
    trace = list((out / "errors").glob("*seed1.txt"))
    assert len(trace) == 1 and "Traceback" in trace[0].read_text()


def test_a_plugin_that_cannot_be_built_fails_before_any_episode(plugin_dir, capsys):
    (plugin_dir / "flaky_plugin.py").write_text(FAILING_POLICY)
    out = plugin_dir / "never"
    assert main(["evaluate", "--policy", "flaky_plugin:broken", *TINY, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cannot build" in err and len(err.strip().splitlines()) == 1 and not out.exists()
    assert main(["evaluate", "--policy", "flaky_plugin:missing", *TINY, "--out", str(out)]) == 2
    assert "no callable 'missing'" in capsys.readouterr().err


@pytest.mark.slow
def test_sb3_agent_loads_safely_and_acts_like_the_saved_model(tmp_path):
    from stable_baselines3 import PPO

    env = CrowdNavEnv(SMALL)
    model = PPO("MultiInputPolicy", env, n_steps=64, batch_size=32, seed=0, device="cpu",
                policy_kwargs={"net_arch": [16]})
    path = tmp_path / "agent.zip"
    model.save(path)
    policy = make_policy(PolicyConfig(f"sb3:{path}"), env)
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        expected, _ = model.predict(obs, deterministic=True)
        action = act(policy, env)
        assert np.allclose(action, expected, atol=1e-6)
        obs, *_ = env.step(action)
    import torch

    tanh = PPO("MultiInputPolicy", env, n_steps=64, batch_size=32, device="cpu",
               policy_kwargs={"activation_fn": torch.nn.Tanh, "net_arch": [16]})
    tanh.save(tmp_path / "tanh.zip")  # an allow-listed class in policy_kwargs is rebuilt without unpickling
    assert np.allclose(act(make_policy(PolicyConfig(f"sb3:{tmp_path / 'tanh.zip'}"), env), env),
                       tanh.predict(obs, deterministic=True)[0], atol=1e-6)
    custom = PPO("MultiInputPolicy", env, n_steps=64, batch_size=32, device="cpu",
                 policy_kwargs={"activation_fn": torch.nn.Hardswish})
    custom.save(tmp_path / "custom.zip")
    with pytest.raises(ValueError, match=r"unpickling.*allow-list"):
        make_policy(PolicyConfig(f"sb3:{tmp_path / 'custom.zip'}"), env)
    (tmp_path / "junk.zip").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a stable-baselines3 model"):
        make_policy(PolicyConfig(f"sb3:{tmp_path / 'junk.zip'}"), env)


VIEW_POLICY = '''
import numpy as np

from envs.view import Decision


class Ahead:
    name = "ahead"

    def reset(self, seed=None):
        self.seen = []

    def act(self, view):
        self.seen.append(len(view.pedestrians.pos))
        return Decision(control=np.array([0.5, 0.0]))


def make(config, env):
    return Ahead()
'''


def test_a_view_plugin_runs_as_is_and_an_old_protocol_one_through_the_legacy_adapter(plugin_dir):
    from envs.policies import LegacyPolicy

    (plugin_dir / "flaky_plugin.py").write_text(FAILING_POLICY)
    (plugin_dir / "pred_plugin.py").write_text(VIEW_POLICY)
    env = CrowdNavEnv(SMALL)
    new = make_policy(PolicyConfig("pred_plugin:make"), env)
    assert type(new).__name__ == "Ahead"
    env.reset(seed=0)
    new.reset(0)
    action = act(new, env)  # the control (0.5 m/s, 0 rad/s) reaches the env as its action
    np.testing.assert_array_equal(action, env.control_to_action(np.array([0.5, 0.0])))
    assert new.seen == [len(env.pedestrians().pos)]
    with pytest.warns(DeprecationWarning, match=r"old protocol act\(obs, env\)"):
        old = make_policy(PolicyConfig("flaky_plugin:make"), env)
    assert isinstance(old, LegacyPolicy) and old.name == "flaky"
    old.reset(0)
    np.testing.assert_array_equal(act(old, env), np.zeros(2, np.float32))


def test_a_plugin_beside_the_command_loads_without_pythonpath_and_never_shadows_a_package(tmp_path, monkeypatch):
    from envs.factories import load_factory

    (tmp_path / "cwd_plugin.py").write_text(VIEW_POLICY)
    (tmp_path / "json.py").write_text("def dumps(obj):\n    return 'shadowed'\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.delitem(sys.modules, "cwd_plugin", raising=False)
    policy = load_factory("cwd_plugin:make")(None, None)  # the console script's sys.path lacks the current folder
    assert type(policy).__name__ == "Ahead" and sys.path[-1] == str(tmp_path)
    assert load_factory("json:dumps")([1]) == "[1]"  # the standard library's json, not the local file
    with pytest.raises(ValueError, match="cannot import module 'nowhere_plugin'"):
        load_factory("nowhere_plugin:make")


ALWAYS_FAILS = """
from envs.view import Decision


class Broken:
    name = "broken"

    def reset(self, seed=None):
        pass

    def act(self, view):
        raise RuntimeError("this policy always fails")


def make(config, env):
    return Broken()
"""


def test_a_benchmark_with_error_episodes_writes_its_leaderboard_and_exits_1_with_one_line(plugin_dir, capsys):
    (plugin_dir / "flaky_plugin.py").write_text(ALWAYS_FAILS)
    out = plugin_dir / "bench"
    argv = ["benchmark", "--suite", "smoke", "--cells", "circle-low-invisible", "--policy", "flaky_plugin:make",
            "--workers", "1", "--no-progress", "--out", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("crowdnav: 2 episodes ended in an error") and "rerun" in err[0]
    assert (out / "leaderboard.md").is_file() and len(list((out / "errors").glob("*.txt"))) == 2
    assert main(argv) == 1  # rerun: the errors are retried (and fail again), not taken as results
    assert len((out / "records.jsonl").read_text().splitlines()) == 4
