"""Generate recordings and whole synthetic datasets (train/val/test folders the predictor reads)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from crowdsim import __version__
from crowdsim.config import SimConfig
from crowdsim.export import TrajectoryLog, write_recording
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
        log.add(shifted, sim.slots.label)
        if recorder is not None:
            recorder.log_frame(shifted, sim.slots.label)
    if recorder is not None:
        recorder.close()
    return log, sim


def metadata(config: SimConfig, spec: RunSpec, sim: CrowdSimulator) -> dict[str, Any]:
    return {
        "generator": f"crowdsim {__version__}",
        "scenario": config.scenario,
        "seed": spec.seed,
        "steps": int(round(spec.duration_s / config.record_dt_s)),
        "duration_s": spec.duration_s,
        "warmup_s": spec.warmup_s,
        "record_dt_s": config.record_dt_s,
        "pedestrians_spawned": sim.n_spawned,
        "config": config.to_dict(),
    }


def generate(config: SimConfig, spec: RunSpec, out_dir: Path, name: str | None = None,
             rrd: bool = False, progress: bool = False) -> dict[str, Path]:
    """Simulate and write one recording (and optionally `<name>.rrd`) into out_dir."""
    name = name or f"{config.scenario}_n{config.n_pedestrians}_s{spec.seed}"
    out_dir = Path(out_dir)
    rrd_path = out_dir / f"{name}.rrd" if rrd else None
    log, sim = simulate(config, spec, rrd_path, progress)
    paths = write_recording(out_dir, name, log, metadata(config, spec, sim))
    if rrd_path is not None:
        paths["rrd"] = rrd_path
    return paths


def split_of(index: int, n: int) -> str:
    """Deterministic split of recording `index` out of n per scenario: ~70/15/15, every split non-empty
    when n >= 3."""
    if n >= 3 and index == n - 1:
        return "test"
    if n >= 3 and index == n - 2:
        return "val"
    return ("train", "train", "train", "train", "val", "test")[index % 6] if n > 6 else "train"


def make_dataset(out_dir: Path, scenarios: list[str], seeds_per_scenario: int, base: SimConfig,
                 spec: RunSpec, progress: bool = True) -> dict[str, list[Path]]:
    """Generate `seeds_per_scenario` recordings per scenario into out_dir/{train,val,test}/.

    Seeds are spec.seed + k; recording k of a scenario goes to `split_of(k, seeds_per_scenario)`.
    """
    out = {s: [] for s in SPLITS}
    jobs = [(scen, k) for scen in scenarios for k in range(seeds_per_scenario)]
    for scen, k in tqdm(jobs, desc="dataset", unit="recording", disable=not progress):
        config = replace(base, scenario=scen)
        run = replace(spec, seed=spec.seed + k)
        split = split_of(k, seeds_per_scenario)
        paths = generate(config, run, Path(out_dir) / split, progress=False)
        out[split].append(paths["trajectories"])
    return out
