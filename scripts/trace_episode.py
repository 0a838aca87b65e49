"""Trace one benchmark episode of an MPC policy: every re-plan in a time window, one line each.

Per re-plan: time, robot pose and speed, the solve's status and fallback, whether the safety shield replaced the
plan's control (and the risk it saw), the plan's largest clearance violation (slack, m), the applied control, the
plan's end point, the subgoal (the goal or the route's carrot), how many passing options were solved (guidance), and
the three nearest pedestrians (centre distance, position, velocity). Then the outcome, with the share of the
episode's plans the shield replaced and that carried slack, overall and in the last 3 s. This is how the failures in
docs/decisions/planner-settings.md were found (e.g. plans that ended behind a corridor wall). For tuning suites and
cells; it reads nothing a policy may not.

    .venv/bin/python scripts/trace_episode.py crowdnav-tune tune-corridor-low-visible 1009 --policy mpc-oracle \
        --from 2 --to 10
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from envs import CrowdNavEnv
from envs.cli import build_parser
from envs.cli_options import policy_configs
from envs.evaluation.suite import load_suite
from envs.policies import decide, make_policy

SLACK_M = 0.05  # a plan counts as infeasible at its clearances above this slack, m
LAST_S = 3.0  # the summary's closing window, s


def _line(t: float, robot: np.ndarray, result: Any, peds: Any) -> str:
    near = ""
    if len(peds.pos):
        dist = np.linalg.norm(peds.pos - robot[:2], axis=1)
        near = " ".join(f"[{dist[i]:.2f} @({peds.pos[i, 0]:.1f},{peds.pos[i, 1]:.1f}) "
                        f"v({peds.vel[i, 0]:.1f},{peds.vel[i, 1]:.1f})]" for i in np.argsort(dist)[:3])
    sub = "-" if result.subgoal is None else f"({result.subgoal[0]:.1f},{result.subgoal[1]:.1f})"
    speed = robot[3] if len(robot) > 4 else float(np.hypot(robot[2], robot[3]))
    return (f"t={t:5.1f} robot=({robot[0]:5.2f},{robot[1]:5.2f}) v={speed:4.2f} {result.status:13s} "
            f"fallback={result.fallback or '-':13s} shield={'yes' if result.shielded else 'no ':3s} "
            f"risk={result.shield_risk:.2f} slack={result.max_slack_m:5.2f} u={np.round(result.control, 2)} "
            f"end=({result.states[-1, 0]:.1f},{result.states[-1, 1]:.1f}) sub={sub} opts={len(result.options)} "
            f"| {near}")


def trace(suite: str, cell_name: str, seed: int, policy: str, t_from: float, t_to: float,
          mpc: Sequence[str] = ()) -> str:
    """Run the episode, print the re-plans between t_from and t_to (s); returns the outcome line. The policy is
    configured as `crowdnav benchmark` configures it in that cell: the suite's planner settings, `mpc` (FIELD=VALUE
    items, as its --mpc) over them, and the cell's predictor."""
    loaded = load_suite(suite)
    cell = loaded.cell(cell_name)
    args = build_parser().parse_args(["evaluate", "--policy", policy,
                                      *(arg for item in mpc for arg in ("--mpc", item))])
    (pcfg,) = policy_configs(args, loaded)
    cfg = cell.env_config(seed)
    env = CrowdNavEnv(cfg)
    pol = make_policy(pcfg.for_cell(cell.scene, cell.predictor), env)
    planner = getattr(pol, "planner", None)
    if planner is None or not hasattr(planner, "plan"):
        raise ValueError(f"{policy} has no planner to trace; MPC policies only (mpc-gpgraph, mpc-oracle, mpc-cv, ...)")
    results: list[Any] = []
    plan = planner.plan

    def recorded(*args: Any, **kwargs: Any) -> Any:
        results.append(plan(*args, **kwargs))
        return results[-1]

    planner.plan = recorded
    env.reset(seed=seed)
    pol.reset(seed)
    done, step, info, times = False, 0, {}, []
    while not done:
        robot, peds, before = env.robot_state.copy(), env.pedestrians(), len(results)
        decision = decide(pol, env)
        if len(results) > before:
            times.append(step * cfg.dt_s)
            if t_from <= step * cfg.dt_s <= t_to:
                print(_line(step * cfg.dt_s, robot, results[-1], peds))
        _, _, term, trunc, info = env.step_decision(decision)
        done, step = term or trunc, step + 1
    m = info["episode_metrics"]
    outcome = f"{m['outcome']} at {m['time_s']:.1f} s" + (f" ({m['at_fault']} at fault)" if m["at_fault"] else "")
    return outcome + _summary(np.array(times), results, step * cfg.dt_s)


def _summary(times: np.ndarray, results: list[Any], end_s: float) -> str:
    """" | N plans: shield F (last 3 s: F3), slack > 0.05 m S (last 3 s: S3)": the fractions of the episode's plans
    whose first control the shield replaced and that carried more than SLACK_M of slack, over the whole episode and
    its last LAST_S seconds (docs/decisions/planner-guidance.md, "The shield's share of control")."""
    if not results:
        return " | 0 plans"
    shielded = np.array([r.shielded for r in results], float)
    slack = np.array([r.max_slack_m > SLACK_M for r in results], float)
    last = times >= end_s - LAST_S
    window = f"last {LAST_S:.0f} s"
    return (f" | {len(results)} plans: shield {shielded.mean():.2f} ({window}: {shielded[last].mean():.2f}), "
            f"slack > {SLACK_M} m {slack.mean():.2f} ({window}: {slack[last].mean():.2f})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("suite")
    ap.add_argument("cell")
    ap.add_argument("seed", type=int)
    ap.add_argument("--policy", default="mpc-gpgraph")
    ap.add_argument("--from", dest="t_from", type=float, default=0.0, help="first time to print, s")
    ap.add_argument("--to", dest="t_to", type=float, default=float("inf"), help="last time to print, s")
    ap.add_argument("--mpc", action="append", default=[], metavar="FIELD=VALUE", help="as in crowdnav benchmark")
    args = ap.parse_args(argv)
    try:
        cell = load_suite(args.suite).cell(args.cell)
        if args.seed not in cell.seeds:
            raise ValueError(f"seed {args.seed} is not one of {args.cell}'s seeds ({cell.seeds[0]}..{cell.seeds[-1]})")
        if not args.t_from <= args.t_to:
            raise ValueError("--from must not be after --to")
        print(trace(args.suite, args.cell, args.seed, args.policy, args.t_from, args.t_to, args.mpc))
    except ValueError as exc:
        print(f"trace_episode: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
