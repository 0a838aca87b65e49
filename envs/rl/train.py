"""Train a PPO agent on `crowdnav/CrowdNav-v1`: `python -m envs.rl.train` or `crowdnav train`.

    crowdnav train --scenario circle_crossing --pedestrians 5 --invisible --steps 1000000 --out out/train/cc5
    crowdnav train --config run.toml --warm-start bc          # flags override the file's values
    crowdnav train --resume out/train/cc5 --steps 2000000      # go on from the last checkpoint
    crowdnav train --suite crowdnav-classic --decision-every-steps 5 --warm-start dagger --demo-policy mpc-cv
                                                               # a benchmark cell's env, a decision every 0.25 s

It reads top to bottom: the settings (`TrainConfig`), the vectorised envs, the SB3 PPO model with the
set-aware extractor (`envs.rl.extractor`), an optional warm start by behaviour cloning of the MPC
(`envs.rl.imitation`), then `learn` with one callback (`envs.rl.monitor`) that prints steps/s and an ETA,
evaluates the deterministic agent with the harness metrics every `eval_every_steps` on seeds it never trained
on, and saves checkpoints atomically. Out folder: config.json, progress.csv + tb/ (SB3's logger: CSV and
TensorBoard), eval.csv, demos.npz, checkpoints/{latest,best}.zip (+ state.json), final.zip.

The env is either built from --scenario/--pedestrians/--invisible/--time-limit-s, or is a simulated cell of a
benchmark suite (--suite, --cell; `envs.rl.setting`): the cell's env config (crowd model, robot, dt, time limit)
with this run's observation and reward settings; `crowdnav benchmark --suite S --policy sb3:OUT/final.zip` then
evaluates the agent on the suite's own episodes. No run ever trains or selects on a suite's episodes: training
resets draw episodes from the streams of seeds 10000000 + seed .. + envs - 1 (`TRAIN_SEED_OFFSET`), evaluation
uses seeds eval_seed .. eval_seed + eval_episodes - 1 (default 100000+), demonstrations demo_seed onwards (default
200000+); these ranges are checked to be disjoint from each other and from every shipped suite's seeds.
--decision-every-steps k: the agent acts every k env steps and holds its action in between (CrowdNav: every 0.25
s, 5 steps of 0.05 s); steps (--steps, --n-steps, --eval-every-steps, ...) then count the agent's decisions. The
saved agent records k, and the harness's sb3: policy acts at the same period; demonstrations are collected at it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from envs.atomic import write_json_atomic
from envs.config import CrowdNavConfig, ObservationConfig, RewardWeights
from envs.rl.setting import TRAIN_SEED_OFFSET, add_setting_arguments, check_disjoint, check_seeds, suite_env_config

WARM_STARTS = ("none", "bc", "dagger")
# The env settings of a run without a suite (None in TrainConfig: not given). With a suite they come from its cell,
# and giving any of them is an error.
SCENARIO_DEFAULTS: dict[str, Any] = {"scenario": "circle_crossing", "pedestrians": 5, "invisible": True,
                                     "time_limit_s": 40.0}
# --quick: a smoke run of the whole pipeline (warm start, PPO, evaluation, checkpoints), not a usable agent.
QUICK: dict[str, Any] = {"total_steps": 4096, "n_steps": 256, "eval_every_steps": 2048, "eval_episodes": 5,
                         "checkpoint_every_steps": 2048, "demo_episodes": 5, "bc_epochs": 5, "dagger_rounds": 1,
                         "dagger_episodes": 3}


@dataclass(frozen=True)
class TrainConfig:
    """Everything a run depends on (saved as config.json; defaults run). Steps are agent steps (decisions), each
    `decision_every_steps` env steps."""

    suite: str = ""                   # train in a simulated cell of this benchmark suite ("": the four below)
    cell: str = ""                    # the suite's cell ("": its only cell)
    scenario: str | None = None       # None: circle_crossing (without a suite)
    pedestrians: int | None = None    # None: 5
    invisible: bool | None = None     # pedestrians do not see the robot (CrowdNav's invisible setting); None: True
    time_limit_s: float | None = None  # s; None: 40
    decision_every_steps: int = 1     # env steps per agent decision; the action is held in between
    max_pedestrians: int = 20         # P rows in the observation
    groups: bool = True               # the extractor pools rows by group id
    predictions: bool = False         # predicted futures in the observation and the extractor
    wall_rays: int = 0                # range rays to the walls in the observation (0: none)
    rewards: tuple[tuple[str, float], ...] = ()  # RewardWeights overrides, e.g. (("collision", -20.0),)
    total_steps: int = 1_000_000
    seed: int = 0
    envs: int = 8                     # parallel envs in the rollout
    workers: int = 1                  # 1: all envs in this process; = envs: one subprocess per env (SB3)
    n_steps: int = 256                # rollout length per env
    batch_size: int = 256
    n_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    target_kl: float | None = None   # stop an update's epochs once the approximate KL passes 1.5x this
    log_std_init: float = -0.5
    warm_start: str = "none"          # "bc": behaviour cloning of demo_policy before PPO; "dagger": then DAgger
    demo_policy: str = "mpc-gpgraph"
    demo_episodes: int = 60
    demo_seed: int = 200_000
    bc_epochs: int = 30
    dagger_rounds: int = 3            # DAgger: roll the learner out, expert labels, clone again on the aggregate
    dagger_episodes: int = 30         # learner episodes per DAgger round
    eval_every_steps: int = 100_000
    eval_episodes: int = 30
    eval_seed: int = 100_000
    checkpoint_every_steps: int = 50_000
    threads: int = 1                  # torch threads in the learner process

    def __post_init__(self) -> None:
        self._resolve_env_fields()
        ints = ("decision_every_steps", "max_pedestrians", "total_steps", "envs", "workers", "n_steps", "batch_size",
                "n_epochs", "demo_episodes", "bc_epochs", "dagger_rounds", "dagger_episodes", "eval_every_steps",
                "eval_episodes", "checkpoint_every_steps", "threads")
        for name in ints:
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {getattr(self, name)!r}")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"unknown warm_start {self.warm_start!r}; valid: {', '.join(WARM_STARTS)}")
        if self.workers not in (1, self.envs):
            raise ValueError(f"workers must be 1 (all envs in this process) or equal to envs ({self.envs}: one "
                             f"subprocess per env, SB3's SubprocVecEnv), got {self.workers}")
        if not isinstance(self.wall_rays, int) or self.wall_rays < 0:
            raise ValueError(f"wall_rays must be an integer >= 0, got {self.wall_rays!r}")
        if self.target_kl is not None and not self.target_kl > 0:
            raise ValueError(f"target_kl must be > 0 (or unset), got {self.target_kl}")
        if not (0 < self.gamma <= 1 and 0 < self.gae_lambda <= 1 and self.learning_rate > 0 and self.clip_range > 0):
            raise ValueError("gamma and gae_lambda must be in (0, 1], learning_rate and clip_range > 0")
        self.env_config().sim_config()  # validates the scenario, crowd size (against the group sizes), rewards
        seeds = self.seed_ranges()
        for what, r in seeds.items():
            check_seeds(what, r)
        check_disjoint(seeds)

    def _resolve_env_fields(self) -> None:
        """Fill the env settings left None (no suite) with `SCENARIO_DEFAULTS`; with a suite, refuse any given."""
        if not isinstance(self.suite, str) or not isinstance(self.cell, str):
            raise ValueError("suite and cell must be names (strings)")
        if self.cell and not self.suite:
            raise ValueError(f"cell {self.cell!r} needs its suite (--suite)")
        if self.suite:
            given = ["--" + k.replace("_", "-") for k in SCENARIO_DEFAULTS if getattr(self, k) is not None]
            if given:
                raise ValueError(f"suite {self.suite}: its cell sets the env, so {', '.join(given)} would be ignored; "
                                 "drop them")
            return
        for key, value in SCENARIO_DEFAULTS.items():
            if getattr(self, key) is None:
                object.__setattr__(self, key, value)
        if not isinstance(self.pedestrians, int) or self.pedestrians < 1:
            raise ValueError(f"pedestrians must be an integer >= 1, got {self.pedestrians!r}")

    def seed_ranges(self) -> dict[str, range]:
        """The reset seeds of every episode this run draws: training (the first reset of each env; later resets
        continue each env's random stream), evaluation, and demonstrations (BC and DAgger; none without a warm
        start)."""
        demos = 0 if self.warm_start == "none" else self.demo_episodes
        if self.warm_start == "dagger":
            demos += self.dagger_rounds * self.dagger_episodes
        first = TRAIN_SEED_OFFSET + self.seed
        return {"training seeds (10000000 + seed)": range(first, first + self.envs),
                "eval_seed": range(self.eval_seed, self.eval_seed + self.eval_episodes),
                "demo_seed": range(self.demo_seed, self.demo_seed + demos)}

    @property
    def env_cell(self) -> str:
        """The suite cell trained in ("" without a suite)."""
        return suite_env_config(self.suite, self.cell)[0] if self.suite else ""

    def env_config(self) -> CrowdNavConfig:
        """The env every training and evaluation episode runs in: the suite cell's (with this run's observation
        and reward weights), or the one the scenario fields describe."""
        names = {"progress": "progress_per_m", "success": "success", "collision": "collision",
                 "discomfort": "discomfort_per_s", "group_intrusion": "group_intrusion_per_s", "time": "time_per_s"}
        unknown = [k for k, _ in self.rewards if k not in names]
        if unknown:
            raise ValueError(f"unknown reward term(s) {unknown}; valid: {', '.join(names)}")
        overrides = {names[k]: float(v) for k, v in self.rewards}
        if self.suite:
            _, cfg = suite_env_config(self.suite, self.cell)
            obs = replace(cfg.observation, max_pedestrians=self.max_pedestrians, predictions=self.predictions,
                          wall_rays=self.wall_rays)
            return replace(cfg, observation=obs, rewards=replace(cfg.rewards, **overrides))
        weights = replace(RewardWeights(), **overrides)
        obs = ObservationConfig(max_pedestrians=self.max_pedestrians, predictions=self.predictions,
                                wall_rays=self.wall_rays)
        return CrowdNavConfig(scenario=self.scenario, n_pedestrians=self.pedestrians,
                              robot_visible=not self.invisible, time_limit_s=self.time_limit_s, rewards=weights,
                              observation=obs)

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["rewards"] = {k: v for k, v in self.rewards}
        return d

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainConfig:
        """A config from JSON/TOML data; unknown keys are an error."""
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - fields)
        if unknown:
            raise ValueError(f"unknown setting(s) {unknown}; valid: {', '.join(sorted(fields))}")
        data = dict(data)
        if "rewards" in data:
            data["rewards"] = tuple((str(k), float(v)) for k, v in dict(data["rewards"]).items())
        return cls(**data)


# ------------------------------------------------------------------------------------------ the run
def make_vec_env(cfg: TrainConfig) -> Any:
    """`cfg.envs` monitored envs stepped in this process (workers 1) or in `cfg.envs` subprocesses, each deciding
    every `decision_every_steps` env steps (`DecisionPeriod`); env i first resets with seed 10000000 + seed + i."""
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from envs.env import CrowdNavEnv
    from envs.rl.setting import DecisionPeriod

    env_cfg = cfg.env_config()
    vec_cls = DummyVecEnv if cfg.workers == 1 else SubprocVecEnv
    kwargs = {"start_method": "forkserver"} if cfg.workers > 1 else None
    wrapper = {"wrapper_class": DecisionPeriod, "wrapper_kwargs": {"every": cfg.decision_every_steps}} \
        if cfg.decision_every_steps > 1 else {}
    return sb3_make_vec_env(CrowdNavEnv, n_envs=cfg.envs, seed=TRAIN_SEED_OFFSET + cfg.seed, vec_env_cls=vec_cls,
                            env_kwargs={"config": env_cfg}, vec_env_kwargs=kwargs, **wrapper)


def make_model(cfg: TrainConfig, vec_env: Any) -> Any:
    from stable_baselines3 import PPO

    from envs.rl.extractor import CrowdAttentionExtractor

    policy_kwargs = {"features_extractor_class": CrowdAttentionExtractor,
                     "features_extractor_kwargs": {"use_groups": cfg.groups, "use_predictions": cfg.predictions},
                     "net_arch": {"pi": [64, 64], "vf": [64, 64]}, "log_std_init": cfg.log_std_init}
    model = PPO("MultiInputPolicy", vec_env, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                learning_rate=cfg.learning_rate, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range,
                ent_coef=cfg.ent_coef, target_kl=cfg.target_kl, policy_kwargs=policy_kwargs, seed=cfg.seed,
                device="cpu", verbose=0)
    vec_env.seed(TRAIN_SEED_OFFSET + cfg.seed)  # PPO(seed=) re-seeded the envs' next resets with seed + i
    return model


def expert_mpc(cfg: TrainConfig) -> Any:
    """The demonstrating MPC's settings: in a suite, the env's MPC with the suite's planner defaults (what
    `crowdnav benchmark` runs there); else None (the env's MPC)."""
    if not cfg.suite:
        return None
    from envs.evaluation.suite import load_suite
    from envs.policies import ENV_MPC

    return replace(ENV_MPC, **dict(load_suite(cfg.suite).mpc))


def warm_start(cfg: TrainConfig, model: Any, out: Path, demos_path: Path | None) -> dict[str, Any]:
    """Behaviour cloning of the demo policy (demos from `demos_path`, or collected and saved to out/demos.npz),
    then for "dagger" `dagger_rounds` rounds of learner roll-outs labelled by the expert (seeds after the
    demos' own) and cloning on the aggregate (saved to out/dagger.npz)."""
    from envs.rl.imitation import Demos, behaviour_clone, collect_demos, concat

    start, workers = time.perf_counter(), min(max(2, cfg.workers), os.cpu_count() or 2)
    if demos_path is not None:
        demos = Demos.load(demos_path)
    else:
        print(f"collecting {cfg.demo_episodes} {cfg.demo_policy} demonstrations ...", flush=True)
        demos = collect_demos(cfg.env_config(), cfg.demo_policy, cfg.demo_episodes, cfg.demo_seed, cfg.gamma,
                              workers=workers, every=cfg.decision_every_steps, mpc=expert_mpc(cfg))
        demos.save(out / "demos.npz")
    info: dict[str, Any] = {"demo_steps": len(demos.actions), "demo_episodes": len(demos.episode_seed),
                            "demo_success_rate": demos.success_rate}
    losses = behaviour_clone(model, demos, epochs=cfg.bc_epochs, reset_log_std=cfg.log_std_init, seed=cfg.seed)
    print(f"behaviour cloning: {len(demos.actions)} labelled steps (success in their episodes "
          f"{demos.success_rate:.2f}), loss {losses[0]:.3f} -> {losses[-1]:.3f}", flush=True)
    rounds = []
    for r in range(cfg.dagger_rounds if cfg.warm_start == "dagger" else 0):
        seed = cfg.demo_seed + cfg.demo_episodes + r * cfg.dagger_episodes
        new = collect_demos(cfg.env_config(), cfg.demo_policy, cfg.dagger_episodes, seed, cfg.gamma, workers,
                            learner=model.policy, beta=0.0, every=cfg.decision_every_steps, mpc=expert_mpc(cfg))
        demos = concat(demos, new)
        losses = behaviour_clone(model, demos, epochs=cfg.bc_epochs, reset_log_std=cfg.log_std_init, seed=cfg.seed + r)
        rounds.append({"learner_success": new.success_rate, "steps": len(demos.actions), "loss": losses[-1]})
        print(f"DAgger round {r + 1}: the learner succeeded in {new.success_rate:.2f} of its {cfg.dagger_episodes} "
              f"episodes; {len(demos.actions)} labelled steps, loss {losses[-1]:.3f}", flush=True)
    if rounds:
        demos.save(out / "dagger.npz")
    info.update(bc_loss_last=losses[-1], dagger=rounds, warm_start_s=time.perf_counter() - start)
    return info


def train(cfg: TrainConfig, out: Path, resume: bool = False, demos_path: Path | None = None) -> int:
    """Run (or resume) training into `out`; 0 on completion, 1 when training diverged."""
    from stable_baselines3.common.logger import configure

    from envs.rl.monitor import Diverged, TrainMonitor, load_checkpoint, tensorboard_available
    from predictor import set_threads

    set_threads(cfg.threads)
    out.mkdir(parents=True, exist_ok=True)
    vec_env = make_vec_env(cfg)
    try:
        model = make_model(cfg, vec_env)
        formats = ["csv", "tensorboard"] if tensorboard_available() else ["csv"]
        model.set_logger(configure(str(out / "tb"), formats))
        monitor = TrainMonitor(cfg, out)
        if resume:
            load_checkpoint(model, monitor, out)
        else:
            write_json_atomic(out / "config.json", cfg.to_json())
            if cfg.warm_start != "none":
                monitor.note_warm_start(warm_start(cfg, model, out, demos_path))
            monitor.evaluate(model)  # the curve starts at step 0 (the cloned or the random policy)
        remaining = cfg.total_steps - model.num_timesteps
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=monitor, reset_num_timesteps=False)
        monitor.finish(model)
        return 0
    except Diverged as exc:
        print(f"crowdnav train: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # e.g. torch's Normal refusing a NaN mean mid-rollout
        if "nan" not in str(exc).lower():
            raise
        print(f"crowdnav train: training diverged ({str(exc).splitlines()[0]}); the last good checkpoint is "
              f"{out / 'checkpoints' / 'latest.zip'}", file=sys.stderr)
        return 1
    finally:
        vec_env.close()


def check_demos(path: Path, cfg: TrainConfig) -> None:
    """ValueError unless `path` holds demonstrations for this run (`envs.rl.imitation.check_demos`)."""
    from envs.rl.imitation import check_demos as check

    check(path, cfg.env_config(), cfg.decision_every_steps)


# ------------------------------------------------------------------------------------------ command line
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=None, metavar="TOML", help="settings file (TrainConfig fields)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="run folder (default out/train/<scenario or cell>)")
    p.add_argument("--resume", type=Path, default=None, metavar="DIR", help="resume the run in DIR")
    p.add_argument("--demos", type=Path, default=None, metavar="NPZ", help="reuse demonstrations for --warm-start bc")
    p.add_argument("--quick", action="store_true",
                   help="a short smoke run (about a minute on a laptop CPU; not a usable agent): "
                        + ", ".join(f"{k} {v}" for k, v in QUICK.items()) + "; other flags override these")
    add_setting_arguments(p)
    for name, typ in {"scenario": str, "pedestrians": int, "time_limit_s": float}.items():
        p.add_argument("--" + name.replace("_", "-"), type=typ, default=argparse.SUPPRESS, dest=name,
                       help=f"without --suite (default: {SCENARIO_DEFAULTS[name]})")
    flags = {"max_pedestrians": int, "wall_rays": int,
             "total_steps": int, "seed": int, "envs": int, "workers": int, "n_steps": int, "batch_size": int,
             "n_epochs": int, "learning_rate": float, "gamma": float, "ent_coef": float,
             "target_kl": float, "log_std_init": float,
             "warm_start": str, "demo_policy": str, "demo_episodes": int, "demo_seed": int, "bc_epochs": int,
             "dagger_rounds": int, "dagger_episodes": int,
             "eval_every_steps": int, "eval_episodes": int, "eval_seed": int, "checkpoint_every_steps": int,
             "threads": int}
    defaults = TrainConfig()
    for name, typ in flags.items():
        p.add_argument("--" + name.replace("_", "-"), type=typ, default=argparse.SUPPRESS, dest=name,
                       help=f"(default: {getattr(defaults, name)})")
    p.add_argument("--steps", type=int, default=argparse.SUPPRESS, dest="total_steps",
                   help=f"total agent steps (decisions), alias of --total-steps (default: {defaults.total_steps})")
    p.add_argument("--invisible", action=argparse.BooleanOptionalAction, default=argparse.SUPPRESS, dest="invisible",
                   help=f"without --suite (default: {SCENARIO_DEFAULTS['invisible']})")
    for name in ("groups", "predictions"):
        p.add_argument(f"--{name}", action=argparse.BooleanOptionalAction, default=argparse.SUPPRESS, dest=name,
                       help=f"(default: {getattr(defaults, name)})")
    p.add_argument("--reward", action="append", default=None, metavar="TERM=WEIGHT",
                   help="reward weight override (repeatable): progress, success, collision, discomfort, "
                        "group_intrusion, time")


def config_from_args(args: argparse.Namespace) -> tuple[TrainConfig, Path, bool]:
    """(config, out folder, resume) from the parsed flags; ValueError on misuse."""
    data: dict[str, Any] = {}
    if args.resume is not None:
        if args.config is not None or args.out is not None:
            raise ValueError("--resume DIR takes its settings from DIR/config.json; drop --config/--out")
        path = args.resume / "config.json"
        if not path.is_file() or not (args.resume / "checkpoints" / "latest.zip").is_file():
            raise ValueError(f"nothing to resume in {args.resume} (needs config.json and checkpoints/latest.zip)")
        data = json.loads(path.read_text())
    elif args.config is not None:
        try:
            data = tomllib.loads(args.config.read_text())
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"--config {args.config}: {exc}") from exc
    fields = {f.name for f in dataclasses.fields(TrainConfig)} - {"rewards"}
    given = {k: v for k, v in vars(args).items() if k in fields}
    if args.resume is not None and (set(given) - {"total_steps"} or getattr(args, "quick", False)):
        raise ValueError(f"--resume keeps the run's settings; only --steps may change (got {sorted(given)})")
    if getattr(args, "quick", False):
        data.update(QUICK)
    data.update(given)
    if args.reward:
        rewards = dict(data.get("rewards", {}))
        for item in args.reward:
            key, sep, value = item.partition("=")
            if not sep:
                raise ValueError(f"--reward {item!r}: expected TERM=WEIGHT")
            rewards[key] = float(value)
        data["rewards"] = rewards
    cfg = TrainConfig.from_json(data)
    if args.demos is not None and cfg.warm_start == "none":
        raise ValueError("--demos is used only with --warm-start bc or dagger")
    if args.demos is not None:
        check_demos(args.demos, cfg)
    out = args.resume or args.out or Path("out/train") / (cfg.env_cell or str(cfg.scenario))
    if args.resume is None and (out / "checkpoints" / "latest.zip").exists():
        raise ValueError(f"{out} already holds a run; use --resume {out} or another --out")
    return cfg, out, args.resume is not None


def main(argv: list[str] | None = None) -> int:
    from crowdsim.cli import OneLineParser

    parser = OneLineParser(prog="crowdnav train", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        cfg, out, resume = config_from_args(args)
        out.mkdir(parents=True, exist_ok=True)
    except (ValueError, OSError) as exc:
        print(f"crowdnav train: error: {exc}", file=sys.stderr)
        return 2
    return train(cfg, out, resume, args.demos)


if __name__ == "__main__":
    sys.exit(main())
