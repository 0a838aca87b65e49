"""The MPC's solve with its NLP compiled (planner/jit.py) against CasADi's virtual machine, on the same problems.

mpc-gpgraph drives `--episodes` episodes of a crowdnav-v1 cell (default corridor-high-visible, the densest walled
one; seeds 400000+, which no suite reports) with the suite's planner settings; every solver call's inputs (initial
guess, parameters, bounds) are recorded. Then both solvers solve every recorded problem, alternating call by call
so that the machine's drift hits both alike. The table gives the solver call's p50 / p95 / max (ms) for each, the
ratio, and how many solutions are the same bit for bit (all of them, or the compiled solver is wrong).

    python bench/bench_mpc_jit.py               # 3 episodes, ~1,000 solves, about 3 minutes plus one compile
    python bench/bench_mpc_jit.py --quick       # 1 episode
    python bench/bench_mpc_jit.py --cell crossing-high-invisible
    python bench/bench_mpc_jit.py --flags=-O2   # also the NLP compiled with other compiler flags, side by side

The compiled solver comes from the cache (`CROWDNAV_CACHE_DIR`) or is compiled first (~30 s, not timed).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from dataclasses import replace

import casadi as ca
import numpy as np

from bench.bench_policy_latency import SEED0
from envs.env import CrowdNavEnv
from envs.evaluation.suite import load_suite
from envs.policies import ENV_MPC, PolicyConfig, act, make_policy
from planner import jit
from planner.mpc import shared_ocp
from predictor import set_threads


class _Recorder:
    """Stands in for the OCP's solver: records each call's inputs, then solves."""

    def __init__(self, solver: ca.Function) -> None:
        self.solver, self.calls = solver, []

    def __call__(self, **kwargs):
        self.calls.append({k: np.array(v, float) for k, v in kwargs.items()})
        return self.solver(**kwargs)

    def stats(self) -> dict:
        return self.solver.stats()


def record_problems(cell: str, episodes: int) -> tuple[list[dict], object]:
    """The solver inputs of mpc-gpgraph's plans in `episodes` episodes of the cell, and the MPC config."""
    suite = load_suite("crowdnav-v1")
    every = suite.replan_every_steps or 1
    config = PolicyConfig("mpc-gpgraph", mpc=suite.mpc_config(ENV_MPC), replan_every_steps=every)
    env = CrowdNavEnv(suite.cell(cell).env_config(SEED0))
    policy = make_policy(config, env)
    recorder = _Recorder(policy.planner.ocp.solver)
    policy.planner.ocp = replace(policy.planner.ocp, solver=recorder)
    for seed in range(SEED0, SEED0 + episodes):
        env.reset(seed=seed)
        policy.reset(seed)
        done = False
        while not done:
            done = any(env.step(act(policy, env))[2:4])
    return recorder.calls, config.mpc


def solvers(mpc, flags: tuple[str, ...] | None = None) -> dict[str, ca.Function]:
    """The virtual-machine solver and the compiled one for `mpc` (and, with `flags`, one compiled with those compiler
    flags instead of `jit.FLAGS`), by name."""
    built, default = {}, jit.FLAGS
    runs = [("virtual machine", "off", default), ("compiled", "on", default)]
    if flags:
        runs.append((f"compiled {' '.join(flags)}", "on", flags))
    try:
        for name, mode, use in runs:
            os.environ[jit.JIT_ENV], jit.FLAGS = mode, tuple(use)
            shared_ocp.cache_clear()
            built[name] = shared_ocp(mpc).solver
    finally:
        jit.FLAGS = default
        shared_ocp.cache_clear()
    return built


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="1 episode")
    ap.add_argument("--episodes", type=int, default=3)
    ap.add_argument("--cell", default="corridor-high-visible", help="a crowdnav-v1 cell")
    ap.add_argument("--flags", default=None, metavar="'FLAG ...'",
                    help=f"also compile with these C compiler flags, e.g. --flags=-O2 (default build: "
                         f"{' '.join(jit.FLAGS)})")
    args = ap.parse_args(argv)
    if jit.compiler() is None:
        raise SystemExit("bench_mpc_jit: no C compiler (gcc or cc) on PATH: nothing to compare")
    set_threads(1)
    previous = os.environ.get(jit.JIT_ENV)
    os.environ[jit.JIT_ENV] = "off"  # record on the virtual machine
    calls, mpc = record_problems(args.cell, 1 if args.quick else args.episodes)
    built = solvers(mpc, tuple(args.flags.split()) if args.flags else None)
    if previous is None:
        os.environ.pop(jit.JIT_ENV)
    times = {name: [] for name in built}
    same = dict.fromkeys(built, 0)
    for call in calls:
        out = {}
        for name, solver in built.items():
            start = time.perf_counter()
            out[name] = solver(**call)["x"].full()
            times[name].append(time.perf_counter() - start)
        for name in built:
            same[name] += int(np.array_equal(out["virtual machine"], out[name]))
    print(f"crowdnav-v1 {args.cell}, mpc-gpgraph's {len(calls)} solver calls ({1 if args.quick else args.episodes} "
          f"episodes, seeds {SEED0}+), each solved by every solver in turn; {platform.processor() or 'cpu'}, "
          f"Python {platform.python_version()}, CasADi {ca.__version__}")
    print("| solver | p50 (ms) | p95 (ms) | max (ms) | p50 / VM | p95 / VM "
          "| solutions equal to the VM's, bit for bit |")
    print("|---|---|---|---|---|---|---|")
    ref = np.array(times["virtual machine"]) * 1e3
    for name, t in times.items():
        t = np.array(t) * 1e3
        equal = "(the reference)" if name == "virtual machine" else f"{same[name]} of {len(calls)}"
        p50, p95 = np.percentile(t, 50), np.percentile(t, 95)
        print(f"| {name} | {p50:.2f} | {p95:.2f} | {t.max():.2f} | {p50 / np.percentile(ref, 50):.3f} | "
              f"{p95 / np.percentile(ref, 95):.3f} | {equal} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
