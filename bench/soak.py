"""Soak tests, outside the default suite: long runs that must not raise, leak memory or let bodies escape.

1. env steps: 10^4 env steps with each of mpc-gpgraph, mpc-cv, mpc-none and social-force, episodes cycling
   through plaza, corridor, crossing and circle_crossing (reset whenever one ends). Resident memory is read after
   a warm-up (the first 10% of steps: solvers built, predictor loaded) and at the end.
2. resets: 10^3 env resets across the same scenarios (no steps), memory after the first 100 and at the end.
3. crowd: a 30-minute crowdsim run (4,500 steps of 0.4 s) of 400 people in an 80 x 10 m corridor: every active
   position finite, every body between the side walls (0 < y < 10 m), memory after 10% and at the end.

Prints one table row per part: work done, errors, RSS (MiB) after warm-up and at the end, growth (%), and the
check that matters. Targets: no exception, RSS growth < 5%, no NaN, no escape.

    python bench/soak.py [--quick]      # --quick: a tenth of everything
"""

from __future__ import annotations

import argparse
import time
import traceback
from pathlib import Path

import numpy as np

SCENARIOS = ("plaza", "corridor", "crossing", "circle_crossing")
POLICIES = ("mpc-gpgraph", "mpc-cv", "mpc-none", "social-force")


def rss_mib() -> float:
    """Resident set size of this process, MiB (Linux /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _env(scenario: str):
    from envs import CrowdNavConfig, CrowdNavEnv

    return CrowdNavEnv(CrowdNavConfig(scenario=scenario, n_pedestrians=24, time_limit_s=20.0))


def soak_policy(name: str, steps: int) -> dict:
    from envs.policies import act, make_policy

    envs = {s: _env(s) for s in SCENARIOS}
    policies = {s: make_policy(name, env) for s, env in envs.items()}
    done, episodes, errors, warm = 0, 0, 0, None
    start = time.perf_counter()
    while done < steps:
        scenario = SCENARIOS[episodes % len(SCENARIOS)]
        env, policy = envs[scenario], policies[scenario]
        env.reset(seed=episodes)
        policy.reset(episodes)
        episodes += 1
        end = False
        while not end and done < steps:
            try:
                _, _, term, trunc, _ = env.step(act(policy, env))
            except Exception:  # counted (the soak target is zero) and shown
                errors += 1
                traceback.print_exc()
                break
            end, done = term or trunc, done + 1
            if warm is None and done >= steps // 10:
                warm = rss_mib()
    return {"part": f"env steps, {name}", "work": f"{done} steps, {episodes} episodes", "errors": errors,
            "rss0": warm, "rss1": rss_mib(), "check": f"{time.perf_counter() - start:.0f} s"}


def soak_resets(n: int) -> dict:
    envs = {s: _env(s) for s in SCENARIOS}
    errors, warm = 0, None
    for k in range(n):
        try:
            envs[SCENARIOS[k % len(SCENARIOS)]].reset(seed=k)
        except Exception:  # counted and shown
            errors += 1
            traceback.print_exc()
        if k + 1 == n // 10:
            warm = rss_mib()
    return {"part": "env resets", "work": f"{n} resets", "errors": errors, "rss0": warm, "rss1": rss_mib(),
            "check": "-"}


def soak_crowd(steps: int, n: int = 400) -> dict:
    from crowdsim import CrowdSimulator, SimConfig

    width = 10.0
    sim = CrowdSimulator(SimConfig(scenario="corridor", n_pedestrians=n,
                                   scenario_options=(("length_m", 80.0), ("width_m", width))))
    state = sim.reset(seed=0)
    nan, escaped, warm, errors = 0, 0, None, 0
    for k in range(steps):
        try:
            state = sim.step()
        except Exception:  # counted and shown
            errors += 1
            traceback.print_exc()
            break
        pos = state.pos[state.active]
        nan += int((~np.isfinite(pos)).any(axis=1).sum())
        escaped += int(((pos[:, 1] <= 0.0) | (pos[:, 1] >= width)).sum())
        if k + 1 == steps // 10:
            warm = rss_mib()
    minutes = steps * 0.4 / 60.0
    return {"part": f"crowd, {n} people", "work": f"{steps} steps ({minutes:.0f} simulated min)", "errors": errors,
            "rss0": warm, "rss1": rss_mib(), "check": f"NaN rows {nan}, escapes {escaped}"}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="a tenth of every part")
    args = p.parse_args(argv)
    scale = 10 if args.quick else 1
    from predictor import set_threads

    set_threads(1)
    rows = [soak_policy(name, 10_000 // scale) for name in POLICIES]
    rows.append(soak_resets(1_000 // scale))
    rows.append(soak_crowd(4_500 // scale))
    print("| part | work | errors | RSS after warm-up / end (MiB) | growth | check |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        growth = 100.0 * (r["rss1"] - r["rss0"]) / r["rss0"]
        print(f"| {r['part']} | {r['work']} | {r['errors']} | {r['rss0']:.0f} / {r['rss1']:.0f} | {growth:+.1f}% "
              f"| {r['check']} |", flush=True)


if __name__ == "__main__":
    main()
