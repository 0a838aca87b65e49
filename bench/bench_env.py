"""`CrowdNavEnv` throughput, against the bare crowd simulator and against another checkout of the code, and with
planners in the loop.

1. Env throughput, one process, random policy (uniform actions in [-1, 1]^2 from a seeded Generator),
   scenario plaza, dt 0.1 s, at 20 and 50 pedestrians: env steps per second over several thousand steps,
   with the resets (crowd reset + 3.2 s warm-up + route choice) timed apart: steps/s excluding resets and
   including them. Side by side, the reference: the bare `crowdsim.CrowdSimulator` with the env's own config
   (`CrowdNavConfig(...).sim_config()`, dt 0.1 s), stepped with the robot set before each step as the env does
   (here a robot walking at 1 m/s between opposite corners, reversing at each end). env/bare is the fraction of
   the bare simulator's rate the env keeps (1 - it is the env's overhead). Wall time (time.perf_counter) and
   process CPU time (time.process_time); best of the repeats, each metric on its own.
2. Env throughput with W worker processes (default 2), in aggregate: each worker builds its own env, warms up,
   waits for the others (a barrier), then runs the single-process loop of 1. (`steps` random steps, resets
   timed apart); aggregate steps/s = all workers' steps / (last end - first start), including resets, and
   the sum of the workers' rates excluding resets.
3. With `--before TREE` (a checkout of other code, e.g. `git worktree add /tmp/before 2711a6f`, the last commit
   before the throughput work): 1. and 2. measured again in a fresh process that imports `crowdsim` and `envs`
   from TREE, right after, and a table of before / now / ratio.
4. Planner in the loop (`bench/env_loop.py`; `--skip-planners` leaves it out).

Run: python bench/bench_env.py [--quick] [--steps 5000] [--episodes 3] [--workers 2] [--skip-planners]
    [--before TREE]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.sim import CrowdSimulator
from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv

TARGET_STEPS_PER_S = 2000.0
TARGET_ONE_PROCESS = 3000.0  # issue 13 item 5: plaza, 20 pedestrians, one process
TARGET_AGGREGATE = 5000.0  # ... and with 2 worker processes in aggregate


def _load() -> str:
    return "/".join(f"{x:.2f}" for x in os.getloadavg())


def _clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


# ------------------------------------------------------------------------------------ 1. throughput
def env_run(env: CrowdNavEnv, steps: int, seed: int) -> dict[str, float]:
    """`steps` random-action env steps from a reset with `seed`; every reset (the first included) is
    timed apart. Returns wall/CPU seconds in total and in resets, and the number of resets."""
    rng = np.random.default_rng(seed)
    reset_wall = reset_cpu = 0.0
    w0, c0 = _clocks()
    env.reset(seed=seed)
    w1, c1 = _clocks()
    reset_wall, reset_cpu, resets = w1 - w0, c1 - c0, 1
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, 2).astype(np.float32))
        if terminated or truncated:
            rw, rc = _clocks()
            env.reset()
            rw2, rc2 = _clocks()
            reset_wall, reset_cpu, resets = reset_wall + rw2 - rw, reset_cpu + rc2 - rc, resets + 1
    w2, c2 = _clocks()
    return {"wall": w2 - w0, "cpu": c2 - c0, "reset_wall": reset_wall, "reset_cpu": reset_cpu, "resets": resets}


def bare_run(sim: CrowdSimulator, steps: int, seed: int, warmup_steps: int, radius_m: float) -> dict[str, float]:
    """`steps` bare simulator steps after a reset and `warmup_steps` untimed ones; before each step the
    robot is set (pos, vel, radius) as the env does, walking at 1 m/s between opposite corners."""
    sim.reset(seed)
    for _ in range(warmup_steps):
        sim.step()
    x0, y0, x1, y1 = (float(b) for b in sim.scenario.bounds)
    a, b = np.array([x0 + 3.0, y0 + 3.0]), np.array([x1 - 3.0, y1 - 3.0])
    dt = sim.config.record_dt_s
    pos, goal = a.copy(), b
    w0, c0 = _clocks()
    for _ in range(steps):
        d = goal - pos
        dist = float(np.hypot(*d))
        if dist < 0.05:
            goal = a if goal is b else b
            d, dist = goal - pos, float(np.hypot(*(goal - pos)))
        vel = d / dist * min(1.0, dist / dt)
        sim.set_robot(pos, vel, radius_m)
        sim.step()
        pos = pos + vel * dt
    w1, c1 = _clocks()
    return {"wall": w1 - w0, "cpu": c1 - c0}


def bench_throughput(n: int, steps: int, repeats: int) -> dict[str, float]:
    """Best-of-`repeats` rates (each metric on its own) for the env and the bare simulator at n peds."""
    cfg = CrowdNavConfig(n_pedestrians=n)
    env = CrowdNavEnv(cfg)
    env_run(env, 50, seed=10_000)  # numba cache load, first allocations
    sim = CrowdSimulator(cfg.sim_config())
    warmup = round(cfg.warmup_s / cfg.dt_s)
    bare_run(sim, 20, 10_000, 0, cfg.robot.radius_m)
    best: dict[str, float] = {}

    def keep(key: str, value: float) -> None:
        best[key] = max(best.get(key, 0.0), value)

    resets = []
    for rep in range(repeats):
        r = env_run(env, steps, seed=rep)
        keep("excl_wall", steps / (r["wall"] - r["reset_wall"]))
        keep("excl_cpu", steps / (r["cpu"] - r["reset_cpu"]))
        keep("incl_wall", steps / r["wall"])
        keep("incl_cpu", steps / r["cpu"])
        keep("reset_rate", r["resets"] / r["reset_wall"])  # resets/s, best = shortest mean reset
        resets.append(r["resets"])
        b = bare_run(sim, steps, rep, warmup, cfg.robot.radius_m)
        keep("bare_wall", steps / b["wall"])
        keep("bare_cpu", steps / b["cpu"])
    best["resets"] = float(np.mean(resets))
    return best


def _worker(n: int, steps: int, seed: int, barrier: Any, out: Any) -> None:
    env = CrowdNavEnv(CrowdNavConfig(n_pedestrians=n))
    env_run(env, 50, seed=10_000 + seed)  # numba cache load, first allocations
    barrier.wait()
    start = time.perf_counter()  # CLOCK_MONOTONIC: comparable across processes
    r = env_run(env, steps, seed=seed)
    out.put({**r, "start": start, "end": time.perf_counter()})


def bench_workers(n: int, steps: int, workers: int, repeats: int) -> dict[str, float]:
    """Best-of-`repeats` aggregate rates of `workers` processes each running `env_run` for `steps` steps."""
    ctx = mp.get_context("fork")
    best: dict[str, float] = {}
    for rep in range(repeats):
        barrier, out = ctx.Barrier(workers), ctx.Queue()
        procs = [ctx.Process(target=_worker, args=(n, steps, 100 * rep + w, barrier, out)) for w in range(workers)]
        for p in procs:
            p.start()
        results = [out.get() for _ in procs]
        for p in procs:
            p.join()
        wall = max(r["end"] for r in results) - min(r["start"] for r in results)
        best["incl_wall"] = max(best.get("incl_wall", 0.0), workers * steps / wall)
        best["excl_wall"] = max(best.get("excl_wall", 0.0),
                                sum(steps / (r["wall"] - r["reset_wall"]) for r in results))
    return best


def _ratio(new: float, ref: float) -> str:
    return f"{new / ref:.2f}x" if ref > 0 else "-"


THROUGHPUT_HEADER = ("| N | steps x repeats | resets / run | env steps/s excl. resets (wall / CPU) "
                     "| env steps/s incl. resets (wall / CPU) | mean reset ms | bare crowdsim steps/s (wall / CPU) "
                     "| env / bare (wall / CPU) | env overhead ms/step |")


def throughput_row(n: int, steps: int, repeats: int, r: dict[str, float]) -> str:
    overhead_ms = 1e3 * (1.0 / r["excl_wall"] - 1.0 / r["bare_wall"])
    return (f"| {n} | {steps} x {repeats} | {r['resets']:.1f} | {r['excl_wall']:,.0f} / {r['excl_cpu']:,.0f} "
            f"| {r['incl_wall']:,.0f} / {r['incl_cpu']:,.0f} | {1e3 / r['reset_rate']:.1f} "
            f"| {r['bare_wall']:,.0f} / {r['bare_cpu']:,.0f} "
            f"| {r['excl_wall'] / r['bare_wall']:.2f} / {r['excl_cpu'] / r['bare_cpu']:.2f} | {overhead_ms:.2f} |")


def measure(sizes: list[int], steps: int, repeats: int, workers: int) -> dict[str, dict[str, float]]:
    """Parts 1 and 2: {str(n): bench_throughput, "workers": bench_workers at 20 pedestrians (if workers)}."""
    out = {str(n): bench_throughput(n, steps, repeats) for n in sizes}
    if workers > 0:
        out["workers"] = bench_workers(20, steps, workers, repeats)
    return out


def measure_tree(tree: Path, sizes: list[int], steps: int, repeats: int, workers: int) -> dict[str, dict[str, float]]:
    """`measure` in a fresh process that imports the code (crowdsim, envs, ...) from `tree` (this script's
    functions, that code's modules)."""
    code = (f"import json, sys; sys.path[:0] = [{str(tree)!r}, {str(Path(__file__).parent)!r}]; import bench_env; "
            f"print(json.dumps(bench_env.measure({sizes!r}, {steps}, {repeats}, {workers})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tree, check=False)
    if done.returncode != 0:
        raise SystemExit(f"bench_env: measuring {tree} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _print_target(what: str, rates: dict[str, float], target: float) -> None:
    """One line per rate (excluding and including resets): whether it reaches `target` env steps/s."""
    for key, label in (("excl_wall", "excl."), ("incl_wall", "incl.")):
        verdict = "met" if rates[key] >= target else "NOT met"
        print(f"target >= {target:,.0f} env steps/s {what} ({label} resets, wall): {verdict} ({rates[key]:,.0f})")


def print_targets(now: dict[str, dict[str, float]], workers: int) -> None:
    at_20, w = now.get("20"), now.get("workers")
    if at_20 is not None:
        met = at_20["excl_wall"] >= TARGET_STEPS_PER_S
        print(f"target >= {TARGET_STEPS_PER_S:,.0f} env steps/s at 20 pedestrians (excl. resets, wall): "
              f"{'met' if met else 'NOT met'} ({at_20['excl_wall']:,.0f}; CPU-time rate {at_20['excl_cpu']:,.0f})")
        _print_target("at 20 pedestrians, one process", at_20, TARGET_ONE_PROCESS)
    if w is not None:
        print(f"{workers} workers, 20 pedestrians: aggregate {w['incl_wall']:,.0f} steps/s including resets, "
              f"summed {w['excl_wall']:,.0f} excluding them")
        _print_target(f"aggregate with {workers} workers", w, TARGET_AGGREGATE)


def compare_rows(before: dict[str, dict[str, float]], now: dict[str, dict[str, float]], workers: int) -> list[str]:
    """Markdown rows: measurement | before | now | now / before."""
    rows = []
    for n in (k for k in now if k != "workers" and k in before):
        b, r = before[n], now[n]
        for key, label in (("excl_wall", "steps/s excl. resets"), ("incl_wall", "steps/s incl. resets"),
                           ("bare_wall", "bare crowdsim steps/s")):
            rows.append(f"| N = {n}, one process, {label} (wall) | {b[key]:,.0f} | {r[key]:,.0f} "
                        f"| {_ratio(r[key], b[key])} |")
        ms_b, ms_r = 1e3 / b["reset_rate"], 1e3 / r["reset_rate"]
        rows.append(f"| N = {n}, one process, mean reset ms | {ms_b:.1f} | {ms_r:.1f} | {_ratio(ms_r, ms_b)} |")
    if "workers" in now and "workers" in before:
        b, r = before["workers"], now["workers"]
        rows.append(f"| N = 20, {workers} workers, aggregate steps/s incl. resets (wall) | {b['incl_wall']:,.0f} "
                    f"| {r['incl_wall']:,.0f} | {_ratio(r['incl_wall'], b['incl_wall'])} |")
        rows.append(f"| N = 20, {workers} workers, summed steps/s excl. resets (wall) | {b['excl_wall']:,.0f} "
                    f"| {r['excl_wall']:,.0f} | {_ratio(r['excl_wall'], b['excl_wall'])} |")
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="300 steps, 1 repeat, one 20 s episode per policy")
    parser.add_argument("--steps", type=int, default=5000, help="env steps per throughput repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=3, help="episodes (seeds 0..E-1) per policy")
    parser.add_argument("--sizes", default="20,50", help="pedestrian counts for the throughput table")
    parser.add_argument("--workers", type=int, default=2, help="worker processes for the aggregate rate (0: skip)")
    parser.add_argument("--skip-planners", action="store_true", help="skip the planner-in-the-loop table")
    parser.add_argument("--before", type=Path, default=None, help="a checkout of other code to measure side by side")
    args = parser.parse_args(argv)
    if args.before is not None and not (args.before / "envs" / "env.py").is_file():
        parser.error(f"--before {args.before}: not a checkout of this project (no envs/env.py)")
    steps, repeats = (300, 1) if args.quick else (args.steps, args.repeats)
    sizes = [int(x) for x in args.sizes.split(",")]
    start = time.perf_counter()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"python {platform.python_version()}; date {time.strftime('%Y-%m-%d')}; load average at start "
          f"{_load()} (1/5/15 min)")
    now = measure(sizes, steps, repeats, args.workers)
    print(f"\nenv throughput, random policy, plaza, dt 0.1 s, one process; {steps} steps, best of {repeats}")
    print(THROUGHPUT_HEADER)
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        print(throughput_row(n, steps, repeats, now[str(n)]))
    print_targets(now, args.workers)
    if args.before is not None:
        print(f"\nmeasuring {args.before} the same way in a fresh process (load average now {_load()}) ...", flush=True)
        before = measure_tree(args.before.resolve(), sizes, steps, repeats, args.workers)
        print(f"\nbefore ({args.before}) and now, same protocol, measured one after the other; load average now "
              f"{_load()}")
        print("| measurement | before | now | now / before |")
        print("|---|---:|---:|---:|")
        print("\n".join(compare_rows(before, now, args.workers)), flush=True)
    if not args.skip_planners:
        import env_loop

        env_loop.main(args.quick, args.episodes)
    print(f"\nload average at end {_load()}; {time.perf_counter() - start:.0f} s in all")


if __name__ == "__main__":
    main()
