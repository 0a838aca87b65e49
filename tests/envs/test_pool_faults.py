"""`run_tasks` on the local pool survives workers killed with SIGKILL: the other episodes' records are those of an
unbroken run, an episode killed once is rerun, one killed every time becomes an error record with one stderr line."""

from __future__ import annotations

from dataclasses import replace

import pytest

import envs.evaluation.pool as pool_module
from envs.evaluation.episode import EpisodeTask
from envs.evaluation.pool import run_tasks
from envs.evaluation.suite import load_suite
from envs.policies import PolicyConfig
from tests.envs.pool_fault_tasks import DOOMED_SEED, ONCE_SEED, run_or_die


def _tasks(error_dir: str) -> list[EpisodeTask]:
    cell = load_suite("smoke").cell("corridor-low-visible")
    return [EpisodeTask(replace(cell.env_config(s), time_limit_s=1.0), PolicyConfig("random"), s, cell=cell.name,
                        fingerprint="fp", error_dir=error_dir) for s in range(7)]


def _records(tasks: list[EpisodeTask], workers: int) -> dict[int, object]:
    return {i: replace(r["record"], wall_time_s=0.0) for i, r in run_tasks(tasks, workers)}


@pytest.mark.xdist_group("crowdsim-parallel")
def test_dead_workers_heal_and_a_doomed_episode_becomes_an_error_record(tmp_path, monkeypatch, capsys):
    tasks = _tasks(str(tmp_path / "errors"))
    unbroken = _records(tasks, workers=1)  # this process, real run_task
    monkeypatch.setattr(pool_module, "run_task", run_or_die)  # what the pool's workers run
    broken = _records(tasks, workers=2)
    assert (tmp_path / "errors" / f"killed-{ONCE_SEED}").exists()  # it did die once ...
    assert broken[ONCE_SEED] == unbroken[ONCE_SEED] and broken[ONCE_SEED].outcome != "error"  # ... and was rerun
    assert {i: r for i, r in broken.items() if i != DOOMED_SEED} == {
        i: r for i, r in unbroken.items() if i != DOOMED_SEED}
    doomed = broken[DOOMED_SEED]
    cause = "worker process died (signal 9, SIGKILL) twice while running this task"
    assert (doomed.outcome, doomed.error, doomed.seed, doomed.cell, doomed.policy, doomed.fingerprint) == (
        "error", cause, DOOMED_SEED, "corridor-low-visible", "random", "fp")
    err = capsys.readouterr().err
    assert err.splitlines() == [f"crowdnav: episode corridor-low-visible/random/seed {DOOMED_SEED} recorded as an "
                                f"error: {cause}"]
