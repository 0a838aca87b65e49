"""Train a PPO agent on `crowdnav/CrowdNav-v1`: `python -m envs.rl.train` or `crowdnav train`.

    crowdnav train --quick --out out/train/quick               # a check that training runs (minutes, 4,096 steps)
    crowdnav train --scenario circle_crossing --pedestrians 5 --invisible --steps 1000000 --out out/train/cc5
    crowdnav train --config run.toml --warm-start bc          # flags override the file's values
    crowdnav train --resume out/train/cc5 --steps 2000000      # go on from the last checkpoint (or a Ctrl-C)
    crowdnav train --suite crowdnav-classic --decision-every-steps 5 --warm-start dagger --demo-policy mpc-cv
                                                               # a benchmark cell's env, a decision every 0.25 s
    crowdnav train --constraint collision=1,group_intrusion=1 --cost-budget 0.5 --out out/train/cc5-lag
                                                               # constrained PPO (PPO-Lagrangian, envs.rl.lagrangian)

It reads top to bottom: the settings (`TrainConfig`), the vectorised envs, the SB3 PPO model with the
set-aware extractor (`envs.rl.extractor`), an optional warm start by behaviour cloning of the MPC
(`envs.rl.imitation`), then `learn` with one callback (`envs.rl.monitor`) that prints steps/s and an ETA,
evaluates the deterministic agent with the harness metrics every `eval_every_steps` on seeds it never trained
on, and saves checkpoints atomically. Out folder: config.json, progress.csv + tb/ (SB3's logger: CSV and
TensorBoard), eval.csv, demos.npz, checkpoints/{latest,best}.zip (+ state.json), final.zip. With --constraint the
model is PPO-Lagrangian (`envs.rl.lagrangian`): the mean episode cost (`envs.rl.cost`) kept within --cost-budget by
a multiplier, which progress.csv logs and state.json keeps for --resume.

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
import contextlib
import functools
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from envs.atomic import write_json_atomic
from envs.rl.config import LAGRANGE_FIELDS, TrainConfig
from envs.rl.cost import wrap_for_cost
from envs.rl.setting import TRAIN_SEED_OFFSET
from envs.rl.train_args import add_arguments, config_from_args


# ------------------------------------------------------------------------------------------ the run
def make_vec_env(cfg: TrainConfig) -> Any:
    """`cfg.envs` monitored envs stepped in this process (workers 1) or in `cfg.envs` subprocesses, each deciding
    every `decision_every_steps` env steps (`DecisionPeriod`); env i first resets with seed 10000000 + seed + i."""
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from envs.env import CrowdNavEnv
    from envs.rl.mix import MixEnv
    from envs.rl.setting import DecisionPeriod

    mix = cfg.mixture()
    env_cls, env_kwargs = (MixEnv, {"mix": mix}) if mix is not None else (CrowdNavEnv, {"config": cfg.env_config()})
    if cfg.workers > 1:  # built in each subprocess, which then leaves Ctrl-C to this one (it saves and closes them)
        env_cls = functools.partial(_env_ignoring_ctrl_c, env_cls)
    vec_cls = DummyVecEnv if cfg.workers == 1 else SubprocVecEnv
    kwargs = {"start_method": "forkserver"} if cfg.workers > 1 else None
    wrapper = {"wrapper_class": DecisionPeriod, "wrapper_kwargs": {"every": cfg.decision_every_steps}} \
        if cfg.decision_every_steps > 1 else {}
    if cfg.constraint:  # each env step's cost into the info, inside the decision period (`envs.rl.cost`)
        wrapper = {"wrapper_class": wrap_for_cost,
                   "wrapper_kwargs": {"weights": dict(cfg.constraint), "dt_s": cfg.env_config().dt_s,
                                      "every": cfg.decision_every_steps}}
    return sb3_make_vec_env(env_cls, n_envs=cfg.envs, seed=TRAIN_SEED_OFFSET + cfg.seed, vec_env_cls=vec_cls,
                            env_kwargs=env_kwargs, vec_env_kwargs=kwargs, **wrapper)


def _env_ignoring_ctrl_c(env_cls: Any, **kwargs: Any) -> Any:
    """`env_cls(**kwargs)` in a SubprocVecEnv worker, which ignores SIGINT from now on: a terminal's Ctrl-C reaches
    the whole process group, and a worker stopped by it would print a traceback and leave the learner's pipe dead."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return env_cls(**kwargs)


def make_model(cfg: TrainConfig, vec_env: Any) -> Any:
    from stable_baselines3 import PPO

    from envs.rl.extractor import CrowdAttentionExtractor

    policy_kwargs = {"features_extractor_class": CrowdAttentionExtractor,
                     "features_extractor_kwargs": {"use_groups": cfg.groups, "use_predictions": cfg.predictions,
                                                   "use_calibration": cfg.calibration},
                     "net_arch": {"pi": [64, 64], "vf": [64, 64]}, "log_std_init": cfg.log_std_init}
    algo, constrained = PPO, {}
    if cfg.constraint:  # PPO-Lagrangian: PPO with a cost critic and a multiplier (`envs.rl.lagrangian`)
        from envs.rl.lagrangian import PPOLagrangian

        algo, constrained = PPOLagrangian, {k: getattr(cfg, k) for k in (*LAGRANGE_FIELDS, "cost_source")}
    model = algo("MultiInputPolicy", vec_env, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                learning_rate=cfg.learning_rate, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range,
                ent_coef=cfg.ent_coef, target_kl=cfg.target_kl, policy_kwargs=policy_kwargs, seed=cfg.seed,
                device="cpu", verbose=0, **constrained)
    vec_env.seed(TRAIN_SEED_OFFSET + cfg.seed)  # PPO(seed=) re-seeded the envs' next resets with seed + i
    return model


def expert_mpc(cfg: TrainConfig) -> Any:
    """The demonstrating MPC's settings: in a suite, the env's MPC with the suite's planner defaults (what
    `crowdnav benchmark` runs there; in a mix, its first suite's), else the env's MPC; then `cfg.demo_mpc`'s
    overrides. None (the env's MPC) when neither a suite nor an override applies."""
    from dataclasses import replace

    from envs.policies import ENV_MPC

    if not cfg.suite and not cfg.mix:
        return replace(ENV_MPC, **cfg.demo_mpc_overrides()) if cfg.demo_mpc else None
    from envs.evaluation.suite import load_suite

    base = load_suite(cfg.suite or cfg.mixture().mpc_suite).mpc_config(ENV_MPC)
    return replace(base, **cfg.demo_mpc_overrides())


def warm_start(cfg: TrainConfig, model: Any, out: Path, demos_path: Path | None,
               backend: str = "local", address: str | None = None) -> dict[str, Any]:
    """Behaviour cloning of the demo policy (demos from `demos_path`, or collected and saved to out/demos.npz),
    then for "dagger" `dagger_rounds` rounds of learner roll-outs labelled by the expert (seeds after the
    demos' own) and cloning on the aggregate (saved to out/dagger.npz). The expert's roll-outs run on `backend`
    (`envs.rl.imitation.collect_demos`: the local pool, or Ray tasks at `address`)."""
    from envs.policies.sb3_files import DECISION_KEY, save_agent
    from envs.rl.imitation import Demos, behaviour_clone, collect_demos, concat

    start, workers = time.perf_counter(), min(max(2, cfg.workers), os.cpu_count() or 2)
    setting = cfg.mixture() or cfg.env_config()  # a mix: each episode seed in its cell
    if demos_path is not None:
        demos = Demos.load(demos_path)
    else:
        print(f"collecting {cfg.demo_episodes} {cfg.demo_policy} demonstrations ...", flush=True)
        demos = collect_demos(setting, cfg.demo_policy, cfg.demo_episodes, cfg.demo_seed, cfg.gamma, workers=workers,
                              every=cfg.decision_every_steps, mpc=expert_mpc(cfg),
                              successes_only=cfg.demo_successes_only, backend=backend, address=address)
        demos.save(out / "demos.npz")
    info: dict[str, Any] = {"demo_steps": len(demos.actions), "demo_episodes": len(demos.episode_seed),
                            "demo_success_rate": demos.success_rate}
    clone = {"reset_log_std": cfg.log_std_init, "rotations": cfg.bc_rotations, "detach_critic": cfg.bc_detach_critic}
    losses = behaviour_clone(model, demos, epochs=cfg.bc_epochs, seed=cfg.seed, **clone)
    print(f"behaviour cloning: {len(demos.actions)} labelled steps (success in their episodes "
          f"{demos.success_rate:.2f}), loss {losses[0]:.3f} -> {losses[-1]:.3f}", flush=True)
    rounds = []
    for r in range(cfg.dagger_rounds if cfg.warm_start == "dagger" else 0):
        seed = cfg.demo_seed + cfg.demo_episodes + r * cfg.dagger_episodes
        new = collect_demos(setting, cfg.demo_policy, cfg.dagger_episodes, seed, cfg.gamma, workers,
                            learner=model.policy, beta=0.0, every=cfg.decision_every_steps, mpc=expert_mpc(cfg),
                            backend=backend, address=address)
        demos = concat(demos, new)
        losses = behaviour_clone(model, demos, epochs=cfg.dagger_epochs or cfg.bc_epochs, seed=cfg.seed + r, **clone)
        rounds.append({"learner_success": new.success_rate, "steps": len(demos.actions), "loss": losses[-1]})
        print(f"DAgger round {r + 1}: the learner succeeded in {new.success_rate:.2f} of its {cfg.dagger_episodes} "
              f"episodes; {len(demos.actions)} labelled steps, loss {losses[-1]:.3f}", flush=True)
        # every round's labels and learner are kept: a stopped warm start loses at most one round (`--demos`
        # out/dagger.npz continues from the labels; out/dagger_learner.zip is the learner cloned on them)
        demos.save(out / "dagger.npz")
        save_agent(model, out / "dagger_learner.zip", cfg.env_config(),
                   {"dagger_round": r + 1, "labels": len(demos.actions), "train_config": cfg.to_json(),
                    DECISION_KEY: cfg.decision_every_steps, "wall_s": round(time.perf_counter() - start, 1)})
    info.update(bc_loss_last=losses[-1], dagger=rounds, warm_start_s=time.perf_counter() - start)
    return info


class TrainInterrupted(KeyboardInterrupt):
    """Ctrl-C during `train`; `str()` says in one line what was saved and how to continue. Still a
    KeyboardInterrupt, so code that stops on Ctrl-C keeps doing so."""


@contextlib.contextmanager
def ctrl_c_ignored() -> Iterator[None]:
    """While entered (in the main thread): Ctrl-C is ignored, so a second press cannot cut a save short."""
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        yield
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)


def interrupted(monitor: Any, model: Any, cfg: TrainConfig, out: Path) -> TrainInterrupted:
    """Save what Ctrl-C left (`TrainMonitor.save_interrupted`) and say so in one line."""
    with ctrl_c_ignored():
        steps = monitor.save_interrupted(model) if monitor is not None and model is not None else None
    if steps is not None:
        return TrainInterrupted(f"interrupted: step {steps} of {cfg.total_steps} saved in "
                                f"{out / 'checkpoints' / 'latest.zip'}; continue with: crowdnav train --resume {out}")
    if (out / "checkpoints" / "latest.zip").is_file():
        return TrainInterrupted(f"interrupted before any new step; continue with: crowdnav train --resume {out}")
    demos = next((p for p in (out / "dagger.npz", out / "demos.npz") if p.is_file()), None)
    reuse = f" (add --demos {demos} to reuse the demonstrations)" if demos is not None else ""
    return TrainInterrupted(f"interrupted before the first checkpoint, nothing to resume in {out}; rerun the "
                            f"command{reuse}")


def train(cfg: TrainConfig, out: Path, resume: bool = False, demos_path: Path | None = None,
          backend: str = "local", address: str | None = None) -> int:
    """Run (or resume) training into `out`; 0 on completion, 1 when training diverged. `backend`, `address`: where
    the warm start's expert roll-outs run (`warm_start`). Ctrl-C saves the last consistent state (also at step 0,
    after the warm start and the baseline evaluation) and raises `TrainInterrupted`."""
    from stable_baselines3.common.logger import configure

    from envs.rl.monitor import Diverged, TrainMonitor, load_checkpoint, tensorboard_available
    from predictor import set_threads

    set_threads(cfg.threads)
    out.mkdir(parents=True, exist_ok=True)
    vec_env = make_vec_env(cfg)
    model = monitor = None
    try:
        model = make_model(cfg, vec_env)
        formats = ["csv", "tensorboard"] if tensorboard_available() else ["csv"]
        if resume:  # SB3's CSV writer starts its file afresh: the rows before are kept as progress.partN.csv
            keep_progress(out / "tb")
        model.set_logger(configure(str(out / "tb"), formats))
        monitor = TrainMonitor(cfg, out)
        if resume:
            load_checkpoint(model, monitor, out)
        else:
            write_json_atomic(out / "config.json", cfg.to_json())
            write_json_atomic(out / "inputs.json", cfg.input_digests())
            (out / "eval.csv").unlink(missing_ok=True)  # a run stopped before its first checkpoint starts again
            if cfg.init_from:  # before the warm start, whose cloning then continues from it
                from envs.policies.sb3_files import load_policy_weights

                fresh = load_policy_weights(model, cfg.init_path(), cfg.env_config(), cfg.decision_every_steps,
                                            any_period=cfg.warm_start != "none")
                layers = sorted({k.split("features_extractor.")[-1].rsplit(".", 1)[0] for k in fresh})
                print(f"starting from {cfg.init_path()}" + (f" (new or grown: {', '.join(layers)})" if fresh else ""),
                      flush=True)
            if cfg.warm_start != "none":
                monitor.note_warm_start(warm_start(cfg, model, out, demos_path, backend, address))
            monitor.evaluate(model)  # the curve starts at step 0 (the cloned or the random policy): the baseline
            monitor.checkpoint(model)  # resumable from here on
        monitor.safe_steps = model.num_timesteps
        remaining = cfg.total_steps - model.num_timesteps
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=monitor, reset_num_timesteps=False)
        monitor.finish(model)
        return 0
    except KeyboardInterrupt:
        raise interrupted(monitor, model, cfg, out) from None
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


def keep_progress(folder: Path) -> Path | None:
    """Move folder/progress.csv (the rows logged before a resume) to the first free progress.partN.csv (N = 1, 2,
    ...) and return its new path; None when there is none."""
    path = folder / "progress.csv"
    if not path.is_file():
        return None
    n = 1
    while (folder / f"progress.part{n}.csv").exists():
        n += 1
    return path.rename(folder / f"progress.part{n}.csv")


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
    try:
        return train(cfg, out, resume, args.demos, args.backend, args.address)
    except KeyboardInterrupt as exc:
        print(f"crowdnav train: {str(exc) or 'interrupted'}", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
