"""The warm start's expert roll-outs on Ray against the local process pool (`crowdnav train --backend ray`).

`envs.rl.imitation.collect_demos` labels E episodes by an MPC expert, first alone (the demonstrations), then with
an untrained learner driving (a DAgger round, beta 0). Each runs on the local pool (W processes, seeds interleaved)
and on a local Ray instance of W CPUs (one task per episode; Ray's start-up timed apart). Printed: wall time, seconds
per episode, the ratio Ray / pool, and whether the labels are identical (they must be). On one machine Ray can only
add overhead; what it buys is a cluster (`--address`), where the same tasks spread over many machines.

    python bench/bench_rollout_backends.py [--episodes 12] [--workers 2]
"""

from __future__ import annotations

import argparse
import platform
import time
from dataclasses import replace

import numpy as np
import ray
from stable_baselines3 import PPO

from envs.env import CrowdNavEnv
from envs.policies import ENV_MPC
from envs.rl.config import TrainConfig
from envs.rl.extractor import CrowdAttentionExtractor
from envs.rl.imitation import Demos, collect_demos

SEED0 = 500_000  # no suite reports these


def same(a: Demos, b: Demos) -> bool:
    return (np.array_equal(a.actions, b.actions) and np.array_equal(a.returns, b.returns)
            and all(np.array_equal(a.obs[k], b.obs[k]) for k in a.obs))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=12)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    cfg = TrainConfig().env_config()  # circle crossing, 5 people who do not see the robot
    mpc = replace(ENV_MPC, time_budget_s=30.0)  # no load-dependent cut-off: both backends label the same
    learner = PPO("MultiInputPolicy", CrowdNavEnv(cfg), seed=0, device="cpu",
                  policy_kwargs={"features_extractor_class": CrowdAttentionExtractor}).policy
    runs = {"expert demonstrations": {}, "DAgger round (learner drives)": {"learner": learner, "beta": 0.0}}
    rows = []
    for what, kw in runs.items():
        t = time.perf_counter()
        local = collect_demos(cfg, "mpc-cv", args.episodes, SEED0, workers=args.workers, mpc=mpc, **kw)
        t_local = time.perf_counter() - t
        t = time.perf_counter()
        ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
        t_start = time.perf_counter() - t
        try:
            t = time.perf_counter()
            remote = collect_demos(cfg, "mpc-cv", args.episodes, SEED0, workers=args.workers, mpc=mpc, backend="ray",
                                   **kw)
            t_ray = time.perf_counter() - t
        finally:
            ray.shutdown()
        rows.append((what, len(local.actions), t_local, t_ray, t_start, same(local, remote)))
    print(f"{args.episodes} episodes, mpc-cv expert, {args.workers} workers; {platform.processor() or 'cpu'}, "
          f"Python {platform.python_version()}")
    print("| roll-outs | labels | pool (s) | Ray (s) | Ray start-up (s) | s / episode pool, Ray | Ray / pool | "
          "identical |")
    print("|---|---|---|---|---|---|---|---|")
    for what, n, tl, tr, ts, ok in rows:
        print(f"| {what} | {n} | {tl:.1f} | {tr:.1f} | {ts:.1f} | {tl / args.episodes:.2f}, {tr / args.episodes:.2f} | "
              f"{tr / tl:.2f} | {'yes' if ok else 'NO'} |")
    return 0 if all(r[-1] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
