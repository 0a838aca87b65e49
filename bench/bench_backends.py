"""Benchmark backends: Ray's per-episode overhead against the local process pool, and per-cell planner times.

1. Backends. The same short episodes (suite cell `corridor-low-visible` of `smoke`, policy `mpc-cv` and
   `random`, 2 s episodes, seeds 0..E-1) through `envs.evaluation.pool.run_tasks` with the local process pool and with
   Ray (a local instance, `ray.init(num_cpus=W)`), both with W workers. Ray's start-up is timed apart. Per
   backend: wall time, wall s per episode, and the ratio Ray / pool; the records must be identical up to
   wall-clock fields (checked and printed).
2. Planner p50/p95 per cell, from a benchmark output folder (`--board DIR/leaderboard.json`), if given.

Run: python bench/bench_backends.py [--episodes 24] [--workers 2] [--board out/bench-v1/leaderboard.json [--board-only]]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from dataclasses import replace
from pathlib import Path

from envs.evaluation.episode import EpisodeTask
from envs.evaluation.pool import run_tasks
from envs.evaluation.suite import load_suite
from envs.policies import ENV_MPC, PolicyConfig


def tasks(episodes: int, policy: str) -> list[EpisodeTask]:
    cell = load_suite("smoke").cell("corridor-low-visible")
    pcfg = PolicyConfig(policy, mpc=replace(ENV_MPC, time_budget_s=30.0))  # no load-dependent cut-off
    return [EpisodeTask(replace(cell.env_config(s), time_limit_s=2.0), pcfg, s, cell=cell.name)
            for s in range(episodes)]


def timed(ts: list[EpisodeTask], workers: int, backend: str) -> tuple[float, list]:
    start = time.perf_counter()
    out = sorted(((i, r["record"]) for i, r in run_tasks(ts, workers, backend)), key=lambda x: x[0])
    return time.perf_counter() - start, [replace(r, wall_time_s=0.0, solve_times_ms=()) for _, r in out]


def backends_table(episodes: int, workers: int) -> None:
    import ray

    start = time.perf_counter()
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    init_s = time.perf_counter() - start
    print(f"ray.init (local, {workers} CPUs): {init_s:.1f} s, not counted below")
    print("\nCold: the first run (pool: a new process pool; Ray: new worker processes, each importing and building its "
          "env and policy). Warm: the same tasks again (Ray keeps its workers; the pool is always new).")
    print("\n| policy | episodes | workers | pool wall s (s/ep) | Ray cold wall s (s/ep) | Ray warm wall s (s/ep) "
          "| Ray cold / pool | Ray warm / pool | records identical |")
    print("|---|---|---|---|---|---|---|---|---|")
    for policy in ("random", "mpc-cv"):
        ts = tasks(episodes, policy)
        pool_s, pool_recs = timed(ts, workers, "local")
        cold_s, cold_recs = timed(ts, workers, "ray")
        warm_s, warm_recs = timed(ts, workers, "ray")
        same = pool_recs == cold_recs == warm_recs
        print(f"| {policy} | {episodes} | {workers} | {pool_s:.2f} ({pool_s / episodes:.3f}) | {cold_s:.2f} "
              f"({cold_s / episodes:.3f}) | {warm_s:.2f} ({warm_s / episodes:.3f}) | {cold_s / pool_s:.2f} | "
              f"{warm_s / pool_s:.2f} | {same} |")
    ray.shutdown()


def planner_table(board_path: Path) -> None:
    board = json.loads(board_path.read_text())
    names = [n for n in board["policies"] if n.startswith("mpc")]
    print(f"\nPlanner solve time per cell, ms (p50 / p95), from {board_path}")
    print("\n| cell | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for cell, entry in board["cells"].items():
        row = []
        for n in names:
            r = entry["results"].get(n)
            row.append("–" if not r or r["solve_time_p50_ms"] is None
                       else f"{r['solve_time_p50_ms']:.1f} / {r['solve_time_p95_ms']:.1f}")
        print(f"| {cell} | " + " | ".join(row) + " |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=24)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--board", type=Path, default=None, help="leaderboard.json of a benchmark run")
    p.add_argument("--board-only", action="store_true", help="only the per-cell planner table of --board")
    args = p.parse_args()
    if args.board_only and args.board is None:
        p.error("--board-only needs --board")
    print(f"machine: {platform.machine()}, {platform.python_version()}, {time.strftime('%Y-%m-%d')}")
    if not args.board_only:
        backends_table(args.episodes, args.workers)
    if args.board is not None:
        planner_table(args.board)


if __name__ == "__main__":
    main()
