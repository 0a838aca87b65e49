"""Dataset generation wall time per backend: the Ray overhead per recording against the local backend.

Runs `make_dataset` on the same small dataset (scenarios x seeds, the default group events off) with
- local, 1 process (serial, the default): the reference;
- local, a process pool of `--workers` processes;
- ray cold: a local Ray instance of `--workers` CPUs started by the call (`ray.init` and worker start-up
  counted, as `crowdsim dataset --backend ray` pays it);
- ray warm: the same on an instance already running that has run the dataset once (workers up, modules
  imported): the per-task overhead alone.
Every run writes to a fresh folder and the files of each are checked byte-identical to the reference.
Metric: wall-clock seconds of the whole call (simulation, text formatting, writing), best of `--repeats`
rounds that interleave the backends; ratio = wall / wall of local serial. The numba kernels are compiled
(cached) before the timings. The load average before and after is printed: other jobs skew the timings.

Run: python bench/bench_dataset_backends.py [--scenarios corridor,crossing,plaza,circle_crossing]
     [--seeds 2] [--pedestrians 40] [--duration 300] [--workers 2] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

from crowdsim.config import SimConfig
from crowdsim.generate import RunSpec, make_dataset


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", default="corridor,crossing,plaza,circle_crossing")
    parser.add_argument("--seeds", type=int, default=2, help="seeds per scenario")
    parser.add_argument("--pedestrians", type=int, default=40)
    parser.add_argument("--duration", type=float, default=300.0, help="recorded seconds per recording")
    parser.add_argument("--workers", type=int, default=2, help="pool processes / Ray CPUs")
    parser.add_argument("--repeats", type=int, default=3, help="rounds; each row reports its best wall time")
    args = parser.parse_args()
    scenarios = [s for s in args.scenarios.split(",") if s]
    base = SimConfig(scenario=scenarios[0], n_pedestrians=args.pedestrians)
    spec = RunSpec(duration_s=args.duration, warmup_s=4.0, seed=0)
    n_rec = len(scenarios) * args.seeds

    import ray

    load_before = os.getloadavg()[0]
    walls: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        make_dataset(Path(tmp) / "compile", scenarios, 1, base, RunSpec(duration_s=1.0), progress=False)

        def timed(label: str, **backend) -> None:
            out = Path(tmp) / f"{label.replace(' ', '_').replace(',', '')}_{len(walls.get(label, []))}"
            t0 = time.perf_counter()
            make_dataset(out, scenarios, args.seeds, base, spec, progress=False, **backend)
            walls.setdefault(label, []).append(time.perf_counter() - t0)
            reference = Path(tmp) / "local_serial_0"
            if out != reference:
                assert _tree(out) == _tree(reference), f"{label}: files differ from local serial"

        for _ in range(args.repeats):  # rounds interleave the backends, so that load from elsewhere hits all
            timed("local serial")
            timed(f"local pool, {args.workers} processes", workers=args.workers)
            timed(f"ray cold, {args.workers} CPUs", backend="ray", workers=args.workers)
            ray.init(num_cpus=args.workers, include_dashboard=False)
            try:
                make_dataset(Path(tmp) / "ray_warmup", scenarios, args.seeds, base, spec, progress=False,
                             backend="ray")
                timed(f"ray warm, {args.workers} CPUs", backend="ray")
            finally:
                ray.shutdown()
    rows = [(label, min(w)) for label, w in walls.items()]

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"python {platform.python_version()}; ray {ray.__version__}; date {time.strftime('%Y-%m-%d')}")
    print(f"dataset: {len(scenarios)} scenarios x {args.seeds} seeds = {n_rec} recordings of {args.duration:g} s "
          f"(+4 s warm-up), {args.pedestrians} pedestrians; best of {args.repeats}; files byte-identical in all rows")
    print(f"load average (1 min) before {load_before:.2f}, after {os.getloadavg()[0]:.2f}")
    print("| backend | recordings | wall s | s per recording | ratio to local |")
    print("|---|---:|---:|---:|---:|")
    ref = rows[0][1]
    for label, wall in rows:
        print(f"| {label} | {n_rec} | {wall:.2f} | {wall / n_rec:.3f} | {wall / ref:.2f}x |")


if __name__ == "__main__":
    main()
