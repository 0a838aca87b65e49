"""Crowd simulation throughput: crowdsim against PySocialForce on the same scene, side by side.

Scene: the `plaza` scenario (square with walls and four entrances, groups walking between entrances),
its side scaled so the crowd is at ~0.4 persons/m^2. Both simulators start from crowdsim's initial
state (positions, goals, groups) and the same wall segments. PySocialForce always integrates 0.4 s
steps; crowdsim evaluates forces every 0.1 s with 4 pymunk sub-steps of 0.025 s (a finer step).
Metric: simulated pedestrian-seconds per CPU-second (process time, one thread). Real-time factor =
simulated seconds per CPU-second.

Run: python bench/bench_crowdsim.py [--sizes 50,100,200,400,1000] [--quick]
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import platform
import tempfile
import time

import numpy as np

from crowdsim.config import SimConfig
from crowdsim.sim import CrowdSimulator

DENSITY = 0.4  # persons per m^2 over the plaza


def plaza_config(n: int) -> SimConfig:
    size = max(12.0, float(np.sqrt(n / DENSITY)))
    return SimConfig(scenario="plaza", n_pedestrians=n, scenario_options=(("size_m", size),))


def bench_crowdsim(n: int, sim_seconds: float, repeats: int) -> float:
    """Pedestrian-seconds per CPU-second (best of `repeats`)."""
    config = plaza_config(n)
    sim = CrowdSimulator(config)
    best = 0.0
    steps = int(sim_seconds / config.record_dt_s)
    for rep in range(repeats):
        sim.reset(rep)
        sim.step()  # numba compile / cache load outside the timing
        ped_seconds = 0.0
        t0 = time.process_time()
        for _ in range(steps):
            ped_seconds += sim.slots.active.sum() * config.record_dt_s
            sim.step()
        best = max(best, ped_seconds / (time.process_time() - t0))
    return best


def _import_psf():
    """Import pysocialforce in a temporary folder: it writes ./file.log and turns on DEBUG logging."""
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        try:
            import pysocialforce as psf
        finally:
            os.chdir(cwd)
    logging.getLogger().setLevel(logging.WARNING)
    for name in list(logging.root.manager.loggerDict):
        logging.getLogger(name).setLevel(logging.WARNING)
    return psf


def psf_cpu_seconds(config: SimConfig, seed: int, steps: int) -> float | None:
    """CPU seconds of `steps` PySocialForce steps (0.4 s each) from crowdsim's initial state of (config, seed):
    same positions, goals, groups and wall segments (None if pysocialforce is not installed). One step runs
    first, outside the timing (numba compilation)."""
    try:
        psf = _import_psf()
    except ImportError:
        return None
    sim = CrowdSimulator(config)
    s = sim.reset(seed)
    act = s.active
    state = np.concatenate([s.pos[act], np.zeros((act.sum(), 2)), s.goal[act]], axis=1)
    groups = [list(np.flatnonzero(s.group_id[act] == g)) for g in np.unique(s.group_id[act])]
    obstacles = [[a[0], b[0], a[1], b[1]] for a, b in sim.scenario.walls]
    with tempfile.TemporaryDirectory() as tmp, contextlib.chdir(tmp):
        ref = psf.Simulator(state, groups=groups, obstacles=obstacles)
        ref.step(1)
        t0 = time.process_time()
        ref.step(steps)
        return time.process_time() - t0


def bench_pysocialforce(n: int, steps: int) -> float | None:
    """Pedestrian-seconds per CPU-second of PySocialForce on crowdsim's initial plaza scene."""
    cpu = psf_cpu_seconds(plaza_config(n), 0, steps)
    return None if cpu is None else n * steps * 0.4 / cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="50,100,200,400,1000")
    parser.add_argument("--quick", action="store_true", help="shorter runs (noisier)")
    args = parser.parse_args()
    sizes = [int(x) for x in args.sizes.split(",")]
    sim_seconds, repeats = (8.0, 1) if args.quick else (40.0, 3)
    psf_steps = {50: 40, 100: 25, 200: 12, 400: 6, 1000: 3}
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"python {platform.python_version()}; date {time.strftime('%Y-%m-%d')}")
    print(f"scene: plaza at {DENSITY} persons/m^2, groups and walls; crowdsim {sim_seconds:.0f} simulated s, "
          f"best of {repeats}")
    header = "| N | crowdsim ped-s/CPU-s | real-time factor | PySocialForce ped-s/CPU-s | ratio |"
    print(header)
    print("|---:|---:|---:|---:|---:|")
    for n in sizes:
        ours = bench_crowdsim(n, sim_seconds, repeats)
        ref = bench_pysocialforce(n, psf_steps.get(n, 3) if not args.quick else 2)
        ref_txt = f"{ref:,.0f}" if ref else "n/a"
        ratio = f"{ours / ref:.1f}x" if ref else "n/a"
        print(f"| {n} | {ours:,.0f} | {ours / n:.1f}x | {ref_txt} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
