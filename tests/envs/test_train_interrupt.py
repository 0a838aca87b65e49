"""`crowdnav train` as a user meets it: the best agent is never the untrained step-0 one, and Ctrl-C (SIGINT to the
process group, as a terminal sends it) is one line on stderr, exit 130, and leaves a state that --resume continues."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from envs.rl.monitor import is_new_best, select_best
from tests.cli_helpers import terminal_sigint

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["--pedestrians", "5", "--time-limit-s", "4", "--envs", "2", "--n-steps", "64", "--batch-size", "64",
         "--n-epochs", "1", "--eval-episodes", "1", "--eval-every-steps", "256", "--checkpoint-every-steps", "100000"]


def test_the_step_0_agent_is_the_baseline_never_the_best():
    # the --quick run that kept its untrained agent: 0.60 at step 0, 0.00 after training
    rows = [(0, 0.6, 5.0), (2048, 0.0, -3.0), (4096, 0.0, -2.0)]
    assert select_best(rows) == 2  # the better of the trained ones, though the baseline scored higher
    assert select_best([(0, 0.2, 1.0), (256, 0.4, 0.0), (512, 0.4, 1.5), (768, 0.4, 1.0), (1024, 0.3, 9.0)]) == 2
    assert select_best([(0, 1.0, 9.0)]) is None
    assert not is_new_best(256, 1.0, float("nan"), (-1.0, -float("inf")))  # a NaN return is never kept


def _eval_steps(out: Path) -> list[int]:
    with (out / "eval.csv").open(newline="") as f:
        return [int(r["steps"]) for r in csv.DictReader(f)]


@pytest.mark.slow
def test_ctrl_c_saves_a_state_that_resume_continues_and_best_is_a_trained_agent(tmp_path):
    from envs.policies.sb3_files import read_agent

    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "envs.cli", "train"]
    proc = subprocess.Popen([*cmd, *SMALL, "--steps", "100000", "--out", str(out)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=terminal_sigint)
    seen = []
    deadline = time.monotonic() + 240
    for line in proc.stdout:  # progress lines "   STEPS/100000 steps ..." after each rollout
        seen.append(line)
        if (line.split("/")[0].strip().isdigit() and int(line.split("/")[0]) >= 384) or time.monotonic() > deadline:
            break
    os.killpg(proc.pid, signal.SIGINT)
    rest, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, "".join(seen) + rest + err
    state = json.loads((out / "checkpoints" / "state.json").read_text())
    steps = state["steps"]
    assert steps >= 256 and steps % 128 == 0  # a whole number of rollouts (2 envs x 64 steps); a cut one is dropped
    assert err.splitlines() == [f"crowdnav: interrupted: step {steps} of 100000 saved in "
                                f"{out / 'checkpoints' / 'latest.zip'}; continue with: crowdnav train --resume {out}"]
    assert read_agent(out / "checkpoints" / "latest.zip")[1]["meta"]["steps"] == steps
    assert _eval_steps(out)[:2] == [0, 256]
    best = read_agent(out / "checkpoints" / "best.zip")[1]["meta"]["steps"]
    assert best == 256  # the only trained evaluation; step 0 is never kept
    resumed = subprocess.run([*cmd, "--resume", str(out), "--steps", str(steps + 128)], env=env, capture_output=True,
                             text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stderr
    assert f"resumed {out} at step {steps}" in resumed.stdout
    assert json.loads((out / "checkpoints" / "state.json").read_text())["steps"] == steps + 128
    assert _eval_steps(out)[-1] == steps + 128 and _eval_steps(out).count(0) == 1


def test_ctrl_c_before_the_first_checkpoint_says_there_is_nothing_to_resume(tmp_path):
    from envs.rl.train import TrainConfig, interrupted

    cfg = TrainConfig()
    assert str(interrupted(None, None, cfg, tmp_path)) == (
        f"interrupted before the first checkpoint, nothing to resume in {tmp_path}; rerun the command")
    (tmp_path / "demos.npz").write_bytes(b"")  # the warm start's demonstrations were saved before Ctrl-C
    assert str(interrupted(None, None, cfg, tmp_path)).endswith(f"(add --demos {tmp_path / 'demos.npz'} to reuse the "
                                                                 "demonstrations)")
