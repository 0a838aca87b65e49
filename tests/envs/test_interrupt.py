"""Ctrl-C in `crowdnav benchmark` and `crowdnav evaluate`: one line on stderr saying what was kept, exit 130, no
traceback; a benchmark keeps every finished episode and the same command resumes from there."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

import envs.evaluation.benchmark as benchmark_module
import envs.evaluation.evaluate as evaluate_module
from envs.cli import main
from envs.evaluation.benchmark import RECORDS
from envs.evaluation.episode import run_task
from envs.evaluation.evaluate import CtrlC
from envs.evaluation.records import read_records

ROOT = Path(__file__).resolve().parents[2]
BENCH = ["benchmark", "--suite", "smoke", "--cells", "corridor-low-visible", "--policy", "random", "social-force",
         "--workers", "1", "--no-progress"]


def _after(n: int):
    """A `run_tasks` that runs the first n tasks, then is interrupted as by Ctrl-C."""
    def run_tasks(tasks, *args, **kwargs):
        for i in range(n):
            yield i, run_task(tasks[i])
        raise KeyboardInterrupt
    return run_tasks


def _one_line(capsys) -> str:
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in out + err, err
    return lines[0]


@pytest.mark.parametrize(("where", "raises"), [("/x/site-packages/casadi/casadi.py", False),
                                               ("/x/site-packages/pymunk/space.py", False),
                                               ("/repo/envs/env.py", True), ("/x/site-packages/numpy/core.py", True)])
def test_ctrl_c_is_remembered_not_raised_inside_callbacks_from_c(where, raises):
    """Inside CasADi's solve or a pymunk callback a raised KeyboardInterrupt would be printed and dropped: there the
    press is only remembered (and `check` raises it); elsewhere it raises at once."""
    frame = SimpleNamespace(f_code=SimpleNamespace(co_filename=where.replace("/", os.sep)))
    ctrl = CtrlC()
    if raises:
        with pytest.raises(KeyboardInterrupt):
            ctrl._handle(signal.SIGINT, frame)
    else:
        ctrl._handle(signal.SIGINT, frame)
        with pytest.raises(KeyboardInterrupt):
            ctrl.check()
    assert ctrl.pressed


def test_ctrl_c_in_benchmark_keeps_the_finished_episodes_and_the_rerun_resumes(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(benchmark_module, "run_tasks", _after(1))
    assert main([*BENCH, "--out", str(tmp_path)]) == 130
    assert _one_line(capsys) == (f"crowdnav: interrupted: 1 of 4 episodes saved in {tmp_path / RECORDS}; "
                                 "rerun the same command to resume")
    assert len(read_records(tmp_path / RECORDS)) == 1 and not (tmp_path / "leaderboard.json").exists()
    monkeypatch.undo()
    assert main([*BENCH, "--out", str(tmp_path)]) == 0
    assert "3 episodes run, 1 already recorded" in capsys.readouterr().out
    assert len(read_records(tmp_path / RECORDS)) == 4


def test_ctrl_c_in_benchmark_before_any_episode_says_what_the_records_hold(tmp_path, capsys, monkeypatch):
    def plan(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(benchmark_module, "plan_benchmark", plan)
    assert main([*BENCH, "--out", str(tmp_path)]) == 130
    assert _one_line(capsys) == (f"crowdnav: interrupted: 0 episodes saved in {tmp_path / RECORDS}; "
                                 "rerun the same command to resume")


def test_ctrl_c_in_evaluate_says_what_was_written(tmp_path, capsys, monkeypatch):
    real, calls = evaluate_module.run_tasks, []

    def run_tasks(tasks, *args, **kwargs):  # the first policy runs whole, the second is interrupted
        calls.append(len(tasks))
        yield from (real if len(calls) == 1 else _after(1))(tasks, *args, **kwargs)

    monkeypatch.setattr(evaluate_module, "run_tasks", run_tasks)
    code = main(["evaluate", "--policy", "random", "social-force", "--episodes", "2", "--workers", "1",
                 "--pedestrians", "4", "--time-limit", "2", "--no-progress", "--out", str(tmp_path)])
    assert code == 130
    assert _one_line(capsys) == (f"crowdnav: interrupted: 1 of 2 episodes of social-force done, not saved; results "
                                 f"of random written to {tmp_path}; evaluate does not resume: rerun the command to "
                                 "start again")
    assert (tmp_path / "random.json").is_file() and not (tmp_path / "social-force.json").exists()


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_a_real_sigint_during_a_benchmark(tmp_path, workers):
    """SIGINT while episodes run, as a terminal's Ctrl-C sends it to the whole process group (the parent and, with 2
    workers, the pool's processes): exit 130, one line (no worker prints a stray KeyboardInterrupt), the records
    kept."""
    # two cells x two policies x two episodes, about 1 s each: the run must still be going when the signal comes
    # (with one cell it could finish first on a loaded machine, 2026-11-26)
    args = [sys.executable, "-m", "envs.cli", "benchmark", "--suite", "smoke", "--cells",
            "corridor-low-visible,circle-low-invisible", "--policy", "mpc-cv", "mpc-none", "--workers", str(workers),
            "--no-progress", "--out", str(tmp_path)]
    # SIGINT as a terminal leaves it: a runner started in the background (`cmd &`, nohup) ignores SIGINT, and the
    # child would inherit that and run to the end (exit 0)
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    records = tmp_path / RECORDS
    deadline = time.monotonic() + 120
    while not (records.exists() and records.read_text().count("\n") >= 1):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGINT)  # the process group, as the terminal does
    out, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    saved = len(read_records(records))
    assert proc.returncode == 130, err
    assert "Traceback" not in out + err and len(lines) == 1, err
    assert lines[0] == (f"crowdnav: interrupted: {saved} of 8 episodes saved in {records}; "
                        "rerun the same command to resume") and 1 <= saved < 8
