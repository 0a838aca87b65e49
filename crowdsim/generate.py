"""Generate recordings and whole synthetic datasets (train/val/test folders the predictor reads)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import closing
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from crowdsim import __version__
from crowdsim.config import SimConfig
from crowdsim.distributed import WorkerDied, check_backend, process_context, run_in_processes
from crowdsim.export import (
    RecordingFiles,
    TrajectoryLog,
    check_format,
    recording_files,
    write_files,
    write_recording,
)
from crowdsim.presets import get_preset, sample_config
from crowdsim.scenarios import is_scenario_file, scenario_digest, scenario_label
from crowdsim.sim import CrowdSimulator

SPLITS = ("train", "val", "test")


@dataclass(frozen=True)
class RunSpec:
    """One recording: duration and warm-up (not recorded, lets the crowd leave its spawn pattern), s."""

    duration_s: float = 120.0
    warmup_s: float = 4.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"duration_s must be positive, got {self.duration_s}")
        if not (np.isfinite(self.warmup_s) and self.warmup_s >= 0):
            raise ValueError(f"warmup_s must be non-negative, got {self.warmup_s}")


def simulate(config: SimConfig, spec: RunSpec, rrd_path: Path | None = None,
             progress: bool = False) -> tuple[TrajectoryLog, CrowdSimulator]:
    """Run one recording; returns the trajectory log and the simulator at its end."""
    sim = CrowdSimulator(config)
    sim.reset(spec.seed)
    for _ in range(int(round(spec.warmup_s / config.record_dt_s))):
        sim.step()
    recorder = None
    if rrd_path is not None:
        from crowdsim.recording import RrdRecorder

        recorder = RrdRecorder(rrd_path, sim.scenario.walls)
    log = TrajectoryLog()
    steps = int(round(spec.duration_s / config.record_dt_s))
    start = sim.frame
    state = sim.state()
    for k in tqdm(range(steps + 1), desc=f"{config.scenario} seed {spec.seed}", unit="step",
                  disable=not progress, leave=False):
        if k:
            state = sim.step()
        shifted = replace(state, frame=state.frame - start, time_s=(state.frame - start) * config.record_dt_s)
        log.add(shifted)
        if recorder is not None:
            recorder.log_frame(shifted)
    if recorder is not None:
        recorder.close()
    return log, sim


def metadata(config: SimConfig, spec: RunSpec, sim: CrowdSimulator,
             preset: str | None = None) -> dict[str, Any]:
    """The JSON metadata of a recording; `preset` ("name@version") when its config was drawn from a preset. A scenario
    file's recording also holds the file's sha256 (`scenario_sha256`) and its name (`scenario_name`)."""
    from_file = {"scenario_name": sim.scenario.name, "scenario_sha256": scenario_digest(config.scenario)} \
        if is_scenario_file(config.scenario) else {}
    return {
        "generator": f"crowdsim {__version__}",
        "preset": preset,
        "scenario": config.scenario,
        **from_file,
        "seed": spec.seed,
        "steps": int(round(spec.duration_s / config.record_dt_s)),
        "duration_s": spec.duration_s,
        "warmup_s": spec.warmup_s,
        "record_dt_s": config.record_dt_s,
        "pedestrians_spawned": sim.n_spawned,
        "config": config.to_dict(),
    }


def default_name(config: SimConfig, spec: RunSpec) -> str:
    """File stem of a recording: `<scenario>_n<pedestrians>_s<seed>` (a scenario file: its file name's stem)."""
    return f"{scenario_label(config.scenario)}_n{config.n_pedestrians}_s{spec.seed}"


def generate(config: SimConfig, spec: RunSpec, out_dir: Path, name: str | None = None,
             rrd: bool = False, progress: bool = False, fmt: str = "ethucy") -> dict[str, Path]:
    """Simulate and write one recording in format `fmt` (`crowdsim.export.FORMATS`), and optionally `<name>.rrd`
    (written as the simulation runs and removed if it does not finish), into out_dir."""
    check_format(fmt)
    name = name or default_name(config, spec)
    out_dir = Path(out_dir)
    rrd_path = out_dir / f"{name}.rrd" if rrd else None
    try:
        log, sim = simulate(config, spec, rrd_path, progress)
    except BaseException:  # Ctrl-C or an error mid-simulation: no partial rerun recording is left behind
        if rrd_path is not None:
            rrd_path.unlink(missing_ok=True)
        raise
    paths = write_recording(out_dir, name, log, metadata(config, spec, sim), fmt)
    if rrd_path is not None:
        paths["rrd"] = rrd_path
    return paths


@dataclass(frozen=True)
class RecordingJob:
    """One recording of a dataset: what to simulate, and where its files go (split folder, file stem)."""

    config: SimConfig
    spec: RunSpec
    split: str
    name: str
    preset: str | None = None  # "name@version" of the preset the config was drawn from
    fmt: str = "ethucy"  # file format (`crowdsim.export.FORMATS`)


def render_job(job: RecordingJob) -> RecordingFiles:
    """Simulate one dataset recording and return its files as texts (written by the caller): the unit of
    work of every backend, so that they all produce the same bytes."""
    log, sim = simulate(job.config, job.spec)
    return recording_files(job.name, log, metadata(job.config, job.spec, sim, job.preset), job.fmt)


def split_of(index: int, n: int) -> str:
    """Deterministic split of recording `index` out of n per scenario: ~70/15/15, every split non-empty
    when n >= 3."""
    if n >= 3 and index == n - 1:
        return "test"
    if n >= 3 and index == n - 2:
        return "val"
    return ("train", "train", "train", "train", "val", "test")[index % 6] if n > 6 else "train"


def dataset_jobs(scenarios: list[str], seeds_per_scenario: int, base: SimConfig, spec: RunSpec,
                 preset: str | None = None, fmt: str = "ethucy") -> list[RecordingJob]:
    """The recordings of a dataset, scenario-major: seed spec.seed + k of each scenario goes to
    `split_of(k, seeds_per_scenario)`. With a preset name, each recording's config is drawn from the preset
    (`crowdsim.presets.sample_config`, from the scenario and the recording's seed) instead of `base`."""
    chosen = get_preset(preset) if preset is not None else None
    jobs = []
    for scen in scenarios:
        for k in range(seeds_per_scenario):
            run = replace(spec, seed=spec.seed + k)
            config = sample_config(chosen, scen, run.seed) if chosen else replace(base, scenario=scen)
            tag = f"{chosen.name}@{chosen.version}" if chosen else None
            jobs.append(RecordingJob(config, run, split_of(k, seeds_per_scenario), default_name(config, run), tag,
                                     fmt))
    return jobs


def run_local(jobs: list[RecordingJob], workers: int = 1) -> Iterator[tuple[int, RecordingFiles | WorkerDied]]:
    """Render `jobs`, yielding (index in jobs, files) as they finish: in this process if workers <= 1, else in a
    pool of `workers` processes (`crowdsim.distributed.run_in_processes`: a dead worker's recordings run again;
    one whose worker died twice comes back as `WorkerDied`)."""
    if workers <= 1 or len(jobs) <= 1:
        for i, job in enumerate(jobs):
            yield i, render_job(job)
        return
    yield from run_in_processes(render_job, jobs, min(workers, len(jobs)), process_context(["crowdsim.generate"]))


class DatasetIncomplete(RuntimeError):
    """Raised by `make_dataset` at the end, after every other recording was written: some recordings could not
    be made (nothing of theirs is on disk). failures: "split/name" -> cause; paths: what `make_dataset` would
    have returned, without them."""

    def __init__(self, failures: dict[str, str], paths: dict[str, list[Path]]) -> None:
        super().__init__(f"{len(failures)} recording(s) failed: " + "; ".join(f"{k}: {v}" for k, v in failures.items()))
        self.failures = failures
        self.paths = paths


class DatasetInterrupted(KeyboardInterrupt):
    """Ctrl-C during `make_dataset`: `written` of the `total` recordings are on disk, each complete (written
    atomically as it arrived); the others are absent, none partial."""

    def __init__(self, written: int, total: int) -> None:
        super().__init__(f"{written} of {total} recordings written")
        self.written = written
        self.total = total


def make_dataset(out_dir: Path, scenarios: list[str], seeds_per_scenario: int, base: SimConfig,
                 spec: RunSpec, progress: bool = True, backend: str = "local", workers: int | None = None,
                 address: str | None = None, preset: str | None = None,
                 fmt: str = "ethucy") -> dict[str, list[Path]]:
    """Generate `seeds_per_scenario` recordings per scenario into out_dir/{train,val,test}/.

    Seeds are spec.seed + k; recording k of a scenario goes to `split_of(k, seeds_per_scenario)`.
    Every recording is simulated independently (its own seed), and this process writes each one's files
    atomically as it arrives, so the files are byte-identical whatever the backend and worker count.

    Args:
        backend: "local" (this machine) or "ray" (one Ray task per recording; needs the `ray` extra).
        workers: local: processes (None or 1: in this process, serially; more starts a forkserver pool, so
            a calling script needs the `if __name__ == "__main__":` guard). Ray: CPUs of the local Ray
            instance it starts (None: all cores); must be None with `address`.
        address: Ray only: None starts a local Ray instance; "auto" or "HOST:PORT" connects to a running
            cluster, whose nodes need crowdsim installed. An already initialised Ray is used as it is.
        preset: a `crowdsim.presets.PRESETS` name: each recording's config is drawn from it (base is unused);
            its metadata records "name@version".
        fmt: file format of every recording, "ethucy" or "trajnet" (`crowdsim.export.FORMATS`).

    Returns the trajectory file paths of each split, in job order (scenario-major, then seed). A recording whose
    worker process died twice (local pool) is not written; the others are, then DatasetIncomplete names it.
    Ctrl-C raises DatasetInterrupted (a KeyboardInterrupt) saying how many recordings were written.
    """
    check_backend(backend)
    check_format(fmt)
    if address is not None and backend != "ray":
        raise ValueError("address needs backend='ray'")
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if workers is not None and address is not None:
        raise ValueError("workers sizes a local Ray instance; with an address the cluster's CPUs decide")
    jobs = dataset_jobs(scenarios, seeds_per_scenario, base, spec, preset, fmt)
    if backend == "ray":
        from crowdsim.distributed import run_on_ray

        results = run_on_ray(render_job, jobs, address=address, num_cpus=workers)
    else:
        results = run_local(jobs, workers or 1)
    paths: dict[int, Path] = {}
    failures: dict[str, str] = {}
    try:
        with closing(results), tqdm(total=len(jobs), desc="dataset", unit="recording", disable=not progress) as bar:
            for i, files in results:
                if isinstance(files, WorkerDied):
                    failures[f"{jobs[i].split}/{jobs[i].name}"] = str(files)
                else:
                    paths[i] = write_files(Path(out_dir) / jobs[i].split, files)["trajectories"]
                bar.update(1)
    except KeyboardInterrupt:
        raise DatasetInterrupted(len(paths), len(jobs)) from None
    out: dict[str, list[Path]] = {s: [] for s in SPLITS}
    for i, job in enumerate(jobs):
        if i in paths:
            out[job.split].append(paths[i])
    if failures:
        raise DatasetIncomplete(failures, out)
    return out
