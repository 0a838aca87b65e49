"""`crowdnav train`'s command line: every `TrainConfig` field as a flag with its help (`add_arguments`), and the
config, run folder and resume flag they give (`config_from_args`; ValueError on misuse). `envs.rl.train` runs it."""

from __future__ import annotations

import argparse
import dataclasses
import json
import tomllib
from pathlib import Path
from typing import Any

from crowdsim.distributed import BACKENDS
from crowdsim.scenarios import scenario_label
from envs.rl.config import QUICK, SCENARIO_DEFAULTS, TrainConfig, term_weights
from envs.rl.cost import add_constraint_arguments
from envs.rl.setting import add_setting_arguments


def check_demos(path: Path, cfg: TrainConfig) -> None:
    """ValueError unless `path` holds demonstrations for this run (`envs.rl.imitation.check_demos`)."""
    from envs.rl.imitation import check_demos as check

    check(path, cfg.env_config(), cfg.decision_every_steps)


# Every TrainConfig flag with its type and what it does (`crowdnav train --help` prints these and the defaults).
FLAG_HELP: dict[str, tuple[type, str]] = {
    "max_pedestrians": (int, "pedestrian rows P in the observation (the nearest P; the rest unseen)"),
    "wall_rays": (int, "range rays to the walls in the observation (0: none; an agent with rays needs them at "
                       "evaluation)"),
    "prediction_source": (str, "with --predictions, where they come from: predictor (--predictor's samples) or "
                               "oracle (the true future of the people observed: an upper bound)"),
    "predictor": (str, "the observation's predictor with --prediction-source predictor (a name such as "
                       "constant-velocity, a checkpoint or module:factory)"),
    "calibration_alpha": (float, "with --calibration: the errors' quantile is the conformal (1 - alpha) one, alpha "
                                 "in (0, 1)"),
    "total_steps": (int, "agent steps (decisions) to train for, the warm start not counted (0: no PPO, the warm "
                         "start's or --init-from's policy is the result)"),
    "seed": (int, "seed of PPO and of the training episodes (env i first resets with 10000000 + seed + i)"),
    "envs": (int, "parallel envs in each roll-out"),
    "workers": (int, "1: all envs in this process; = --envs: one subprocess per env (SB3's SubprocVecEnv)"),
    "n_steps": (int, "roll-out length per env between PPO updates (decisions)"),
    "batch_size": (int, "PPO minibatch size (decisions)"),
    "n_epochs": (int, "PPO passes over each roll-out"),
    "learning_rate": (float, "Adam learning rate of PPO"),
    "gamma": (float, "discount per decision"),
    "gae_lambda": (float, "GAE's lambda (advantage estimation)"),
    "clip_range": (float, "PPO's clipping range of the probability ratio"),
    "ent_coef": (float, "entropy bonus of PPO's loss"),
    "target_kl": (float, "stop an update's epochs once the approximate KL passes 1.5x this (unset: never)"),
    "log_std_init": (float, "initial log standard deviation of the Gaussian actions (also set after cloning)"),
    "warm_start": (str, "none | bc (clone --demo-policy before PPO) | dagger (then --dagger-rounds of DAgger)"),
    "init_from": (str, "start from this agent's policy: a packaged agent (e.g. ppo-crowdnav-20) or an SB3 .zip with "
                       "this run's observation (and decision period, unless a warm start re-fits it); the optimiser "
                       "starts afresh; with --warm-start, cloning continues from it; with --predictions the agent's "
                       "network grows their inputs at zero weight"),
    "demo_policy": (str, "the registry policy that demonstrates and labels (e.g. mpc-cv; a suite's planner "
                         "defaults apply)"),
    "demo_episodes": (int, "demonstration episodes for cloning (seeds --demo-seed onwards)"),
    "demo_seed": (int, "first seed of the demonstration and DAgger episodes (never a suite's reported seed)"),
    "bc_epochs": (int, "behaviour-cloning passes over the demonstrations (and after each DAgger round, unless "
                       "--dagger-epochs)"),
    "dagger_rounds": (int, "DAgger rounds: roll the learner out, label its states by the expert, clone again"),
    "dagger_episodes": (int, "learner episodes per DAgger round"),
    "dagger_epochs": (int, "cloning passes over the aggregate after each DAgger round (unset: --bc-epochs)"),
    "eval_every_steps": (int, "decisions between selection evaluations (the learning curve; the best is kept)"),
    "eval_episodes": (int, "selection episodes per evaluation (deterministic actions)"),
    "eval_seed": (int, "first seed of the selection episodes (never a suite's reported seed)"),
    "checkpoint_every_steps": (int, "decisions between resumable checkpoints (checkpoints/latest.zip)"),
    "threads": (int, "torch threads in the learner process"),
}
BOOL_HELP: dict[str, str] = {
    "bc_rotations": "clone on scenes turned by random angles about the robot, so the agent need not see every "
                    "heading (holonomic robot in a scene without walls only)",
    "bc_detach_critic": "cloning fits the critic to the demonstrations' returns without moving the features the "
                        "actor shares",
    "demo_successes_only": "keep only the demonstrations (not the DAgger labels) whose episode the expert won",
    "groups": "the extractor pools each pedestrian row with its group's rows (group ids in the observation)",
    "predictions": "predicted futures in the observation and the extractor (slower: the predictor runs every "
                   "step)",
    "calibration": "with --predictions: how wrong each person's predictions have been so far in the episode (the "
                   "running conformal quantile of each step's errors) in the observation and the extractor",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=None, metavar="TOML",
                   help="settings file (TOML of TrainConfig fields; flags override it)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="run folder (default out/train/<scenario or cell>)")
    p.add_argument("--resume", type=Path, default=None, metavar="DIR", help="resume the run in DIR")
    p.add_argument("--demos", type=Path, default=None, metavar="NPZ",
                   help="reuse demonstrations (a demos.npz of an earlier run) for --warm-start bc or dagger")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="where the warm start's expert roll-outs run: the local process pool, or one Ray task per "
                        "episode (the 'ray' extra; the same labels)")
    p.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="Ray cluster for --backend ray (default: a local Ray instance)")
    p.add_argument("--quick", action="store_true",
                   help="a short smoke run (about a minute on a laptop CPU; not a usable agent): "
                        + ", ".join(f"{k} {v}" for k, v in QUICK.items()) + "; other flags override these")
    add_setting_arguments(p)
    scenario_help = {"scenario": (str, "crowdsim scenario (or a .toml scenario file) to train in, without --suite"),
                     "pedestrians": (int, "pedestrians in the scenario, without --suite"),
                     "time_limit_s": (float, "episode time limit (s), without --suite")}
    for name, (typ, text) in scenario_help.items():
        p.add_argument("--" + name.replace("_", "-"), type=typ, default=argparse.SUPPRESS, dest=name,
                       help=f"{text} (default: {SCENARIO_DEFAULTS[name]})")
    defaults = TrainConfig()
    for name, (typ, text) in FLAG_HELP.items():
        p.add_argument("--" + name.replace("_", "-"), type=typ, default=argparse.SUPPRESS, dest=name,
                       help=f"{text} (default: {getattr(defaults, name)})")
    p.add_argument("--steps", type=int, default=argparse.SUPPRESS, dest="total_steps",
                   help=f"total agent steps (decisions), alias of --total-steps (default: {defaults.total_steps})")
    p.add_argument("--invisible", action=argparse.BooleanOptionalAction, default=argparse.SUPPRESS, dest="invisible",
                   help="pedestrians do not see the robot (CrowdNav's invisible setting), without --suite "
                        f"(default: {SCENARIO_DEFAULTS['invisible']})")
    for name, text in BOOL_HELP.items():
        p.add_argument("--" + name.replace("_", "-"), action=argparse.BooleanOptionalAction,
                       default=argparse.SUPPRESS, dest=name, help=f"{text} (default: {getattr(defaults, name)})")
    p.add_argument("--demo-mpc", action="append", default=argparse.SUPPRESS, dest="demo_mpc", metavar="FIELD=VALUE",
                   help="the demonstrating policy's MPC setting (repeatable), as crowdnav benchmark's --mpc: its "
                        "planner's, or a NAME+shield's shield (e.g. shield_horizon_s=0.5)")
    p.add_argument("--reward", action="append", default=None, metavar="TERM=WEIGHT",
                   help="reward weight override (repeatable): progress, success, collision, discomfort, "
                        "group_intrusion, time")
    add_constraint_arguments(p, defaults)


def config_from_args(args: argparse.Namespace) -> tuple[TrainConfig, Path, bool]:
    """(config, out folder, resume) from the parsed flags; ValueError on misuse."""
    data: dict[str, Any] = {}
    saved_inputs: dict[str, str] | None = None
    if args.resume is not None:
        if args.config is not None or args.out is not None:
            raise ValueError("--resume DIR takes its settings from DIR/config.json; drop --config/--out")
        path = args.resume / "config.json"
        if not path.is_file() or not (args.resume / "checkpoints" / "latest.zip").is_file():
            raise ValueError(f"nothing to resume in {args.resume} (needs config.json and checkpoints/latest.zip)")
        data = json.loads(path.read_text())
        inputs = args.resume / "inputs.json"  # absent in runs begun before 2026-11-28
        saved_inputs = json.loads(inputs.read_text()) if inputs.is_file() else None
    elif args.config is not None:
        try:
            data = tomllib.loads(args.config.read_text())
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"--config {args.config}: {exc}") from exc
    fields = {f.name for f in dataclasses.fields(TrainConfig)} - {"rewards", "constraint"}
    given = {k: v for k, v in vars(args).items() if k in fields}
    tables = {"rewards": args.reward, "constraint": getattr(args, "constraint", None)}  # TERM=WEIGHT flags
    if args.resume is not None and (set(given) - {"total_steps"} or getattr(args, "quick", False)
                                    or any(tables.values())):
        raise ValueError(f"--resume keeps the run's settings; only --steps may change (got "
                         f"{sorted(given) + [k for k, v in tables.items() if v]})")
    if getattr(args, "quick", False):
        data.update(QUICK)
    data.update(given)
    for key, items in tables.items():
        if items:
            data[key] = {**dict(data.get(key, {})), **term_weights(key, items)}
    cfg = TrainConfig.from_json(data)
    if args.resume is not None and saved_inputs is not None:
        cfg.check_inputs(saved_inputs)
    if args.address is not None and args.backend != "ray":
        raise ValueError("--address needs --backend ray")
    if args.backend == "ray" and cfg.warm_start == "none":
        raise ValueError("--backend ray runs the warm start's roll-outs; it needs --warm-start bc or dagger")
    if args.demos is not None and cfg.warm_start == "none":
        raise ValueError("--demos is used only with --warm-start bc or dagger")
    if args.demos is not None:
        check_demos(args.demos, cfg)
    if cfg.bc_rotations:
        if cfg.warm_start == "none":
            raise ValueError("--bc-rotations is used only with --warm-start bc or dagger")
        from envs.rl.imitation import check_rotatable

        check_rotatable(cfg.env_config())
    out = args.resume or args.out or Path("out/train") / (cfg.env_cell or scenario_label(str(cfg.scenario)))
    if args.resume is None and (out / "checkpoints" / "latest.zip").exists():
        raise ValueError(f"{out} already holds a run; use --resume {out} or another --out")
    return cfg, out, args.resume is not None
