"""Can any robot get through a door cell? The robot's direction forced, the door's options changed, any policy.

A door cell's robot goes in or out at random (`envs.crowds.crowd.door_route`); this runs a crowdnav-tune door cell's
episodes with the direction fixed ("in": against the evacuating crowd, "out": with it) and the scenario's options
replaced (e.g. '{"door_m": 2.0, "continuous": 0}'), and prints the outcomes (collisions with who was at fault). With
`--policy mpc-oracle` it says what the planner's formulation can do with a perfect prediction. `--occupancy` instead
parks the robot out of the way and prints how many people stand in the door and its passage, and how often nobody.
For tuning suites only (the seeds are the cell's own, 1000 on).

    .venv/bin/python scripts/door_feasibility.py tune-door-low-visible --direction in --policy mpc-oracle \
        --options '{"door_m": 2.0, "continuous": 0}'
    .venv/bin/python scripts/door_feasibility.py tune-door-high-invisible --occupancy --options '{"door_m": 1.0}'
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from dataclasses import replace

import numpy as np

from envs import CrowdNavEnv
from envs.evaluation.suite import load_suite
from envs.policies import PolicyConfig, decide, make_policy


def _swap_if(env: CrowdNavEnv, direction: str, door_x: float) -> None:
    """Swap the robot's start and goal when its route runs the other way (inwards: the goal is in the room)."""
    inwards = env.goal[0] < door_x
    if (direction == "in") != inwards:
        start = env.robot_state[:2].copy()
        env.robot_state[:2], env.goal = env.goal.copy(), start
        d = env.goal - env.robot_state[:2]
        env.robot_state[2] = np.arctan2(d[1], d[0])


def outcomes(cell, direction: str, policy: str, episodes: int) -> Counter:
    out: Counter = Counter()
    door_x = float(dict(cell.spec.get("options", {})).get("room_m", 8.0))
    for seed in cell.seeds[:episodes]:
        env = CrowdNavEnv(cell.env_config(seed))
        pol = make_policy(PolicyConfig(policy), env)
        env.reset(seed=seed)
        pol.reset(seed)
        _swap_if(env, direction, door_x)
        done, info = False, {}
        while not done:
            _, _, term, trunc, info = env.step_decision(decide(pol, env))
            done = term or trunc
        m = info["episode_metrics"]
        out[m["outcome"] + (f" ({m['at_fault']} at fault)" if m["at_fault"] else "")] += 1
    return out


def occupancy(cell, episodes: int, steps: int = 300) -> list[tuple[float, float]]:
    """Per episode: the mean number of people in the door and its passage, and the fraction of steps with nobody."""
    opts = dict(cell.spec.get("options", {}))
    room, door = float(opts.get("room_m", 8.0)), float(opts.get("door_m", 1.0))
    rows = []
    for seed in cell.seeds[:episodes]:
        env = CrowdNavEnv(replace(cell.env_config(seed), robot_visible=False))
        env.reset(seed=seed)
        env.robot_state[:2] = [-50.0, -50.0]  # out of the way (and unseen)
        counts = []
        for _ in range(steps):
            env.step_control(np.zeros(2))
            p = env.pedestrians().pos
            inside = (p[:, 0] > room - 0.5) & (p[:, 0] < room + 2.5) & (np.abs(p[:, 1] - room / 2) < door / 2)
            counts.append(int(inside.sum()))
            if env.metrics.outcome:
                break
        rows.append((float(np.mean(counts)), float(np.mean(np.array(counts) == 0))))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("cell", help="a door cell of crowdnav-tune")
    ap.add_argument("--direction", choices=("in", "out"), default="in")
    ap.add_argument("--policy", default="mpc-oracle")
    ap.add_argument("--options", default="{}", help="JSON: the bottleneck scenario's options for this run")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--occupancy", action="store_true", help="measure the door's occupancy instead")
    args = ap.parse_args(argv)
    try:
        cell = load_suite("crowdnav-tune").cell(args.cell)
        if cell.spec.get("scenario") != "bottleneck":
            raise ValueError(f"{args.cell} is not a door cell")
        options = json.loads(args.options)
        if not isinstance(options, dict):
            raise ValueError("--options must be a JSON object")
        cell = replace(cell, spec={**cell.spec, "options": options})
        cell.env_config(cell.seeds[0]).sim_config()  # validates the options
        if args.episodes < 1:
            raise ValueError("--episodes must be >= 1")
    except (ValueError, json.JSONDecodeError) as exc:
        print(f"door_feasibility: {exc}", file=sys.stderr)
        return 2
    if args.occupancy:
        rows = occupancy(cell, args.episodes)
        print(f"{args.cell} {options}: people in the door and passage (mean), share of steps with nobody:",
              ", ".join(f"{m:.2f} / {e:.2f}" for m, e in rows))
    else:
        print(f"{args.cell} {options} robot {args.direction} ({args.policy}):",
              dict(outcomes(cell, args.direction, args.policy, args.episodes)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
