"""What issue 53's training options cost, each side by side with the run without it, in one process.

1. Constrained PPO (`crowdnav train --constraint`, `envs.rl.lagrangian.PPOLagrangian`: a cost critic, the cost
   GAE, the multiplier) against plain PPO on the same settings: agent decisions per second of `model.learn`
   (rollouts and updates), circle_crossing with 5 invisible pedestrians, `--envs 4 --n-steps 256 --n-epochs 4`,
   after one warm-up rollout each; the two alternate, best of the repeats.
2. Observing predictions (`ObservationConfig.predictions`, the constant-velocity predictor, K = 3), with their
   calibration (`prediction_calibration`, envs/calibration.py) and with the oracle's future instead
   (`prediction_source="oracle"`), against the env without predictions: env steps per second of a random policy,
   the same scene, resets included; the variants alternate, best of the repeats.

Ratios are against the first row of each table (wall time, `time.perf_counter`). torch on one thread.

Run: python bench/bench_rl_options.py [--quick] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from dataclasses import replace

import numpy as np


def _ppo_rate(constrained: bool, rollouts: int) -> float:
    """Decisions per second of `rollouts` rollouts (and their updates) after a warm-up one."""
    from envs.rl.config import TrainConfig
    from envs.rl.train import make_model, make_vec_env

    extra = {"constraint": (("collision", 1.0),), "cost_budget": 0.05} if constrained else {}
    cfg = TrainConfig(pedestrians=5, envs=4, n_steps=256, batch_size=256, n_epochs=4, **extra)
    vec = make_vec_env(cfg)
    try:
        model = make_model(cfg, vec)
        per = cfg.envs * cfg.n_steps
        model.learn(per)  # warm-up: the first rollout and update
        start = time.perf_counter()
        model.learn(per * rollouts, reset_num_timesteps=False)
        return per * rollouts / (time.perf_counter() - start)
    finally:
        vec.close()


def _env_rate(observation, steps: int) -> float:
    """Env steps per second of a seeded random policy (resets included)."""
    from envs import CrowdNavConfig, CrowdNavEnv

    env = CrowdNavEnv(CrowdNavConfig(scenario="circle_crossing", n_pedestrians=5, observation=observation))
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    for _ in range(20):  # warm-up: the predictor loads on the first planning tick
        env.step(rng.uniform(-1, 1, 2))
    start, episode = time.perf_counter(), 1
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2))
        if terminated or truncated:
            env.reset(seed=episode)
            episode += 1
    return steps / (time.perf_counter() - start)


def _table(title: str, unit: str, rows: dict[str, float]) -> str:
    first = next(iter(rows.values()))
    lines = [f"{title}", f"| variant | {unit} | ratio to the first row |", "|---|---|---|"]
    lines += [f"| {name} | {rate:,.0f} | {rate / first:.2f} |" for name, rate in rows.items()]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps (a smoke run)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    import torch

    from envs import ObservationConfig

    torch.set_num_threads(1)
    rollouts, steps = (1, 300) if args.quick else (4, 3000)
    ppo = {"PPO": 0.0, "PPO-Lagrangian (--constraint collision=1)": 0.0}
    for _ in range(args.repeats):
        for name, constrained in zip(ppo, (False, True), strict=True):
            ppo[name] = max(ppo[name], _ppo_rate(constrained, rollouts))
    cv = ObservationConfig(predictions=True, predictor="constant-velocity")
    variants = {"no predictions": ObservationConfig(), "predictions (constant velocity, K 3)": cv,
                "+ calibration": replace(cv, prediction_calibration=True),
                "oracle's future, + calibration": replace(cv, prediction_source="oracle", prediction_calibration=True)}
    env = dict.fromkeys(variants, 0.0)
    for _ in range(args.repeats):
        for name, obs in variants.items():
            env[name] = max(env[name], _env_rate(obs, steps))
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; load "
          f"{'/'.join(f'{x:.2f}' for x in os.getloadavg())}; best of {args.repeats}")
    print(_table(f"\nPPO, circle_crossing 5 people, 4 envs x 256 steps, {rollouts} rollouts + updates",
                 "decisions/s", ppo))
    print(_table(f"\nEnv with a random policy, circle_crossing 5 people, {steps} steps", "env steps/s", env))


if __name__ == "__main__":
    main()
