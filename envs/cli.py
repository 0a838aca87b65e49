"""`crowdnav` console script: evaluate policies, run a benchmark suite, and the end-to-end demo.

    crowdnav evaluate --policy mpc-gpgraph mpc-cv --scenario plaza --episodes 50 --seed 0 --out out/eval
    crowdnav benchmark --suite crowdnav-v1 --policy mpc-gpgraph mpc-cv mpc-none social-force --out out/bench
    crowdnav bounds --suite crowdnav-v1 --out out/bench   (what any robot could do, read by the leaderboard)
    crowdnav demo [--out out/demo]
    crowdnav train --scenario circle_crossing --pedestrians 5 --invisible --warm-start bc --out out/train/cc5
    crowdnav policies | scenarios | suites

Misuse (an unknown name, a bad value, an unwritable output path, a flag the chosen policy ignores) prints one
line on stderr and exits 2 before any episode runs. Ctrl-C prints one line saying what was kept and exits 130
(benchmark: every finished episode; the same command resumes).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from crowdsim.cli import OneLineParser, console_script, show_defaults  # the CLI conventions, shared with crowdsim
from crowdsim.names import flag_values, os_error_line, unknown_name
from crowdsim.scenarios import is_scenario_file
from envs.cli_options import (
    OBSERVATION_POLICIES,
    add_backend_options,
    add_policy_options,
    add_video_options,
    check_backend,
    check_env_flags,
    check_input_files,
    check_video_flags,
    default_workers,
    ignored_flag,
    policy_configs,
    reads_observation,
    replay_predictors,
)
from envs.config import REPLAY_SCENARIO, CrowdNavConfig
from envs.evaluation.suite import DEFAULT_DATA
from envs.rl import train as train_module

DEMO_POLICY = "mpc-gpgraph"
DEMO_SCENARIO = "plaza"
DEMO_PEDESTRIANS = 24
DEMO_EPISODES = 10
FMT = argparse.ArgumentDefaultsHelpFormatter


class UsageError(Exception):
    """A misuse of the command line: reported as one line, exit 2."""


def scenario_names() -> list[str]:
    from crowdsim import SCENARIOS

    return [*sorted(SCENARIOS), REPLAY_SCENARIO]


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="crowdnav", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    e = sub.add_parser("evaluate", help="run policies over fixed episode seeds and report the metrics",
                       formatter_class=FMT)
    add_policy_options(e)
    e.add_argument("--scenario", default="plaza", metavar="NAME|PATH.toml",
                   help="one of: " + ", ".join(scenario_names()) + "; or a scenario file (docs/crowdsim.md)")
    e.add_argument("--episodes", type=int, default=20, help="episodes (seeds seed .. seed + episodes - 1)")
    e.add_argument("--seed", type=int, default=0, help="first episode seed")
    e.add_argument("--json", type=Path, default=None, metavar="OUT",
                   help="also write the results JSON here (several policies: one entry per policy)")
    e.add_argument("--out", type=Path, default=Path("out/eval"), metavar="DIR",
                   help="folder for <policy>.json/.md/.png, recordings and the comparison")
    e.add_argument("--pedestrians", type=int, default=None, help="crowd size (simulated scenarios; default 24)")
    e.add_argument("--invisible", action="store_true", help="pedestrians do not see the robot (simulated scenarios)")
    e.add_argument("--crowd-model", default=None, metavar="NAME",
                   help="simulated pedestrians: social-force (default) or orca (CrowdNav's ORCA humans, scenario "
                   "circle_crossing, env step 0.05 s; needs pyrvo)")
    e.add_argument("--time-limit", type=float, default=None, metavar="S", help="episode time limit, s (default 40)")
    e.add_argument("--wall-rays", type=int, default=None, metavar="R",
                   help="observe R range rays to the walls (for agents trained with crowdnav train --wall-rays R)")
    e.add_argument("--fov-deg", type=float, default=None, metavar="DEG",
                   help="the robot's field of view around its heading, degrees in (0, 360] (default 360: all round); "
                   "people outside it are hidden from every policy (ObservationConfig.fov_deg, docs/envs.md)")
    e.add_argument("--occlusion", action="store_true",
                   help="walls and people's bodies hide the people behind them from every policy "
                   "(ObservationConfig.occlusion)")
    e.add_argument("--record", type=int, default=0, metavar="R",
                   help="rerun recordings (.rrd) of the first R episodes (about 11 MB per plaza episode)")
    add_video_options(e)
    e.add_argument("--replay-file", type=Path, default=None, metavar="PATH",
                   help="scenario replay: ETH/UCY-format trajectory file (frame ped x y)")
    e.add_argument("--frame-step", type=float, default=None, metavar="S",
                   help="scenario replay: seconds per annotation step (default: the known ETH/UCY recording's "
                   "own by file name, biwi_eth 0.6667 and the others 0.4; any other file 0.4)")
    e.add_argument("--groups-file", type=Path, default=None, metavar="PATH",
                   help="scenario replay: group file (one group of ped ids per line)")
    e.add_argument("--group-overlaps", choices=("error", "merge"), default=None,
                   help="scenario replay: a pedestrian listed on two lines of --groups-file is an error (default), "
                   "or merges those groups (each merge is named on stderr)")
    add_backend_options(e)

    b = sub.add_parser("benchmark", help="run policies on every episode of a named suite; leaderboard and "
                       "paired comparisons", formatter_class=FMT)
    b.add_argument("--suite", required=True, help="suite name (crowdnav suites lists them)")
    b.add_argument("--cells", default=None, metavar="A,B", help="comma-separated cells of the suite (default all)")
    b.add_argument("--first-episodes", type=int, default=None, metavar="N",
                   help="a partial run: only the first N episodes (seeds) of each cell; the records are the full "
                   "run's, so the same command without it (same --out) adds the rest")
    add_policy_options(b, required=False)
    b.set_defaults(policy=None)
    b.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="records.jsonl and leaderboard.json/.md/.png; rerun with the same DIR to resume")
    b.add_argument("--data", type=Path, default=DEFAULT_DATA, metavar="DIR",
                   help="ETH/UCY folder (eth/, hotel/, univ/, zara1/, zara2/) for the real cells")
    b.add_argument("--merge", type=Path, nargs="+", action="extend", default=[], metavar="RECORDS",
                   help="records.jsonl files from other runs or machines to merge into the leaderboard")
    add_backend_options(b)

    r = sub.add_parser("bounds", help="what any robot could do: reachable-set bounds on every episode whose crowd "
                       "ignores the robot (envs.evaluation.reachability); the benchmark's leaderboard in the same "
                       "--out folder classes each failure by them", formatter_class=FMT)
    r.add_argument("--suite", required=True, help="suite name (crowdnav suites lists them)")
    r.add_argument("--cells", default=None, metavar="A,B", help="comma-separated cells of the suite (default all)")
    r.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="bounds.jsonl and bounds.md; rerun with the same DIR to resume")
    r.add_argument("--data", type=Path, default=DEFAULT_DATA, metavar="DIR", help="ETH/UCY folder for the real cells")
    r.add_argument("--cells-per-step", type=int, default=5, metavar="N",
                   help="grid cells per robot step at full speed (finer: tighter bounds, slower)")
    r.add_argument("--optimistic-dt", type=float, default=None, metavar="S",
                   help="how often the optimistic set is checked against the people, s (a multiple of the env step; "
                   "default: the smallest multiple >= 0.2 s)")
    r.add_argument("--workers", type=int, default=default_workers())
    r.add_argument("--no-progress", action="store_true", help="no progress bar")

    d = sub.add_parser("demo", help="a grouped crowd, GP-Graph prediction and the MPC robot, end to end",
                       formatter_class=FMT)
    d.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR")
    d.add_argument("--episodes", type=int, default=DEMO_EPISODES)
    d.add_argument("--workers", type=int, default=default_workers())
    d.add_argument("--predictor", default=None, metavar="NAME", help="instead of the shipped GP-Graph")
    d.add_argument("--no-progress", action="store_true", help="no progress bar")

    t = sub.add_parser("train", help="train a PPO agent (envs.rl.train; needs the 'rl' extra)",
                       description=train_module.__doc__.splitlines()[0] + " (python -m envs.rl.train --help: details)")
    train_module.add_arguments(t)

    for name, text in (("policies", "list the policy names"), ("scenarios", "list the scenario names"),
                       ("suites", "list the benchmark suites and their cells")):
        sub.add_parser(name, help=text)
    for command in sub.choices.values():
        show_defaults(command)
    return parser


def _config(args: argparse.Namespace) -> CrowdNavConfig:
    if args.scenario not in scenario_names() and not is_scenario_file(args.scenario):
        raise UsageError(unknown_name("scenario", args.scenario, scenario_names()) + "; or a .toml scenario file")
    replay = args.scenario == REPLAY_SCENARIO
    kw: dict[str, Any] = {"scenario": args.scenario}
    if replay:
        if args.replay_file is None:
            raise UsageError("--scenario replay needs --replay-file PATH")
        if args.pedestrians is not None or args.invisible:
            raise UsageError("--pedestrians and --invisible do not apply to --scenario replay (recorded people)")
        from envs.crowds.replay import ReplayConfig

        if args.group_overlaps is not None and args.groups_file is None:
            raise UsageError("--group-overlaps needs --groups-file")
        check_input_files(args)
        kw["replay"] = ReplayConfig(path=args.replay_file, groups_path=args.groups_file, frame_step_s=args.frame_step,
                                    group_overlaps=args.group_overlaps or "error")
    elif args.replay_file is not None or args.groups_file is not None or args.frame_step is not None \
            or args.group_overlaps is not None:
        raise UsageError("--replay-file/--groups-file/--frame-step/--group-overlaps need --scenario replay")
    else:
        kw["robot_visible"] = not args.invisible
    if args.pedestrians is not None:
        from crowdsim import GroupConfig

        kw["n_pedestrians"] = args.pedestrians
        kw["groups"] = replace(GroupConfig(), max_size=max(1, min(GroupConfig().max_size, args.pedestrians)))
    if args.time_limit is not None:
        kw["time_limit_s"] = args.time_limit
    if args.crowd_model is not None:
        kw["crowd_model"] = args.crowd_model
        if args.crowd_model == "orca":
            kw["dt_s"] = 0.05  # divides both ORCA's 0.25 s step and the predictor's 0.4 s (envs.crowds.orca)
    seen = {"wall_rays": args.wall_rays, "fov_deg": args.fov_deg, "occlusion": args.occlusion or None}
    if any(v is not None for v in seen.values()):
        from envs.config import ObservationConfig

        kw["observation"] = ObservationConfig(**{k: v for k, v in seen.items() if v is not None})
    config = CrowdNavConfig(**kw)
    from envs.crowds.models import DEFAULT_CROWD_MODEL, make_crowd

    if not replay:
        config.sim_config()  # validates the crowd settings before any worker starts
    if replay or config.crowd_model != DEFAULT_CROWD_MODEL:
        make_crowd(config)  # reads and checks the recording, or fails on a missing package (pyrvo), now
    return config


def _frame_step_warning(args: argparse.Namespace) -> str | None:
    """A warning when --frame-step contradicts a known recording's annotation step (`envs.crowds.replay`)."""
    if args.frame_step is None:
        return None
    from envs.crowds.replay import known_frame_step

    known = known_frame_step(args.replay_file)
    if known is None or abs(args.frame_step - known) <= 0.01 * known:
        return None
    return (f"crowdnav: warning: {args.replay_file.name} is annotated every {known} s; replaying it at "
            f"--frame-step {args.frame_step} s instead")


def _group_notes(config: CrowdNavConfig) -> tuple[str, ...]:
    """The merges of overlapping groups in a replay's group file (`--group-overlaps merge`), one line each."""
    if config.replay is None or config.replay.groups_path is None or config.replay.group_overlaps != "merge":
        return ()
    from envs.crowds.models import make_crowd

    return make_crowd(config).group_notes


def _evaluate(args: argparse.Namespace) -> int:
    from envs.atomic import check_writable_dir, check_writable_file, write_json_atomic, write_text_atomic
    from envs.evaluation.evaluate import Interrupted, check_setup, evaluate
    from envs.evaluation.report import compare, compare_json, compare_png, markdown_table

    if args.episodes < 1 or args.seed < 0 or args.record < 0:
        raise UsageError("--episodes must be >= 1, --seed and --record >= 0")
    check_video_flags(args)
    check_backend(args)
    check_env_flags(args)
    configs = policy_configs(args)
    if args.wall_rays is not None and not any(reads_observation(n) for n in args.policy):
        readers = [*OBSERVATION_POLICIES, "sb3:PATH.zip", "module:factory policies"]  # they act on the observation
        raise ignored_flag("--wall-rays", args.policy, readers)
    config = _config(args)
    configs, predictor_note = replay_predictors(args, configs)
    check_writable_dir(args.out)
    if args.json is not None:
        check_writable_file(args.json)
    seen = {pcfg: _agent_config(config, pcfg, args) for pcfg in configs}  # what each agent was trained to observe
    for pcfg in configs:  # every policy and plug-in builds before any episode runs
        check_setup(pcfg, seen[pcfg])
    if (warning := _frame_step_warning(args)) is not None:  # after every check: a misuse stays one line
        print(warning, file=sys.stderr)
    for note in _group_notes(config):
        print(f"crowdnav: warning: {note}", file=sys.stderr)
    if predictor_note is not None:
        print(predictor_note, flush=True)
    results = []
    for pcfg in configs:
        try:
            result = evaluate(pcfg, seen[pcfg], args.episodes, args.seed, args.workers, args.record, args.out,
                              progress=not args.no_progress, backend=args.backend, address=args.address, check=False,
                              video=args.video, video_format=str(args.video_format), video_size=int(args.video_size))
        except KeyboardInterrupt as exc:
            kept = (f"results of {', '.join(r['policy'] for r in results)} written to {args.out}" if results
                    else "no results written")
            done = f"{exc}; " if isinstance(exc, Interrupted) else ""
            raise Interrupted(f"interrupted: {done}{kept}; evaluate does not resume: rerun the command to start "
                              "again") from None
        results.append(result)
        print(markdown_table(result), end="\n\n", flush=True)
    if len(results) > 1:
        table = compare(results)
        print(table)
        write_text_atomic(args.out / "comparison.md", table + "\n")
        write_json_atomic(args.out / "comparison.json", compare_json(results))
        compare_png(results, args.out / "comparison.png")
    if args.json is not None:
        write_json_atomic(args.json, results[0] if len(results) == 1 else compare_json(results))
    return 0


def _agent_config(config: CrowdNavConfig, pcfg: Any, args: argparse.Namespace) -> CrowdNavConfig:
    """`config` observing what an SB3 agent was trained to observe (predictions, their calibration, wall rays:
    `envs.policies.identity.agent_observation`), as `crowdnav benchmark` does; a flag the user gave (--wall-rays) is
    kept, so that a contradiction is refused by the agent's layout check rather than overridden. Other policies:
    `config` itself."""
    from envs.evaluation.benchmark import observed
    from envs.policies.identity import agent_observation

    fields = {k: v for k, v in agent_observation(pcfg).items() if not (k == "wall_rays" and args.wall_rays is not None)}
    return observed(config, fields)


def _benchmark(args: argparse.Namespace) -> int:
    from envs.evaluation.benchmark import RECORDS, run_benchmark
    from envs.evaluation.evaluate import Interrupted
    from envs.evaluation.leaderboard import leaderboard_markdown
    from envs.evaluation.records import read_records
    from envs.evaluation.suite import load_suite

    check_backend(args)
    suite = load_suite(args.suite)
    cells = suite.select(args.cells.split(",") if args.cells else None)
    if args.first_episodes is not None:
        if args.first_episodes < 1:
            raise ValueError(f"--first-episodes must be >= 1, got {args.first_episodes}")
        cells = [replace(c, seeds=c.seeds[:args.first_episodes]) for c in cells]
    args.policy = args.policy or ["mpc-gpgraph", "mpc-cv", "mpc-none", "social-force"]
    configs = policy_configs(args, suite)
    try:
        board = run_benchmark(suite, cells, configs, args.out, data=args.data, workers=args.workers,
                              backend=args.backend, address=args.address, merge=args.merge,
                              progress=not args.no_progress)
    except KeyboardInterrupt as exc:
        if isinstance(exc, Interrupted):
            raise Interrupted(f"interrupted: {exc}") from None
        path = args.out / RECORDS  # interrupted before or after the episodes: what the records file holds
        raise Interrupted(f"interrupted: {len(read_records(path))} episodes saved in {path}; rerun the same "
                          "command to resume") from None
    print(leaderboard_markdown(board))
    run = board["run"]
    records = " and records.jsonl" if (args.out / RECORDS).is_file() else " (no records.jsonl: no episode ran here)"
    print(f"\n{run['episodes_run']} episodes run, {run['episodes_resumed']} already recorded, "
          f"{run['wall_time_s']:.0f} s; wrote {args.out}/leaderboard.json, .md, .png{records}")
    if run["errors"]:
        print(f"crowdnav: {run['errors']} episodes ended in an error (causes in {args.out}/records.jsonl, tracebacks "
              f"in {args.out}/errors); rerun the same command to retry them", file=sys.stderr)
        return 1
    return 0


def _bounds(args: argparse.Namespace) -> int:
    from envs.evaluation.bounds import BOUNDS, bounds_table, run_bounds
    from envs.evaluation.reachability import ReachConfig
    from envs.evaluation.suite import load_suite

    if args.workers < 1:
        raise UsageError(f"--workers must be >= 1, got {args.workers}")
    try:
        config = ReachConfig(cells_per_step=args.cells_per_step, optimistic_dt_s=args.optimistic_dt)
    except ValueError as exc:  # its fields, named as the flags that set them
        raise UsageError(str(exc).replace("cells_per_step", "--cells-per-step").replace("optimistic_dt_s",
                                                                                          "--optimistic-dt")) from None
    suite = load_suite(args.suite)
    cells = suite.select(args.cells.split(",") if args.cells else None)
    summary = run_bounds(suite, cells, args.out, config=config, data=args.data, workers=args.workers,
                         progress=not args.no_progress)
    print("\n".join(bounds_table(summary)))
    run = summary["run"]
    print(f"\n{run['episodes_run']} episodes computed, {run['episodes_resumed']} already there, "
          f"{run['wall_time_s']:.0f} s; wrote {args.out}/{BOUNDS} and bounds.md")
    if run["died"]:
        print(f"crowdnav: {len(run['died'])} episodes not computed, their worker died ({run['died'][0]}); rerun the "
              "same command to compute them", file=sys.stderr)
        return 1
    return 0


def _demo(args: argparse.Namespace) -> int:
    import os

    from envs.atomic import check_writable_dir, write_json_atomic
    from envs.evaluation.evaluate import evaluate
    from envs.evaluation.report import markdown_table
    from envs.policies import PolicyConfig

    if args.episodes < 1 or args.workers < 1:
        raise UsageError("--episodes and --workers must be >= 1")
    out = check_writable_dir(args.out)
    config = CrowdNavConfig(scenario=DEMO_SCENARIO, n_pedestrians=DEMO_PEDESTRIANS, robot_visible=True)
    start = time.perf_counter()
    print(f"crowdnav demo: {DEMO_POLICY} on {DEMO_SCENARIO}, {DEMO_PEDESTRIANS} pedestrians in groups, "
          f"{args.episodes} episodes, {args.workers} workers", flush=True)
    result = evaluate(PolicyConfig(DEMO_POLICY, predictor=args.predictor), config, args.episodes, 0, args.workers,
                      1, out, stem="demo", progress=not args.no_progress)
    os.replace(out / "demo_seed0.rrd", out / "demo.rrd")
    result["run"]["files"] = ["demo.json", "demo.md", "demo.png", "demo.rrd"]
    write_json_atomic(out / "demo.json", result)
    print(markdown_table(result))
    print(f"\nwrote {out / 'demo.json'}, {out / 'demo.md'}, {out / 'demo.png'}, {out / 'demo.rrd'} "
          f"(view with: {console_script('rerun')} {out / 'demo.rrd'}) in {time.perf_counter() - start:.1f} s")
    return 0


def _list(command: str) -> int:
    if command == "policies":
        from envs.policies import POLICIES

        print("\n".join(POLICIES))
    elif command == "scenarios":
        print("\n".join(scenario_names()))
    else:
        from envs.evaluation.suite import load_suite, suite_names

        for name in suite_names():
            s = load_suite(name)
            planner = [f"replan every {s.replan_every_steps}"] * (s.replan_every_steps is not None) \
                + [f"{k}={v}" for k, v in s.mpc]
            print(f"{s.name} v{s.version}: " + ", ".join(f"{c.name} ({len(c.seeds)})" for c in s.cells)
                  + (f"; planner: {', '.join(planner)}" if planner else ""))
    return 0


def _train(args: argparse.Namespace) -> int:
    cfg, out, resume = train_module.config_from_args(args)
    out.mkdir(parents=True, exist_ok=True)
    return train_module.train(cfg, out, resume, args.demos)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    run = {"evaluate": _evaluate, "benchmark": _benchmark, "bounds": _bounds, "demo": _demo,
           "train": _train}.get(args.command)
    try:
        return run(args) if run is not None else _list(args.command)
    except (UsageError, ValueError, OSError) as exc:
        message = os_error_line(exc, flag_values(args)) if isinstance(exc, OSError) else \
            str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"crowdnav: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C: one line saying what was kept (evaluate/benchmark), exit 130
        print(f"crowdnav: {str(exc) or 'interrupted'}", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
