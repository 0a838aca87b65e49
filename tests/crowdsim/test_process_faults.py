"""The local process pool survives dead workers (`crowdsim.distributed.run_in_processes`, the local backend of
`crowdsim dataset`): workers really die of SIGKILL here, as under the OOM killer."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import pytest

import crowdsim.generate as generate_module
from crowdsim.cli import main
from crowdsim.config import SimConfig
from crowdsim.distributed import WorkerDied, describe_exit, run_in_processes
from crowdsim.generate import DatasetIncomplete, RunSpec, make_dataset
from tests.crowdsim.fault_tasks import DOOMED_SEED, Job, fail, render_or_die, square_or_die

pytestmark = pytest.mark.xdist_group("crowdsim-parallel")


def _run(jobs: list[Job], workers: int = 2) -> dict[int, object]:
    out: dict[int, object] = {}
    for i, result in run_in_processes(square_or_die, jobs, workers):
        assert i not in out, f"job {i} yielded twice"
        out[i] = result
    return out


def test_unbroken_pool_yields_every_result_once():
    jobs = [Job(v) for v in range(7)]
    assert _run(jobs) == {i: (v, v * v) for i, v in enumerate(range(7))} == _run(jobs, workers=1)


def test_a_job_killed_once_is_rerun_and_the_others_are_untouched(tmp_path):
    jobs = [Job(v, sleep_s=0.2) for v in range(6)]
    jobs[2] = Job(2, kill="once", marker_dir=str(tmp_path))
    out = _run(jobs)
    assert out == {i: (i, i * i) for i in range(6)}  # exactly the results of an unbroken run
    assert (tmp_path / "killed-2").exists()  # it did die once


def test_a_job_killed_every_time_is_reported_and_its_neighbours_are_not_blamed(tmp_path):
    # the neighbours sleep, so they are running when the doomed job's worker dies (collateral of the first break)
    jobs = [Job(v, sleep_s=0.3) for v in range(5)]
    jobs[1] = Job(1, kill="always")
    out = _run(jobs, workers=3)
    assert out.keys() == set(range(5))
    assert isinstance(out[1], WorkerDied)
    assert str(out[1]) == "worker process died (signal 9, SIGKILL) twice while running this task"
    assert {i: r for i, r in out.items() if i != 1} == {i: (i, i * i) for i in (0, 2, 3, 4)}


def test_two_doomed_jobs_and_one_killed_once(tmp_path):
    jobs = [Job(v, sleep_s=0.1) for v in range(6)]
    jobs[0] = Job(0, kill="always")
    jobs[3] = Job(3, kill="once", marker_dir=str(tmp_path))
    jobs[5] = Job(5, kill="always")
    out = _run(jobs)
    assert {i for i, r in out.items() if isinstance(r, WorkerDied)} == {0, 5}
    assert {i: r for i, r in out.items() if i not in (0, 5)} == {i: (i, i * i) for i in (1, 2, 3, 4)}


def test_a_jobs_own_exception_is_raised_as_by_a_plain_pool():
    with pytest.raises(ValueError, match="bad job"):
        list(run_in_processes(fail, [Job(1), Job(2)], 2))


@pytest.mark.parametrize("code, text", [
    (-9, "worker process died (signal 9, SIGKILL)"),
    (-11, "worker process died (signal 11, SIGSEGV)"),
    (3, "worker process died (exit code 3)"),
    (None, "worker process died"),
])
def test_describe_exit(code, text):
    assert describe_exit(code) == text


def test_workers_must_be_positive():
    with pytest.raises(ValueError, match="workers must be >= 1"):
        list(run_in_processes(square_or_die, [Job(1)], 0))


DATASET = ["dataset", "--scenarios", "corridor", "--seeds-per-scenario", "3", "--pedestrians", "6",
           "--duration", "3", "--warmup", "0", "--seed", str(DOOMED_SEED - 1)]  # seeds 12 (train), 13 (val), 14 (test)


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_dataset_reports_a_recording_whose_worker_always_dies_and_writes_the_rest(tmp_path, monkeypatch, capsys):
    assert main([*DATASET, "--out", str(tmp_path / "serial")]) == 0
    capsys.readouterr()
    monkeypatch.setattr(generate_module, "render_job", render_or_die)  # the pool's workers run render_or_die
    assert main([*DATASET, "--workers", "2", "--out", str(tmp_path / "pool")]) == 1
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    assert [ln for ln in err.splitlines() if "error" in ln] == [
        "crowdsim: error: recording val/corridor_n6_s13 not written: "
        "worker process died (signal 9, SIGKILL) twice while running this task"]
    assert "train: 1 recordings" in out and "val: 0 recordings" in out and "test: 1 recordings" in out
    serial, pool = _tree(tmp_path / "serial"), _tree(tmp_path / "pool")
    assert pool == {k: v for k, v in serial.items() if not k.startswith("val/")}  # the rest, byte for byte
    assert len(pool) == 8 and not list((tmp_path / "pool").rglob("*_s13*"))  # nothing partial of the lost one


def test_make_dataset_raises_after_writing_the_rest(tmp_path, monkeypatch):
    monkeypatch.setattr(generate_module, "render_job", render_or_die)
    base = SimConfig(scenario="corridor", n_pedestrians=5)
    with pytest.raises(DatasetIncomplete) as info:
        make_dataset(tmp_path, ["corridor"], 3, base, RunSpec(duration_s=1.0, warmup_s=0.0, seed=DOOMED_SEED - 2),
                     progress=False, workers=2)
    assert info.value.failures == {"test/corridor_n5_s13": "worker process died (signal 9, SIGKILL) twice while "
                                                           "running this task"}
    assert [p.name for ps in info.value.paths.values() for p in ps] == ["corridor_n5_s11.txt", "corridor_n5_s12.txt"]
    assert all(p.exists() for ps in info.value.paths.values() for p in ps)


@pytest.mark.slow
def test_ray_backend_reruns_once_then_reports_worker_died(tmp_path):
    """The Ray backend keeps the same promise: one rerun (Ray's retry), then WorkerDied."""
    pytest.importorskip("ray")
    from crowdsim.distributed import run_on_ray

    jobs = [Job(v, sleep_s=0.1) for v in range(5)]
    jobs[1] = Job(1, kill="always")
    jobs[3] = Job(3, kill="once", marker_dir=str(tmp_path))
    out = dict(run_on_ray(square_or_die, jobs, num_cpus=2))
    assert out.pop(1) == WorkerDied("Ray worker process died twice while running this task")
    assert out == {i: (i, i * i) for i in (0, 2, 3, 4)} and (tmp_path / "killed-3").exists()


def test_a_worker_that_dies_while_the_pool_is_still_being_filled_loses_nothing(monkeypatch):
    """The race in which the first job kills its worker before the later ones are even submitted: submit raises
    BrokenProcessPool for them; they run again like any job that had not started."""
    import time
    from concurrent.futures import ProcessPoolExecutor

    import crowdsim.distributed as distributed

    class SlowToFill(ProcessPoolExecutor):
        raced: ClassVar[list[bool]] = []

        def submit(self, fn, /, *args, **kwargs):
            if args[1] == 2 and not self.raced:  # in the first pool, job 2 waits until job 0 killed its worker
                deadline = time.monotonic() + 30
                while not self._broken and time.monotonic() < deadline:
                    time.sleep(0.01)
                self.raced.append(bool(self._broken))
            return super().submit(fn, *args, **kwargs)

    monkeypatch.setattr(distributed, "ProcessPoolExecutor", SlowToFill)
    jobs = [Job(0, kill="always"), *(Job(v) for v in range(1, 5))]
    out = _run(jobs, workers=2)
    assert SlowToFill.raced == [True]  # the race happened: submit found the pool broken
    assert isinstance(out[0], WorkerDied)
    assert {i: r for i, r in out.items() if i != 0} == {i: (i, i * i) for i in range(1, 5)}
