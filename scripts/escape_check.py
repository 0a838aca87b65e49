"""Re-run a benchmark run's pedestrian collisions and say, for each, whether the robot could have escaped it.

For every record of RECORDS (a `crowdnav benchmark` run's records.jsonl) that ended in a collision with a pedestrian,
the episode is run again with the same policy (deterministic with the suites' seeds when no solve hits its wall-clock
budget: pass `--mpc time_budget_s=10` as the run did, if it did), and the script prints when the touched pedestrian
first appeared (seconds before the contact, and how far from the robot), and `escape_clearance`
(envs/scoring/escape.py): the largest clearance a constant command held from that moment would have kept, knowing
the pedestrian's future. Negative: no constant command escapes (people who enter a replayed recording a metre from
the robot). A summary line counts them. A re-run that does not end in the record's collision (outcome, or contact time
when the record has one) is flagged and left out.

    .venv/bin/python scripts/escape_check.py crowdnav-v1 out/bench/records.jsonl --policy mpc-oracle \
        --mpc time_budget_s=10
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

import numpy as np

from envs import CrowdNavEnv
from envs.cli import build_parser
from envs.cli_options import policy_configs
from envs.evaluation.suite import load_suite
from envs.policies import decide, make_policy
from envs.scoring.escape import escape_clearance

RECENT_S = 1.0  # the summary counts pedestrians first seen less than this before the contact


def rerun(loaded, pcfg, cell_name: str, seed: int) -> dict | None:
    """One episode again: the touched pedestrian's first appearance and the escape clearance from it, or None when
    the re-run does not end in a pedestrian collision."""
    cell = loaded.cell(cell_name)
    cfg = cell.env_config(seed)
    env = CrowdNavEnv(cfg)
    policy = make_policy(pcfg.for_cell(cell.scene, cell.predictor), env)
    env.reset(seed=seed)
    policy.reset(seed)
    states, seen = [env.robot_state.copy()], [_people(env)]
    info, done = {}, False
    while not done:
        _, _, terminated, truncated, info = env.step_decision(decide(policy, env))
        states.append(env.robot_state.copy())
        seen.append(_people(env))
        done = terminated or truncated
    m = info.get("episode_metrics", {})
    if not (m.get("collision") and m.get("collision_with") == "pedestrian"):
        return None
    last = seen[-1]
    pid = min(last, key=lambda i: np.hypot(*(last[i][0] - states[-1][:2])) - last[i][1])
    k0 = next(k for k, people in enumerate(seen) if pid in people)
    track = np.array([people[pid][0] for people in seen[k0:] if pid in people])
    clearance = escape_clearance(states[k0], cfg.robot, cfg.dt_s, track, last[pid][1]) if len(track) > 1 else -np.inf
    return {"at_fault": m.get("at_fault"), "contact_s": (len(states) - 1) * cfg.dt_s,
            "seen_s": (len(states) - 1 - k0) * cfg.dt_s, "seen_m": float(np.hypot(*(track[0] - states[k0][:2]))),
            "escape_m": clearance}


def _people(env: CrowdNavEnv) -> dict[int, tuple[np.ndarray, float]]:
    p = env.pedestrians()
    return {int(i): (p.pos[j].copy(), float(p.radius[j])) for j, i in enumerate(p.ped_id)}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("suite")
    parser.add_argument("records")
    parser.add_argument("--policy", required=True, help="the run's policy (the records' policy name)")
    parser.add_argument("--mpc", action="append", default=[], metavar="FIELD=VALUE", help="as the run had them")
    args = parser.parse_args(argv)
    try:
        loaded = load_suite(args.suite)
        options = [a for m in args.mpc for a in ("--mpc", m)]
        cli = build_parser().parse_args(["evaluate", "--policy", args.policy, *options])
        (pcfg,) = policy_configs(cli, loaded)
        with open(args.records) as handle:
            records = [json.loads(line) for line in handle if line.strip()]
    except (OSError, ValueError, KeyError) as exc:
        print(f"escape_check: {exc}", file=sys.stderr)
        return 2
    hits = [r for r in records if r.get("outcome") == "collision" and r.get("collision_with") == "pedestrian"
            and r.get("policy") == args.policy]
    rows = []
    for r in hits:
        out = rerun(loaded, pcfg, r["cell"], int(r["seed"]))
        recorded = r.get("collision_time_s")
        if out is None or (recorded is not None and abs(out["contact_s"] - float(recorded)) > 0.05):
            print(f"{r['cell']} {r['seed']}: the re-run did not end in the recorded pedestrian collision (left out)")
            continue
        rows.append(out)
        print(f"{r['cell']} {r['seed']} at fault {out['at_fault']}: contact at {out['contact_s']:.1f} s with someone "
              f"first seen {out['seen_s']:.1f} s before, {out['seen_m']:.2f} m away; escape clearance "
              f"{out['escape_m']:+.2f} m", flush=True)
    recent = [r for r in rows if r["seen_s"] < RECENT_S]
    print(f"{len(rows)} pedestrian collisions re-run: {len(recent)} with someone first seen < {RECENT_S:.0f} s before; "
          f"{sum(r['escape_m'] < 0 for r in rows)} not escapable by a constant command from the first sight "
          f"({sum(r['escape_m'] < 0 and r['at_fault'] != 'spawn' for r in rows)} of them counted avoidable)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
