"""`crowdnav` console script: evaluate navigation policies in the crowd env, and the end-to-end demo.

    crowdnav evaluate --policy mpc-gpgraph mpc-cv --scenario plaza --episodes 50 --seed 0 --workers 2 \\
        --json out/eval/results.json --out out/eval
    crowdnav demo [--out out/demo]
    crowdnav policies | crowdnav scenarios
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from envs.config import REPLAY_SCENARIO, CrowdNavConfig

DEMO_POLICY = "mpc-gpgraph"
DEMO_SCENARIO = "plaza"
DEMO_PEDESTRIANS = 24
DEMO_EPISODES = 10


def policy_names() -> list[str]:
    from envs.policies import POLICIES

    return list(POLICIES)


def scenario_names() -> list[str]:
    from crowdsim import SCENARIOS

    return [*sorted(SCENARIOS), REPLAY_SCENARIO]


def _default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="crowdnav", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    e = sub.add_parser("evaluate", help="run policies over fixed episode seeds and report the metrics")
    e.add_argument("--policy", nargs="+", required=True, metavar="NAME", help="one or more of: "
                   + ", ".join(policy_names()))
    e.add_argument("--scenario", default="plaza", help="one of: " + ", ".join(scenario_names()))
    e.add_argument("--episodes", type=int, default=20, help="episodes (seeds seed .. seed + episodes - 1)")
    e.add_argument("--seed", type=int, default=0, help="first episode seed")
    e.add_argument("--workers", type=int, default=_default_workers(), help="processes (1: in this process)")
    e.add_argument("--json", type=Path, default=None, metavar="OUT",
                   help="JSON path of the results (several policies: one entry per policy)")
    e.add_argument("--out", type=Path, default=Path("out/eval"), metavar="DIR",
                   help="folder for <policy>.json/.md/.png, recordings and the comparison (default out/eval)")
    e.add_argument("--pedestrians", type=int, default=None, help="crowd size (default 24)")
    e.add_argument("--invisible", action="store_true", help="pedestrians do not see the robot")
    e.add_argument("--time-limit", type=float, default=None, metavar="S", help="episode time limit, s (default 40)")
    e.add_argument("--record", type=int, default=2, metavar="R", help="rerun recordings of the first R episodes")
    e.add_argument("--predictor", default=None, metavar="NAME",
                   help="mpc-gpgraph only: predictor name or checkpoint instead of the shipped default")
    e.add_argument("--replay-file", type=Path, default=None, metavar="PATH",
                   help="scenario replay: ETH/UCY-format trajectory file (frame ped x y)")
    e.add_argument("--groups-file", type=Path, default=None, metavar="PATH",
                   help="scenario replay: group file (one group of ped ids per line)")
    e.add_argument("--no-progress", action="store_true", help="no progress bar")
    e.set_defaults(subparser=e)

    d = sub.add_parser("demo", help="a grouped crowd, GP-Graph prediction and the MPC robot, end to end")
    d.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR")
    d.add_argument("--episodes", type=int, default=DEMO_EPISODES)
    d.add_argument("--workers", type=int, default=_default_workers())
    d.add_argument("--predictor", default=None, metavar="NAME", help="instead of the shipped GP-Graph")
    d.add_argument("--no-progress", action="store_true", help="no progress bar")
    d.set_defaults(subparser=d)

    sub.add_parser("policies", help="list the policy names")
    sub.add_parser("scenarios", help="list the scenario names")
    return parser


def _config(args: argparse.Namespace, parser: argparse.ArgumentParser) -> CrowdNavConfig:
    if args.scenario not in scenario_names():
        parser.error(f"unknown scenario {args.scenario!r}; valid names: {', '.join(scenario_names())}")
    kw: dict[str, Any] = {"scenario": args.scenario, "robot_visible": not args.invisible}
    if args.pedestrians is not None:
        kw["n_pedestrians"] = args.pedestrians
        if args.pedestrians >= 1:  # a small crowd caps the group size (as `crowdsim generate` does)
            from crowdsim import GroupConfig

            kw["groups"] = replace(GroupConfig(), max_size=min(GroupConfig().max_size, args.pedestrians))
    if args.time_limit is not None:
        kw["time_limit_s"] = args.time_limit
    if args.scenario == REPLAY_SCENARIO:
        if args.replay_file is None:
            parser.error("--scenario replay needs --replay-file PATH")
        from envs.replay import ReplayConfig

        try:
            kw["replay"] = ReplayConfig(path=args.replay_file, groups_path=args.groups_file)
        except ValueError as exc:
            parser.error(str(exc))
    elif args.replay_file is not None or args.groups_file is not None:
        parser.error("--replay-file/--groups-file need --scenario replay")
    try:
        config = CrowdNavConfig(**kw)
        if config.scenario != REPLAY_SCENARIO:
            config.sim_config()  # validates the crowd settings before any worker starts
        return config
    except ValueError as exc:
        parser.error(str(exc))
        raise  # unreachable: parser.error exits


def _fail(exc: BaseException) -> int:
    print(f"crowdnav: error: {exc}", file=sys.stderr)
    return 1


def _evaluate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from envs.evaluate import compare, compare_json, compare_png, evaluate, markdown_table, write_json_atomic

    valid = policy_names()
    unknown = [p for p in args.policy if p not in valid]
    if unknown:
        parser.error(f"unknown policy {', '.join(map(repr, unknown))}; valid names: {', '.join(valid)}")
    if len(set(args.policy)) != len(args.policy):
        parser.error("a policy is named twice")
    for name in ("episodes", "workers"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1")
    if args.seed < 0 or args.record < 0:
        parser.error("--seed and --record must be >= 0")
    config = _config(args, parser)
    results = []
    try:
        for name in args.policy:
            result = evaluate(name, config, args.episodes, args.seed, args.workers, args.record, args.out,
                              predictor=args.predictor, progress=not args.no_progress)
            results.append(result)
            print(markdown_table(result), end="\n\n", flush=True)
    except (ValueError, OSError) as exc:
        return _fail(exc)
    if len(results) > 1:
        table = compare(results)
        print(table)
        from envs.evaluate import write_text_atomic

        write_text_atomic(args.out / "comparison.md", table + "\n")
        write_json_atomic(args.out / "comparison.json", compare_json(results))
        compare_png(results, args.out / "comparison.png")
    if args.json is not None:
        write_json_atomic(args.json, results[0] if len(results) == 1 else compare_json(results))
    return 0


def _demo(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from envs.evaluate import evaluate, markdown_table, write_json_atomic

    if args.episodes < 1 or args.workers < 1:
        parser.error("--episodes and --workers must be >= 1")
    config = CrowdNavConfig(scenario=DEMO_SCENARIO, n_pedestrians=DEMO_PEDESTRIANS, robot_visible=True)
    start = time.perf_counter()
    print(f"crowdnav demo: {DEMO_POLICY} on {DEMO_SCENARIO}, {DEMO_PEDESTRIANS} pedestrians in groups, "
          f"{args.episodes} episodes, {args.workers} workers", flush=True)
    try:
        result = evaluate(DEMO_POLICY, config, args.episodes, 0, args.workers, 1, args.out,
                          predictor=args.predictor, stem="demo", progress=not args.no_progress)
    except (ValueError, OSError) as exc:
        return _fail(exc)
    out = Path(args.out)
    os.replace(out / "demo_seed0.rrd", out / "demo.rrd")
    result["run"]["files"] = ["demo.json", "demo.md", "demo.png", "demo.rrd"]
    write_json_atomic(out / "demo.json", result)
    print(markdown_table(result))
    print(f"\nwrote {out / 'demo.json'}, {out / 'demo.md'}, {out / 'demo.png'}, {out / 'demo.rrd'} "
          f"(view with: rerun {out / 'demo.rrd'}) in {time.perf_counter() - start:.1f} s")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "policies":
        print("\n".join(policy_names()))
        return 0
    if args.command == "scenarios":
        print("\n".join(scenario_names()))
        return 0
    if args.command == "evaluate":
        return _evaluate(args, args.subparser)
    return _demo(args, args.subparser)


if __name__ == "__main__":
    sys.exit(main())
