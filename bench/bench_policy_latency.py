"""Per-decision latency of the policies in CrowdNav's settings: the PPO agent against the MPC, side by side.

Every policy runs the same episodes of the suite's cell (`--suite`: crowdnav-classic, 5 humans, with its agent
`ppo-crowdnav-classic`; crowdnav-plusplus, 20 humans and a 5 m sensor, with `ppo-crowdnav-20`; crowdnav-v1's
`--cell`, default corridor-high-visible, with the generalist `ppo-crowdnav-mix`; `--agent` names another; seeds
400000+, which no suite reports) and decides as the suite runs it: the agent at its recorded period (with the wall
rays it was trained with), `mpc-cv` and `mpc-gpgraph` re-planning every `replan_every_steps` of the suite (5 in
CrowdNav's settings, 1 in crowdnav-v1) with the suite's planner defaults. Measured: the wall time of
`envs.policies.act` at each policy's decision steps (the policy's view of the env, its predictor, its solve or
forward pass, and the action) plus, for an agent that observes predictions, the env's prediction updates since the
last decision (its predictor and calibration run in the env's step, not in `act`), one torch thread, one process.
The table gives p50 / p95 / max in ms and the ratio of each p50 and p95 to mpc-gpgraph's.

    python bench/bench_policy_latency.py              # 10 episodes per policy, about a minute
    python bench/bench_policy_latency.py --quick      # 2 episodes per policy
    python bench/bench_policy_latency.py --suite crowdnav-plusplus
    python bench/bench_policy_latency.py --suite crowdnav-v1 --cell crossing-high-visible
    python bench/bench_policy_latency.py --suite crowdnav-v1 --agent ppo-crowdnav-mix ppo-crowdnav-mix+shield
    python bench/bench_policy_latency.py --suite crowdnav-plusplus --agent ppo-crowdnav-20 ppo-crowdnav-20+shield \
        --shield-horizon 0.5

A shielded agent (`NAME+shield`) decides every env step (the shield checks the held action each step), so all
its steps are timed; the network runs at its period inside them.
"""

from __future__ import annotations

import argparse
import platform
import time
from dataclasses import replace

import numpy as np
from env_loop import Timers  # bench/ is on sys.path when a bench script runs

from envs.env import CrowdNavEnv
from envs.evaluation.benchmark import observed
from envs.evaluation.suite import load_suite
from envs.policies import ENV_MPC, PolicyConfig, act, make_policy
from envs.policies.identity import agent_observation
from predictor import set_threads

SEED0 = 400_000
AGENTS = {"crowdnav-classic": "ppo-crowdnav-classic", "crowdnav-plusplus": "ppo-crowdnav-20",
          "crowdnav-v1": "ppo-crowdnav-mix"}  # suite -> its agent
CELLS = {"crowdnav-v1": "corridor-high-visible"}  # suite -> default cell (others: their only one)


def decision_times(suite_name: str, cell: str, name: str, episodes: int,
                   shield_horizon_s: float | None = None) -> np.ndarray:
    """Wall times (s) of `act` at the policy's decision steps of `episodes` episodes of the suite's cell; an agent's
    shield (NAME+shield) looks `shield_horizon_s` ahead (None: the MPC's)."""
    suite = load_suite(suite_name)
    agent = name.startswith(("ppo", "sb3:"))
    every = suite.replan_every_steps or 1
    shield = {} if shield_horizon_s is None else {"shield_horizon_s": shield_horizon_s}
    config = PolicyConfig(name, mpc=replace(ENV_MPC, **shield)) if agent else \
        PolicyConfig(name, mpc=suite.mpc_config(ENV_MPC), replan_every_steps=every)
    env = CrowdNavEnv(observed(suite.cell(cell).env_config(SEED0), agent_observation(config)))
    policy = make_policy(config, env)
    every = getattr(policy, "decision_every_steps", every)
    observing = Timers()  # an agent's predictor and calibration run in the env's step / reset, not in `act`
    observing.wrap(env, "_update_prediction", "predictions")
    times = []
    for seed in range(SEED0, SEED0 + episodes):
        observing.take()  # the last episode's final update is nobody's decision
        env.reset(seed=seed)
        policy.reset(seed)
        step, done = 0, False
        while not done:
            start = time.perf_counter()
            action = act(policy, env)
            if step % every == 0:
                times.append(time.perf_counter() - start + observing.take()["predictions"])
            done = any(env.step(action)[2:4])
            step += 1
    return np.array(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="2 episodes per policy")
    ap.add_argument("--suite", choices=sorted(AGENTS), default="crowdnav-classic", help="the setting and its agent")
    ap.add_argument("--cell", default=None, help="the suite's cell (default: crowdnav-v1 corridor-high-visible, "
                                                   "else the suite's first)")
    ap.add_argument("--agent", nargs="+", default=None,
                    help="the agents (registry names or sb3:PATH.zip, each optionally NAME+shield; default: the "
                         "suite's)")
    ap.add_argument("--shield-horizon", type=float, default=None, metavar="S",
                    help="look-ahead of an agent's shield (NAME+shield), s (default: the MPC's, 1.6)")
    args = ap.parse_args(argv)
    set_threads(1)
    episodes = 2 if args.quick else 10
    cell = args.cell or CELLS.get(args.suite) or load_suite(args.suite).cells[0].name
    rows = {name: decision_times(args.suite, cell, name, episodes, args.shield_horizon) * 1e3
            for name in (*(args.agent or [AGENTS[args.suite]]), "mpc-cv", "mpc-gpgraph")}
    ref = rows["mpc-gpgraph"]
    print(f"{args.suite} {cell}, {episodes} episodes per policy (seeds {SEED0}+), one thread; "
          f"{platform.processor() or 'cpu'}, Python {platform.python_version()}")
    print("| policy | decisions | p50 (ms) | p95 (ms) | max (ms) | p50 / mpc-gpgraph | p95 / mpc-gpgraph |")
    print("|---|---|---|---|---|---|---|")
    for name, t in rows.items():
        p50, p95 = np.percentile(t, 50), np.percentile(t, 95)
        print(f"| {name} | {len(t)} | {p50:.2f} | {p95:.2f} | {t.max():.2f} | {p50 / np.percentile(ref, 50):.3f} | "
              f"{p95 / np.percentile(ref, 95):.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
