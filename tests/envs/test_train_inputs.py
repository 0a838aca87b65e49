"""A training run records the sha256 of the files it reads by path (inputs.json, and in its agents), and --resume
refuses to go on when one of them changed since the run began."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from envs.rl.config import TrainConfig
from envs.rl.train import main

PLAZA = Path(__file__).resolve().parents[2] / "crowdsim" / "builtin_scenarios" / "plaza.toml"


def _run_dir(tmp_path: Path, cfg: TrainConfig) -> Path:
    """A run folder as `crowdnav train` leaves it after its first checkpoint (the checkpoint's bytes not read here)."""
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "latest.zip").write_bytes(b"")
    (run / "config.json").write_text(json.dumps(cfg.to_json()))
    (run / "inputs.json").write_text(json.dumps(cfg.input_digests()))
    return run


def test_an_edited_scenario_file_stops_the_resume(tmp_path, capsys):
    scenario = tmp_path / "plaza.toml"
    shutil.copy(PLAZA, scenario)
    cfg = TrainConfig(scenario=str(scenario), pedestrians=8)
    digests = cfg.input_digests()
    assert set(digests) == {"scenario_sha256"} and len(digests["scenario_sha256"]) == 64
    assert TrainConfig().input_digests() == {}  # a built-in scenario: nothing read by path
    run = _run_dir(tmp_path, cfg)
    cfg.check_inputs(digests)  # unchanged: no error
    scenario.write_text(scenario.read_text() + "\n# edited\n")
    with pytest.raises(ValueError, match="changed since the run began"):
        cfg.check_inputs(digests)
    assert main(["--resume", str(run)]) == 2
    err = capsys.readouterr().err.strip()
    assert "the scenario file" in err and "changed since the run began" in err and len(err.splitlines()) == 1


def test_the_agent_started_from_is_digested():
    cfg = TrainConfig(suite="crowdnav-plusplus", decision_every_steps=5, init_from="ppo-crowdnav-20")
    assert set(cfg.input_digests()) == {"init_from_sha256"}
    with pytest.raises(ValueError, match="the agent ppo-crowdnav-20 changed"):
        cfg.check_inputs({"init_from_sha256": "0" * 64})
