"""The training callback of `envs.rl.train`: progress with steps/s and ETA, periodic evaluation with the harness
metrics, atomic checkpoints, resume, a stop (keeping the last good checkpoint) when training diverges, and the
state to save when Ctrl-C stops training anywhere (`TrainMonitor.save_interrupted`).

The best agent (checkpoints/best.zip) is chosen among the evaluations made after training steps (`is_new_best`):
the step-0 evaluation is the baseline, logged in eval.csv but never kept as best."""

from __future__ import annotations

import copy
import csv
import importlib.util
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from envs.atomic import write_json_atomic
from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.evaluation.episode import episode_record, run_episode
from envs.evaluation.stats import aggregate
from envs.policies.sb3_files import DECISION_KEY, load_parameters, save_agent
from envs.view import Decision, PolicyView

EVAL_FIELDS = ("steps", "wall_s", "success", "collision", "timeout", "mean_return", "time_to_goal_s",
               "intrusion", "min_distance_m")


class Diverged(RuntimeError):
    """Training produced non-finite weights or losses."""


def tensorboard_available() -> bool:
    return importlib.util.find_spec("tensorboard") is not None


class ModelPolicy:
    """A model being trained, as a harness policy (deterministic actions), deciding every `every` env steps and
    holding its action in between (as it acts in training, and as `SB3Policy` runs the saved agent)."""

    reads_history = False  # it reads `view.obs` only

    def __init__(self, model: Any, name: str = "ppo", every: int = 1) -> None:
        self.model, self.name, self.every = model, name, every
        self._action: np.ndarray | None = None
        self._age = 0

    def reset(self, seed: int | None = None) -> None:
        self._action, self._age = None, 0

    def act(self, view: PolicyView) -> Decision:
        if self._action is None or self._age >= self.every:
            action, _ = self.model.predict(view.obs, deterministic=True)
            self._action, self._age = np.asarray(action, np.float32).reshape(2), 0
        self._age += 1
        return Decision(action=self._action.copy())


def is_new_best(steps: int, success: float, mean_return: float, best: tuple[float, float]) -> bool:
    """Whether an evaluation replaces best.zip: made after training steps (`steps` > 0; the step-0 agent, untrained
    or only cloned, is the baseline: on a few episodes it can score by luck), with a finite mean return, and better
    than `best` = (success, mean return) of the kept one: a higher success rate, ties to the higher return."""
    return steps > 0 and bool(np.isfinite(mean_return)) and (success, mean_return) > best


def select_best(rows: list[tuple[int, float, float]]) -> int | None:
    """Index of the evaluation that `is_new_best` keeps in a sequence of (steps, success, mean return); None when
    none is eligible (only the baseline)."""
    best, index = (-1.0, -float("inf")), None
    for i, (steps, success, ret) in enumerate(rows):
        if is_new_best(steps, success, ret, best):
            best, index = (success, ret), i
    return index


def finite_parameters(model: Any) -> bool:
    import torch

    return all(bool(torch.isfinite(p).all()) for p in model.policy.parameters())


class TrainMonitor(BaseCallback):
    """Prints progress after every rollout, evaluates every `eval_every_steps`, checkpoints every
    `checkpoint_every_steps` (only finite weights are ever saved), stops with `Diverged` otherwise."""

    def __init__(self, cfg: Any, out: Path) -> None:
        super().__init__()
        self.cfg, self.out = cfg, out
        self.env_config = cfg.env_config()  # the observation layout saved with the agent (a mix's first cell)
        self.mix = cfg.mixture()
        self.eval_envs: dict[str, CrowdNavEnv] = {}  # one per cell evaluated in
        self.wall_before = 0.0  # wall seconds of earlier sessions (resume)
        self.t0 = time.perf_counter()
        self.steps0 = 0
        self.next_eval = cfg.eval_every_steps
        self.next_ckpt = cfg.checkpoint_every_steps
        self.best_success = -1.0
        self.best_return = -float("inf")  # ties in success go to the higher mean return (e.g. the faster agent)
        self.baseline: tuple[float, float] | None = None  # (success, mean return) of the step-0 evaluation
        self.extra: dict[str, Any] = {}
        # Ctrl-C: the step count whose weights the model holds (None while a PPO update changes them), and the
        # weights and optimiser state of the last rollout's start, taken before its update (`save_interrupted`)
        self.safe_steps: int | None = None
        self.snapshot: tuple[int, dict, dict, dict | None] | None = None  # (+ constrained PPO's multiplier)

    # --------------------------------------------------------------------------------------- SB3 hooks
    def _on_training_start(self) -> None:
        self.t0, self.steps0 = time.perf_counter(), self.model.num_timesteps

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:  # after each PPO update (and before the first rollout)
        if not finite_parameters(self.model):
            raise Diverged(f"training diverged at step {self.model.num_timesteps} (non-finite weights); the last good "
                           f"checkpoint is {self.out / 'checkpoints' / 'latest.zip'}")
        steps = self.model.num_timesteps
        self.safe_steps = steps  # the rollout about to start does not change the weights
        if steps >= self.next_ckpt:
            self.checkpoint()
            self.next_ckpt = (steps // self.cfg.checkpoint_every_steps + 1) * self.cfg.checkpoint_every_steps
        if steps >= self.next_eval:
            self.evaluate(self.model)
            self.next_eval = (steps // self.cfg.eval_every_steps + 1) * self.cfg.eval_every_steps

    def _on_rollout_end(self) -> None:
        policy = self.model.policy  # the update that follows changes these: keep them as of the rollout's start
        self.snapshot = (int(self.safe_steps or 0), copy.deepcopy(policy.state_dict()),
                         copy.deepcopy(policy.optimizer.state_dict()), lagrangian_state(self.model))
        self.safe_steps = None
        steps, total = self.model.num_timesteps, self.cfg.total_steps
        elapsed = time.perf_counter() - self.t0
        rate = (steps - self.steps0) / max(elapsed, 1e-9)
        eta = eta_s(total, steps, rate)
        eps = list(self.model.ep_info_buffer)
        ret = np.mean([e["r"] for e in eps]) if eps else float("nan")
        succ = self.model.ep_success_buffer
        rate_s = f"{np.mean(succ):.2f}" if len(succ) else "-"
        print(f"{steps:>9}/{total} steps  {rate:6.0f} steps/s  ETA {_hms(eta)}  return {ret:7.2f}  "
              f"success(last {len(succ)}) {rate_s}{_constraint_note(self.model)}", flush=True)

    # ------------------------------------------------------------------------------------ evaluation
    def evaluate(self, model: Any) -> dict[str, float]:
        """Deterministic episodes on the eval seeds, harness metrics; appends a row to eval.csv."""
        policy = ModelPolicy(model, every=self.cfg.decision_every_steps)
        seeds = range(self.cfg.eval_seed, self.cfg.eval_seed + self.cfg.eval_episodes)
        records = []
        for s in seeds:
            config, env = self._eval_env(s)
            records.append(episode_record(run_episode(config, "", s, env=env, policy=policy), policy.name, s))
        summary = aggregate(records)  # the harness's own definitions (envs.evaluation.stats)
        keys = {"success": "success_rate", "collision": "collision_rate", "timeout": "timeout_rate",
                "mean_return": "mean_return", "time_to_goal_s": "time_to_goal_s", "intrusion": "group_intrusion_rate",
                "min_distance_m": "min_distance_m"}
        row = {"steps": model.num_timesteps, "wall_s": round(self.wall_s, 1),
               **{k: float("nan") if summary[v] is None else summary[v] for k, v in keys.items()}}
        path = self.out / "eval.csv"
        new = not path.exists()
        with path.open("a", newline="") as f:
            w = csv.DictWriter(f, EVAL_FIELDS)
            if new:
                w.writeheader()
            w.writerow({k: (round(float(v), 4) if isinstance(v, float | np.floating) else v) for k, v in row.items()})
        print(f"eval @ {row['steps']}: success {row['success']:.2f}  collision {row['collision']:.2f}  "
              f"timeout {row['timeout']:.2f}  return {row['mean_return']:.2f}  ({self.cfg.eval_episodes} episodes, "
              f"seeds {seeds.start}..{seeds.stop - 1})", flush=True)
        if row["steps"] > 0 and getattr(model, "cost_source", "rollout") == "evaluation":
            model.observe_evaluation_cost(dict(self.cfg.constraint)["collision"] * row["collision"])
            print(f"  lagrange multiplier {model.lagrange_multiplier:.3f} (evaluation cost "
                  f"{row['collision']:.3f} collisions per episode, budget {self.cfg.cost_budget})", flush=True)
        if row["steps"] == 0 and np.isfinite(row["mean_return"]):
            self.baseline = (float(row["success"]), float(row["mean_return"]))
        best = (self.best_success, self.best_return)
        if is_new_best(row["steps"], row["success"], row["mean_return"], best) and finite_parameters(model):
            self.best_success, self.best_return = float(row["success"]), float(row["mean_return"])
            save_agent(model, self.out / "checkpoints" / "best.zip", self.env_config, self._meta(model))
        return row

    def _eval_env(self, seed: int) -> tuple[CrowdNavConfig, CrowdNavEnv]:
        """(config, env) of evaluation episode `seed`: the run's env, or its mix cell's; envs are kept."""
        label, config = self.mix.cell_of(seed) if self.mix is not None else ("", self.env_config)
        if label not in self.eval_envs:
            self.eval_envs[label] = CrowdNavEnv(config)
        return config, self.eval_envs[label]

    # ----------------------------------------------------------------------------------- checkpoints
    @property
    def wall_s(self) -> float:
        return self.wall_before + time.perf_counter() - self.t0

    def note_warm_start(self, info: dict[str, Any]) -> None:
        self.extra["warm_start"] = info
        self.wall_before += info["warm_start_s"]
        self.t0 = time.perf_counter()  # the warm start's time is in wall_before now (it was counted twice at step 0)

    def _meta(self, model: Any) -> dict[str, Any]:
        return {"steps": int(model.num_timesteps), "wall_s": round(self.wall_s, 1), "train_config": self.cfg.to_json(),
                "inputs": self.cfg.input_digests(), DECISION_KEY: self.cfg.decision_every_steps, **self.extra}

    def checkpoint(self, model: Any = None) -> None:
        """checkpoints/latest.zip and state.json: what `--resume` reads (`model`: default the one in training)."""
        model = model or self.model
        meta = self._meta(model)
        save_agent(model, self.out / "checkpoints" / "latest.zip", self.env_config, meta)
        best_return = self.best_return if np.isfinite(self.best_return) else None
        lagrangian = lagrangian_state(model)  # constrained PPO: the multiplier that a resumed run continues with
        write_json_atomic(self.out / "checkpoints" / "state.json",
                          {**meta, "best_success": self.best_success, "best_return": best_return,
                           "next_eval": self.next_eval, "baseline": self.baseline,
                           **({"lagrangian": lagrangian} if lagrangian is not None else {})})

    def save_interrupted(self, model: Any) -> int | None:
        """After Ctrl-C anywhere in training: save the last consistent state as checkpoints/latest.zip (the weights
        and optimiser state as of the last rollout's start, with its step count; a rollout cut short is dropped,
        an update cut short is undone); returns the saved step count, None when there is nothing (yet) to save."""
        if self.safe_steps is not None:
            steps = self.safe_steps
        elif self.snapshot is not None:
            steps, policy, optimiser, lagrangian = self.snapshot
            model.policy.load_state_dict(policy)
            model.policy.optimizer.load_state_dict(optimiser)
            if lagrangian is not None:
                model.load_lagrangian_state(lagrangian)
        else:
            return None
        if not finite_parameters(model):
            return None
        model.num_timesteps = steps
        self.checkpoint(model)
        return steps

    def finish(self, model: Any) -> None:
        self.model = model
        last = list(csv.DictReader((self.out / "eval.csv").open()))[-1] if (self.out / "eval.csv").exists() else None
        if last is None or int(last["steps"]) < model.num_timesteps:
            self.evaluate(model)
        steps = model.num_timesteps
        self.next_eval = max(self.next_eval, (steps // self.cfg.eval_every_steps + 1) * self.cfg.eval_every_steps)
        self.checkpoint()  # after the last evaluation, so that a resume does not repeat it
        save_agent(model, self.out / "final.zip", self.env_config, self._meta(model))
        if self.cfg.total_steps == 0:
            print(f"done: no PPO (total_steps 0) in {_hms(self.wall_s)}; agent {self.out / 'final.zip'} (the "
                  f"{'warm start' if self.cfg.warm_start != 'none' else 'init_from agent'}'s policy)", flush=True)
            return
        print(f"done: {model.num_timesteps} steps in {_hms(self.wall_s)}; agent {self.out / 'final.zip'}, "
              f"best {self.out / 'checkpoints' / 'best.zip'} (success {self.best_success:.2f}, return "
              f"{self.best_return:.2f}; chosen among the evaluations after training steps)", flush=True)
        if self.baseline is not None and self.baseline > (self.best_success, self.best_return):
            print(f"note: the step-0 agent (before PPO) scored better (success {self.baseline[0]:.2f}, return "
                  f"{self.baseline[1]:.2f}) than every trained evaluation; best.zip is the best trained agent, not "
                  "it", flush=True)


def load_checkpoint(model: Any, monitor: TrainMonitor, out: Path) -> None:
    """Resume: the weights and optimiser state of out/checkpoints/latest.zip (no unpickling) and the counters."""
    load_parameters(model, out / "checkpoints" / "latest.zip", monitor.env_config)
    state = json.loads((out / "checkpoints" / "state.json").read_text())
    model.num_timesteps = int(state["steps"])
    monitor.wall_before = float(state["wall_s"])
    monitor.best_success = float(state["best_success"])
    best_return = state.get("best_return")  # absent in runs saved before it was kept; None before a finite one
    monitor.best_return = -float("inf") if best_return is None else float(best_return)
    monitor.next_eval = int(state["next_eval"])
    baseline = state.get("baseline")  # absent in runs saved before it was kept
    monitor.baseline = None if baseline is None else (float(baseline[0]), float(baseline[1]))
    monitor.extra = {k: v for k, v in state.items() if k == "warm_start"}
    if hasattr(model, "load_lagrangian_state"):  # constrained PPO continues with the saved multiplier
        if "lagrangian" not in state:
            raise ValueError(f"{out / 'checkpoints' / 'state.json'} holds no multiplier for constrained PPO")
        model.load_lagrangian_state(state["lagrangian"])
    monitor.next_ckpt = (model.num_timesteps // monitor.cfg.checkpoint_every_steps + 1) \
        * monitor.cfg.checkpoint_every_steps
    print(f"resumed {out} at step {model.num_timesteps}", flush=True)


def lagrangian_state(model: Any) -> dict[str, Any] | None:
    """Constrained PPO's multiplier state (`PPOLagrangian.lagrangian_state`); None for plain PPO."""
    return model.lagrangian_state() if hasattr(model, "lagrangian_state") else None


def _constraint_note(model: Any) -> str:
    """The progress line's tail for constrained PPO: the rollout's mean episode cost J_c and the multiplier."""
    state = lagrangian_state(model)
    if state is None:
        return ""
    cost = "-" if state["episode_cost"] is None else f"{state['episode_cost']:.3f}"
    return f"  cost {cost} (budget {model.cost_budget:g})  lambda {state['multiplier']:.3f}"


def eta_s(total: int, steps: int, rate: float) -> float:
    """Seconds left to reach `total` steps at `rate` steps/s: 0 once the last rollout overshot it, inf at rate 0."""
    return max(total - steps, 0) / rate if rate > 0 else float("inf")


def _hms(seconds: float) -> str:
    if not np.isfinite(seconds):
        return "--:--:--"
    s = int(seconds)
    return f"{s // 3600:d}:{s % 3600 // 60:02d}:{s % 60:02d}"
