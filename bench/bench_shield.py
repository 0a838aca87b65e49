"""Cost of the planner's safety shield: plan() time of the crowd MPC with and without it, side by side.

The same closed-loop crowd as `bench_planner.py` (numpy walkers in a 16 m x 10 m hall, 20 perturbed
constant-velocity samples per step, the robot shuttling between two goals), here with a history so the shield's
constant-velocity future is used. Three configurations on identical crowds and seeds:

* `v1`: the version 1 crowd MPC (mid-step checks, no shield);
* `knots`: the same without mid-step checks (the NLP `CROWD_MPC` solves);
* `CROWD_MPC`: `knots` plus the shield (what the env runs).

Reports plan() wall time p50 / p95 (solver + shield), the ratio of each p50 / p95 to `v1`'s, the fraction of
calls the shield changed, and steps in collision (one plan step of 0.4 s applied per call, so these are not the
env's 0.1 s closed loop; use them as a sanity check, not a safety result).

    python bench/bench_shield.py [--steps 300] [--peds 20 40 60]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from bench_planner import GOALS, PRED_DT_S, Crowd  # the sibling script (this folder is sys.path[0] when run)

from planner import CROWD_MPC, MPCPlanner, PedPrediction, step_robot

CONFIGS = {
    "v1": replace(CROWD_MPC, check_midpoints=True, shield_horizon_s=0.0),
    "knots": replace(CROWD_MPC, shield_horizon_s=0.0),
    "CROWD_MPC": CROWD_MPC,
}


def with_history(pred: PedPrediction, crowd: Crowd) -> PedPrediction:
    """The prediction plus an 8-row history walked back along the current velocities (rows 0.4 s apart)."""
    hist = crowd.pos[None] + PRED_DT_S * np.arange(-7, 1)[:, None, None] * crowd.vel[None]
    return replace(pred, history=hist)


def run(name: str, n_peds: int, steps: int, seed: int) -> dict:
    cfg = replace(CONFIGS[name], time_budget_s=10.0)  # no load-dependent cut-off in a timing run
    rng = np.random.default_rng(seed)
    planner, crowd = MPCPlanner(cfg), Crowd.make(n_peds, rng)
    state, goal_idx, collisions, wall = np.zeros(5), 1, 0, []
    for _ in range(steps):
        pred = with_history(crowd.predict(rng), crowd)
        start = time.perf_counter()
        result = planner.plan(state, GOALS[goal_idx], pred)
        wall.append(time.perf_counter() - start)
        state = step_robot(state, result.control, cfg.dt_s)
        crowd.step(cfg.dt_s)
        collisions += crowd.contacts(state[:2], cfg.robot.radius_m)[0]
        if np.linalg.norm(state[:2] - GOALS[goal_idx]) < cfg.robot.radius_m:
            goal_idx = 1 - goal_idx
    ms = np.array(wall) * 1e3
    calls = max(planner.stats.counts["calls"], 1)
    return {"p50": float(np.percentile(ms, 50)), "p95": float(np.percentile(ms, 95)),
            "shielded": planner.stats.counts["shielded"] / calls, "collisions": collisions}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--peds", type=int, nargs="+", default=[20, 40, 60])
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    print("| peds | config | plan() p50 / p95 ms | ratio to v1 p50 / p95 | shield changed | steps in collision |")
    print("|---|---|---|---|---|---|")
    for n in args.peds:
        rows = {name: run(name, n, args.steps, args.seed) for name in CONFIGS}
        ref = rows["v1"]
        for name, r in rows.items():
            print(f"| {n} | {name} | {r['p50']:.1f} / {r['p95']:.1f} | {r['p50'] / ref['p50']:.2f} / "
                  f"{r['p95'] / ref['p95']:.2f} | {100 * r['shielded']:.0f}% | {r['collisions']} |", flush=True)


if __name__ == "__main__":
    main()
