"""`CrowdNavEnv` throughput, against the bare crowd simulator, and with planners in the loop.

1. Env throughput, one process, random policy (uniform actions in [-1, 1]^2 from a seeded Generator),
   scenario plaza, dt 0.1 s, at 20 and 50 pedestrians: env steps per second over several thousand steps,
   with the resets (crowd reset + 3.2 s warm-up + route choice) timed apart: steps/s excluding resets and
   including them; side by side with the same numbers measured on the code before the throughput work
   (`REFERENCE`, 2026-11-23, same machine) and the ratio new / before. Also side by side, the reference: the
   bare `crowdsim.CrowdSimulator` with the env's own config (`CrowdNavConfig(...).sim_config()`, dt 0.1 s),
   stepped with the robot set before each step as the env does (here a robot walking at 1 m/s between
   opposite corners, reversing at each end). env/bare is the fraction of the bare simulator's rate the env
   keeps (1 - it is the env's overhead). Wall time (time.perf_counter) and process CPU time
   (time.process_time); best of 3 repeats, each metric on its own.
2. Planner in the loop at 20 pedestrians: `mpc-gpgraph` (GP-Graph + MPC; if the default synthetic
   checkpoint does not load, `GPGraphPolicy(config, predictor="gpgraph-stgcnn-univ")`), `mpc-cv` and
   `social-force`, full episodes with fixed seeds. Env steps/s (act + step, resets excluded), the
   real-time factor (simulated s / wall s), and the cost of each 0.4 s tick (4 env steps) split into the
   policy's prediction function (for mpc-gpgraph: history window + the model's `predict`), its planner's
   `plan` (the MPC with constant-velocity extrapolation inside for mpc-cv; 4 reactive calls per tick for
   social-force) and `env.step`, timed by wrapping those methods on the instances.

3. Env throughput with W worker processes (default 2), in aggregate: each worker builds its own env, warms up,
   waits for the others (a barrier), then runs the single-process loop of 1. (`steps` random steps, resets
   timed apart); aggregate steps/s = all workers' steps / (last end - first start), including resets, and
   the sum of the workers' rates excluding resets. Against the same measurement on the code before
   (`REFERENCE`).

Run: python bench/bench_env.py [--quick] [--steps 5000] [--episodes 3] [--workers 2] [--skip-planners]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import platform
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from crowdsim.sim import CrowdSimulator
from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.policies import GPGraphPolicy, make_policy
from planner import MPCConfig

FALLBACK_PREDICTOR = "gpgraph-stgcnn-univ"
TARGET_STEPS_PER_S = 2000.0
TARGET_ONE_PROCESS = 3000.0  # issue 13 item 5: plaza, 20 pedestrians, one process
TARGET_AGGREGATE = 5000.0  # ... and with 2 worker processes in aggregate
# The same measurements on the code before the throughput work (issue 13 item 5), 2026-11-23, 2-core sandbox,
# load 0.5-1.7: steps/s (wall) excluding / including resets, mean reset ms, bare crowdsim steps/s; and with
# 2 workers, the aggregate including resets and the summed rates excluding them (load ~1.1: this script run on
# a `git archive` of commit 2711a6f, the last one before the throughput work, with PYTHONPATH pointing at it).
REFERENCE: dict[str, dict[str, float]] = {
    "20": {"excl_wall": 1764.0, "incl_wall": 1636.0, "reset_ms": 8.2, "bare_wall": 4740.0},
    "50": {"excl_wall": 1325.0, "incl_wall": 1163.0, "reset_ms": 12.8, "bare_wall": 3319.0},
    "workers2_n20": {"incl_wall": 3370.0, "excl_wall": 3694.0},
}


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


COMPARE_HEADER = ("| measurement | before (REFERENCE) | now | now / before |")


THROUGHPUT_HEADER = ("| N | steps x repeats | resets / run | env steps/s excl. resets (wall / CPU) "
                     "| env steps/s incl. resets (wall / CPU) | mean reset ms | bare crowdsim steps/s (wall / CPU) "
                     "| env / bare (wall / CPU) | env overhead ms/step |")


def throughput_row(n: int, steps: int, repeats: int, r: dict[str, float]) -> str:
    overhead_ms = 1e3 * (1.0 / r["excl_wall"] - 1.0 / r["bare_wall"])
    return (f"| {n} | {steps} x {repeats} | {r['resets']:.1f} | {r['excl_wall']:,.0f} / {r['excl_cpu']:,.0f} "
            f"| {r['incl_wall']:,.0f} / {r['incl_cpu']:,.0f} | {1e3 / r['reset_rate']:.1f} "
            f"| {r['bare_wall']:,.0f} / {r['bare_cpu']:,.0f} "
            f"| {r['excl_wall'] / r['bare_wall']:.2f} / {r['excl_cpu'] / r['bare_cpu']:.2f} | {overhead_ms:.2f} |")


# -------------------------------------------------------------------------------- 2. planner in the loop
def build_policy(name: str, env: CrowdNavEnv) -> tuple[Any, str]:
    """The policy and a note on its predictor (the fallback checkpoint when the default does not load)."""
    if name != "mpc-gpgraph":
        return make_policy(name, env), "-"
    try:
        policy = make_policy(name, env)
        return policy, "default (gpgraph-stgcnn-synthetic)"
    except Exception as exc:  # the synthetic checkpoint may not be packaged yet
        print(f"note: mpc-gpgraph default predictor did not load ({type(exc).__name__}: {str(exc)[:80]}...); "
              f"using GPGraphPolicy(config, predictor={FALLBACK_PREDICTOR!r})")
        config = replace(MPCConfig(), robot=env.config.robot)
        return GPGraphPolicy(config, predictor=FALLBACK_PREDICTOR), f"{FALLBACK_PREDICTOR} (fallback)"


class Timers:
    """Seconds spent in wrapped methods since the last `take()`."""

    def __init__(self) -> None:
        self.acc: dict[str, float] = {}

    def wrap(self, obj: Any, attr: str, key: str) -> None:
        fn: Callable = getattr(obj, attr)
        self.acc[key] = 0.0

        def timed(*args: Any, **kwargs: Any) -> Any:
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.acc[key] += time.perf_counter() - t

        setattr(obj, attr, timed)

    def take(self) -> dict[str, float]:
        out = dict(self.acc)
        for k in self.acc:
            self.acc[k] = 0.0
        return out


def bench_policy(name: str, n: int, seeds: list[int], time_limit_s: float) -> dict[str, Any]:
    cfg = CrowdNavConfig(n_pedestrians=n, time_limit_s=time_limit_s)
    env = CrowdNavEnv(cfg)
    policy, note = build_policy(name, env)
    timers = Timers()
    timers.wrap(policy, "_predict", "predictor")
    timers.wrap(policy.planner, "plan", "planner")
    if hasattr(policy, "predictor"):
        timers.wrap(policy.predictor, "predict", "model")
    # warm-up (first solve, first model call), untimed
    obs, _ = env.reset(seed=10_000)
    policy.reset(env, 10_000)
    for _ in range(8):
        obs, _, term, trunc, _ = env.step(policy.act(obs, env))
        if term or trunc:
            break
    steps, wall, cpu = 0, 0.0, 0.0
    per_step: list[tuple[int, dict[str, float]]] = []  # (step index in episode, times s)
    outcomes = {"success": 0, "collision": 0, "timeout": 0}
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        policy.reset(env, seed)
        timers.take()
        done, k, info = False, 0, {}
        w0, c0 = _clocks()
        while not done:
            t0 = time.perf_counter()
            action = policy.act(obs, env)
            t1 = time.perf_counter()
            obs, _, term, trunc, info = env.step(action)
            t2 = time.perf_counter()
            done = term or trunc
            times = timers.take()
            times.update(act=t1 - t0, env=t2 - t1)
            per_step.append((k, times))
            k += 1
        w1, c1 = _clocks()
        steps, wall, cpu = steps + k, wall + w1 - w0, cpu + c1 - c0
        m = info["episode_metrics"]
        outcomes["success" if m["success"] else "collision" if m["collision"] else "timeout"] += 1
    # per 0.4 s tick: sums over the tick's env steps (complete ticks only)
    tps = cfg.ticks_per_prediction_step
    ticks: list[dict[str, float]] = []
    cur: dict[str, float] = {}
    for k, times in per_step:
        if k % tps == 0:
            cur = {}
        for key, v in times.items():
            cur[key] = cur.get(key, 0.0) + v
        if k % tps == tps - 1:
            ticks.append(cur)

    def stat(key: str) -> tuple[float, float]:
        vals = np.array([t.get(key, 0.0) for t in ticks]) * 1e3
        return (float(np.median(vals)), float(np.percentile(vals, 95))) if len(vals) else (np.nan, np.nan)

    model_calls = np.array([t["model"] for _, t in per_step if t.get("model", 0.0) > 0.0]) * 1e3
    total = [t["act"] + t["env"] for t in ticks]
    return {"policy": name, "predictor": note, "episodes": len(seeds), "outcomes": outcomes, "steps": steps,
            "ticks": len(ticks), "rate_wall": steps / wall, "rate_cpu": steps / cpu,
            "rtf": steps * cfg.dt_s / wall, "pred": stat("predictor"), "plan": stat("planner"),
            "env": stat("env"), "total": (float(np.median(total)) * 1e3, float(np.percentile(total, 95)) * 1e3),
            "model": (float(np.median(model_calls)), float(np.percentile(model_calls, 95)))
            if len(model_calls) else None}


LOOP_HEADER = ("| policy | predictor | episodes (success / collision / timeout) | steps | env steps/s (wall / CPU) "
               "| real-time factor | predictor ms/tick p50 / p95 | planner ms/tick p50 / p95 "
               "| env step ms/tick p50 / p95 | tick total ms p50 / p95 |")


def loop_row(r: dict[str, Any]) -> str:
    o = r["outcomes"]

    def pair(v: tuple[float, float]) -> str:
        return f"{v[0]:.2f} / {v[1]:.2f}"

    return (f"| {r['policy']} | {r['predictor']} | {r['episodes']} ({o['success']} / {o['collision']} / "
            f"{o['timeout']}) | {r['steps']} | {r['rate_wall']:,.0f} / {r['rate_cpu']:,.0f} | {r['rtf']:.1f}x "
            f"| {pair(r['pred'])} | {pair(r['plan'])} | {pair(r['env'])} | {pair(r['total'])} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="300 steps, 1 repeat, one 20 s episode per policy")
    parser.add_argument("--steps", type=int, default=5000, help="env steps per throughput repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=3, help="episodes (seeds 0..E-1) per policy")
    parser.add_argument("--sizes", default="20,50", help="pedestrian counts for the throughput table")
    parser.add_argument("--workers", type=int, default=2, help="worker processes for the aggregate rate (0: skip)")
    parser.add_argument("--skip-planners", action="store_true", help="skip the planner-in-the-loop table")
    args = parser.parse_args(argv)
    steps, repeats = (300, 1) if args.quick else (args.steps, args.repeats)
    episodes, time_limit = (1, 20.0) if args.quick else (args.episodes, CrowdNavConfig().time_limit_s)
    start = time.perf_counter()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"python {platform.python_version()}; date {time.strftime('%Y-%m-%d')}; load average at start "
          f"{_load()} (1/5/15 min)")
    print(f"\nenv throughput, random policy, plaza, dt 0.1 s, one process; {steps} steps, best of {repeats}")
    print(THROUGHPUT_HEADER)
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    at_20 = None
    rows: list[str] = []
    for n in (int(x) for x in args.sizes.split(",")):
        r = bench_throughput(n, steps, repeats)
        at_20 = r if n == 20 else at_20
        print(throughput_row(n, steps, repeats, r), flush=True)
        ref = REFERENCE.get(str(n))
        if ref:
            for key, label in (("excl_wall", "steps/s excl. resets"), ("incl_wall", "steps/s incl. resets"),
                               ("bare_wall", "bare crowdsim steps/s")):
                rows.append(f"| N = {n}, one process, {label} (wall) | {ref[key]:,.0f} | {r[key]:,.0f} "
                            f"| {_ratio(r[key], ref[key])} |")
            reset_ms = 1e3 / r["reset_rate"]
            rows.append(f"| N = {n}, one process, mean reset ms | {ref['reset_ms']:.1f} | {reset_ms:.1f} "
                        f"| {_ratio(reset_ms, ref['reset_ms'])} |")
    if at_20 is not None:
        met = at_20["excl_wall"] >= TARGET_STEPS_PER_S
        print(f"target >= {TARGET_STEPS_PER_S:,.0f} env steps/s at 20 pedestrians (excl. resets, wall): "
              f"{'met' if met else 'NOT met'} ({at_20['excl_wall']:,.0f}; CPU-time rate {at_20['excl_cpu']:,.0f})")
        for key, label in (("excl_wall", "excl."), ("incl_wall", "incl.")):
            met = at_20[key] >= TARGET_ONE_PROCESS
            print(f"target >= {TARGET_ONE_PROCESS:,.0f} env steps/s at 20 pedestrians, one process ({label} resets, "
                  f"wall): {'met' if met else 'NOT met'} ({at_20[key]:,.0f})")
    if args.workers > 0:
        w = bench_workers(20, steps, args.workers, repeats)
        ref = REFERENCE["workers2_n20"] if args.workers == 2 else {"incl_wall": 0.0, "excl_wall": 0.0}
        rows.append(f"| N = 20, {args.workers} workers, aggregate steps/s incl. resets (wall) | "
                    f"{ref['incl_wall']:,.0f} | {w['incl_wall']:,.0f} | {_ratio(w['incl_wall'], ref['incl_wall'])} |")
        rows.append(f"| N = 20, {args.workers} workers, summed steps/s excl. resets (wall) | "
                    f"{ref['excl_wall']:,.0f} | {w['excl_wall']:,.0f} | {_ratio(w['excl_wall'], ref['excl_wall'])} |")
        for key, label in (("excl_wall", "excl."), ("incl_wall", "incl.")):
            met = w[key] >= TARGET_AGGREGATE
            print(f"target >= {TARGET_AGGREGATE:,.0f} env steps/s aggregate with {args.workers} workers ({label} "
                  f"resets): {'met' if met else 'NOT met'} ({w[key]:,.0f})")
    if rows:
        print(f"\nbefore (REFERENCE, the code before the throughput work, 2026-11-23) and now; load average now "
              f"{_load()}")
        print(COMPARE_HEADER)
        print("|---|---:|---:|---:|")
        print("\n".join(rows), flush=True)
    if args.skip_planners:
        print(f"\nload average at end {_load()}; {time.perf_counter() - start:.0f} s in all")
        return
    print(f"\nplanner in the loop, 20 pedestrians, plaza, {episodes} episode(s) (seeds 0..{episodes - 1}), "
          f"time limit {time_limit:.0f} s; per 0.4 s tick = 4 env steps")
    rows = []
    for name in ("mpc-gpgraph", "mpc-cv", "social-force"):
        rows.append(bench_policy(name, 20, list(range(episodes)), time_limit))
    print(LOOP_HEADER)
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(loop_row(r))
    for r in rows:
        if r["model"] is not None:
            print(f"{r['policy']}: model predict() alone {r['model'][0]:.2f} / {r['model'][1]:.2f} ms per call "
                  f"(p50 / p95, K = 20, one torch thread)")
    print(f"\nload average at end {_load()}; {time.perf_counter() - start:.0f} s in all")


if __name__ == "__main__":
    main()
