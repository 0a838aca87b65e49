"""Planner in the loop at 20 pedestrians (part 4 of `bench/bench_env.py`, which runs it).

`mpc-gpgraph` (GP-Graph + MPC; if the default synthetic checkpoint does not load,
`GPGraphPolicy(config, predictor="gpgraph-stgcnn-univ")`), `mpc-cv` and `social-force`, full episodes with fixed
seeds. Env steps/s (act + step, resets excluded), the real-time factor (simulated s / wall s), and the cost of each
0.4 s tick (4 env steps) split into the policy's prediction function (for mpc-gpgraph: history window + the
model's `predict`), its planner's `plan` (the MPC with constant-velocity extrapolation inside for mpc-cv; 4
reactive calls per tick for social-force) and `env.step`, timed by wrapping those methods on the instances.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from envs.config import DEFAULT_PREDICTOR, CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.policies import GPGraphPolicy, act, make_policy
from planner import MPCConfig

FALLBACK_PREDICTOR = "gpgraph-stgcnn-univ"


def _clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def build_policy(name: str, env: CrowdNavEnv) -> tuple[Any, str]:
    """The policy and a note on its predictor (the fallback checkpoint when the default does not load)."""
    if name != "mpc-gpgraph":
        return make_policy(name, env), "-"
    try:
        policy = make_policy(name, env)
        return policy, f"default ({DEFAULT_PREDICTOR})"
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
    env.reset(seed=10_000)
    policy.reset(10_000)
    for _ in range(8):
        _, _, term, trunc, _ = env.step(act(policy, env))
        if term or trunc:
            break
    steps, wall, cpu = 0, 0.0, 0.0
    per_step: list[tuple[int, dict[str, float]]] = []  # (step index in episode, times s)
    outcomes = {"success": 0, "collision": 0, "timeout": 0}
    for seed in seeds:
        env.reset(seed=seed)
        policy.reset(seed)
        timers.take()
        done, k, info = False, 0, {}
        w0, c0 = _clocks()
        while not done:
            t0 = time.perf_counter()
            action = act(policy, env)
            t1 = time.perf_counter()
            _, _, term, trunc, info = env.step(action)
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




def main(quick: bool, episodes: int) -> None:
    """Print the planner-in-the-loop table (one 20 s episode per policy with `quick`)."""
    episodes, time_limit = (1, 20.0) if quick else (episodes, CrowdNavConfig().time_limit_s)
    print(f"\nplanner in the loop, 20 pedestrians, plaza, {episodes} episode(s) (seeds 0..{episodes - 1}), "
          f"time limit {time_limit:.0f} s; per 0.4 s tick = 4 env steps")
    rows = [bench_policy(name, 20, list(range(episodes)), time_limit)
            for name in ("mpc-gpgraph", "mpc-cv", "social-force")]
    print(LOOP_HEADER)
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(loop_row(r))
    for r in rows:
        if r["model"] is not None:
            print(f"{r['policy']}: model predict() alone {r['model'][0]:.2f} / {r['model'][1]:.2f} ms per call "
                  f"(p50 / p95, K = 20, one torch thread)")
