"""`crowdsim generate` end to end against PySocialForce on the same scene, side by side in one run.

Command measured (issue 11 item 6); the config and spec are the ones crowdsim's own CLI parser builds:

    crowdsim generate --scenario corridor --option length_m=80 --option width_m=10 --pedestrians 400
        --duration 120 --out DIR

crowdsim, three measurements of the same recording (seed 0):
1. `generate(config, spec, out_dir, progress=True)` as the CLI calls it, tqdm's output sent to /dev/null:
   simulator construction, reset, 4 s of warm-up, 120 recorded seconds (301 frames) and writing the four
   files (trajectories, groups, labels, json). This is the headline number.
2. The same call split into its stages: simulate (the stepping loop with the trajectory log and the
   progress bar), build table (ordering the logged rows), format text (the four texts), write (atomic
   writes to disk).
3. The whole console script `crowdsim.cli.main(argv)`: adds argument parsing and the one-line summary
   printed afterwards (which re-reads the trajectory file).
Start-up is excluded: imports and numba compilation (or cache load) are paid by a short warm-up call
first. Process start is not measured.

PySocialForce (1.1.x): started from crowdsim's initial state of that recording (same positions, goals,
groups and wall segments; velocities zero) and integrated 300 of its fixed 0.4 s steps = 120 simulated
seconds. It keeps every pedestrian (no exits, no inflow) and writes nothing; its first step (numba
compilation) is excluded.

Metric: CPU time of this process (`time.process_time`, one thread); best of `--repeats` for crowdsim,
one run for PySocialForce. Ratio = PySocialForce CPU s / crowdsim CPU s, both for 120 simulated seconds.

Run: python bench/bench_generate.py [--pedestrians 400] [--repeats 3] [--quick]
  --quick: one crowdsim run of each kind and 10 PySocialForce steps scaled to 300 (about 10 s, noisier).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import tempfile
import time
from pathlib import Path

from crowdsim import cli
from crowdsim.config import SimConfig
from crowdsim.export import table_files, write_files
from crowdsim.generate import RunSpec, default_name, generate, metadata, simulate

DURATION_S = 120.0
PSF_DT_S = 0.4  # PySocialForce's fixed step


def cli_command(n: int, seed: int, out: str = "DIR", duration_s: float = DURATION_S) -> list[str]:
    return ["generate", "--scenario", "corridor", "--option", "length_m=80", "--option", "width_m=10",
            "--pedestrians", str(n), "--duration", f"{duration_s:g}", "--seed", str(seed), "--out", out]


def config_and_spec(n: int, seed: int) -> tuple[SimConfig, RunSpec]:
    """The SimConfig and RunSpec `crowdsim generate` builds from the command above."""
    args = cli.build_parser().parse_args(cli_command(n, seed))
    return cli._config(args, args.scenario), cli._spec(args)


@contextlib.contextmanager
def quiet_output():
    """Send the progress bar (tqdm writes to sys.stderr) and the CLI's summary line to /dev/null."""
    with open(os.devnull, "w") as sink, contextlib.redirect_stderr(sink), contextlib.redirect_stdout(sink):
        yield


# ----------------------------------------------------------------------------------------------- crowdsim
def time_generate(config: SimConfig, spec: RunSpec, repeats: int) -> list[float]:
    """CPU seconds of each of `repeats` end-to-end generate() calls (after one short warm-up call)."""
    times = []
    with tempfile.TemporaryDirectory() as tmp, quiet_output():
        generate(config, RunSpec(duration_s=2.0, seed=spec.seed + 1), Path(tmp) / "warmup", progress=True)
        for _ in range(repeats):
            t0 = time.process_time()
            generate(config, spec, Path(tmp), progress=True)
            times.append(time.process_time() - t0)
    return times


def time_stages(config: SimConfig, spec: RunSpec) -> dict[str, float]:
    """CPU seconds of the stages of one generate() call, done one after the other as generate does them."""
    pt = time.process_time
    with tempfile.TemporaryDirectory() as tmp, quiet_output():
        t0 = pt()
        log, sim = simulate(config, spec, progress=True)
        t1 = pt()
        table = log.table()
        t2 = pt()
        files = table_files(default_name(config, spec), table, metadata(config, spec, sim))
        t3 = pt()
        write_files(Path(tmp), files)
        t4 = pt()
    return {"simulate": t1 - t0, "build table": t2 - t1, "format text": t3 - t2, "write": t4 - t3}


def time_cli(n: int, seed: int, repeats: int) -> list[float]:
    """CPU seconds of each of `repeats` calls of the console script's `main(argv)` (after a short one)."""
    times = []
    with tempfile.TemporaryDirectory() as tmp, quiet_output():
        cli.main(cli_command(n, seed + 1, f"{tmp}/warmup", duration_s=2.0))
        for _ in range(repeats):
            t0 = time.process_time()
            status = cli.main(cli_command(n, seed, tmp))
            times.append(time.process_time() - t0)
            assert status == 0
    return times


# ------------------------------------------------------------------------------------------ PySocialForce


def time_pysocialforce(config: SimConfig, seed: int, steps: int) -> float | None:
    """CPU seconds of `steps` PySocialForce steps from crowdsim's initial state of the recording (None if
    pysocialforce is not installed); the same harness as bench_crowdsim.py."""
    from bench_crowdsim import psf_cpu_seconds  # the sibling script (this folder is on sys.path when run)

    return psf_cpu_seconds(config, seed, steps)


# ------------------------------------------------------------------------------------------------- report
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pedestrians", type=int, default=400)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3, help="crowdsim runs of each kind; the best counts")
    parser.add_argument("--quick", action="store_true", help="1 crowdsim run each, 10 PySocialForce steps")
    args = parser.parse_args()
    repeats = 1 if args.quick else args.repeats
    psf_steps = 10 if args.quick else int(round(DURATION_S / PSF_DT_S))
    config, spec = config_and_spec(args.pedestrians, args.seed)

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"python {platform.python_version()}; date {time.strftime('%Y-%m-%d')}; "
          f"load average {os.getloadavg()[0]:.1f}")
    print("command: crowdsim " + " ".join(cli_command(args.pedestrians, args.seed)))

    runs = time_generate(config, spec, repeats)
    stages = time_stages(config, spec)
    cli_runs = time_cli(args.pedestrians, args.seed, repeats)
    psf_cpu = time_pysocialforce(config, args.seed, psf_steps)

    print(f"\ngenerate(), CPU s per run: {', '.join(f'{t:.3f}' for t in runs)}")
    print(f"cli.main(), CPU s per run: {', '.join(f'{t:.3f}' for t in cli_runs)}")
    print("\n| stage of one generate() | CPU s | share |\n|---|---:|---:|")
    total = sum(stages.values())
    for name, t in stages.items():
        print(f"| {name} | {t:.3f} | {t / total:.0%} |")
    print(f"| sum | {total:.3f} | |")

    if psf_cpu is None:
        print("\npysocialforce is not installed (extra `bench`): no comparison")
        return
    psf = psf_cpu * DURATION_S / (psf_steps * PSF_DT_S)
    print(f"\nPySocialForce: {psf_steps} steps of {PSF_DT_S} s in {psf_cpu:.2f} CPU s")
    print(f"\n| N = {args.pedestrians}, {DURATION_S:.0f} simulated s | crowdsim CPU s | PySocialForce CPU s | "
          f"ratio |\n|---|---:|---:|---:|")
    for what, cpu in ((f"generate() end to end, best of {repeats}", min(runs)),
                      (f"cli.main(): generate + summary line, best of {repeats}", min(cli_runs)),
                      ("simulate only (the stage above, one run)", stages["simulate"])):
        print(f"| {what} | {cpu:.3f} | {psf:.2f} | {psf / cpu:.1f}x |")


if __name__ == "__main__":
    main()
