"""The cost that constrained training (`crowdnav train --constraint`, `envs.rl.lagrangian`) keeps under a budget.

Terms of one env step, unweighted, read from the env's step info (`envs.env.CrowdNavEnv.step`):
- collision: 1 on the step the robot touches a pedestrian or a wall (the episode ends there; the info's
  `episode_metrics["collision"]`, whatever the collision reward's weight), else 0;
- group_intrusion: dt_s (s) when the robot's body overlaps a ground-truth group's region (the info's `intruding`),
  else 0;
- discomfort: the reward's unweighted discomfort term (`envs.rewards.comfort_depth`: dt_s x how deep the robot is
  inside the comfort zone, `CrowdNavConfig.discomfort_distance_m` (0.2 m) of surface distance to its nearest
  pedestrian, as a fraction of it, from the info's `min_surface_distance_m`; s), whatever the reward's weight on it: a
  near miss, which a policy can learn to avoid before it ever collides, where a collision costs once and ends the
  episode.

An env step costs sum_k weight_k x term_k (weights >= 0: `check_constraint`); an agent decision held for k env steps
(`envs.rl.setting.DecisionPeriod`) costs the sum over its steps. `ConstraintCost`, a wrapper inside DecisionPeriod,
writes the episode's cost so far into `info["episode_cost"]`; the learner takes a decision's cost as the increase
since that env's previous decision (`decision_costs`), and an episode's cost J as the value at its last step.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterable
from typing import Any

import gymnasium as gym
import numpy as np

from envs.config import CrowdNavConfig
from envs.rewards import comfort_depth

CONSTRAINT_TERMS = ("collision", "group_intrusion", "discomfort")
EPISODE_COST_KEY = "episode_cost"  # in the step info: the weighted cost since the episode's reset
COST_SOURCES = ("rollout", "evaluation")  # what the multiplier is stepped on (envs.rl.lagrangian, --cost-source)
COMFORT_M = CrowdNavConfig.discomfort_distance_m  # the env's default comfort zone, m (discomfort)


def check_constraint(weights: Iterable[tuple[str, float]]) -> dict[str, float]:
    """{term: weight} of (term, weight) pairs; ValueError naming the valid terms for an unknown one, and for a
    weight that is not a finite number >= 0."""
    out: dict[str, float] = {}
    for name, weight in weights:
        if name not in CONSTRAINT_TERMS:
            raise ValueError(f"unknown constraint term {name!r}; valid: {', '.join(CONSTRAINT_TERMS)}")
        if isinstance(weight, bool) or not isinstance(weight, int | float) or not math.isfinite(weight) or weight < 0:
            raise ValueError(f"constraint weight of {name} must be a finite number >= 0, got {weight!r}")
        out[name] = float(weight)
    return out


# what each term reads from one step's info: (info, dt_s, comfort_m) -> unweighted term (module docstring)
_READERS = {
    "collision": lambda info, dt_s, comfort_m: float(bool((info.get("episode_metrics") or {}).get("collision", False))),
    "group_intrusion": lambda info, dt_s, comfort_m: dt_s * float(bool(info["intruding"])),
    "discomfort": lambda info, dt_s, comfort_m: dt_s * comfort_depth(float(info["min_surface_distance_m"]), comfort_m),
}


def step_terms(info: dict[str, Any], dt_s: float, names: Iterable[str] = CONSTRAINT_TERMS,
               comfort_m: float = COMFORT_M) -> dict[str, float]:
    """The unweighted cost terms `names` of one env step from its info (module docstring); dt_s: the env's step, s;
    comfort_m: the env's discomfort distance, m. An info without what a term reads (an env that is not `CrowdNavEnv`)
    raises a KeyError naming the term."""
    out = {}
    for name in names:
        try:
            out[name] = _READERS[name](info, dt_s, comfort_m)
        except KeyError as err:
            raise KeyError(f"cost term {name!r} needs the env's step info key {err}") from None
    return out


class ConstraintCost(gym.Wrapper):
    """Adds `info["episode_cost"]`: the weighted cost (`step_terms`) summed since the last reset, this step
    included (0.0 in the reset's info). `weights`: {term: weight}; dt_s: the env's time step (s)."""

    def __init__(self, env: gym.Env, weights: dict[str, float], dt_s: float) -> None:
        super().__init__(env)
        self.weights, self.dt_s = check_constraint(weights.items()), float(dt_s)
        config = getattr(env.unwrapped, "config", None)  # CrowdNavEnv's: its comfort zone (discomfort)
        self.comfort_m = float(getattr(config, "discomfort_distance_m", COMFORT_M))
        self.total = 0.0

    def reset(self, **kwargs: Any) -> tuple[Any, dict]:
        obs, info = self.env.reset(**kwargs)
        self.total = 0.0
        info[EPISODE_COST_KEY] = 0.0
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        terms = step_terms(info, self.dt_s, self.weights, self.comfort_m)
        self.total += sum(w * terms[k] for k, w in self.weights.items())
        info[EPISODE_COST_KEY] = self.total
        return obs, reward, terminated, truncated, info


def wrap_for_cost(env: gym.Env, weights: dict[str, float], dt_s: float, every: int = 1) -> gym.Env:
    """`env` with `ConstraintCost`, then deciding every `every` env steps (`DecisionPeriod`, for every > 1): the
    `wrapper_class` of a constrained run's vectorised envs."""
    from envs.rl.setting import DecisionPeriod

    env = ConstraintCost(env, weights, dt_s)
    return DecisionPeriod(env, every) if every > 1 else env


def episode_costs_of(infos: list[dict[str, Any]]) -> np.ndarray:
    """(n_envs,) `info["episode_cost"]` of a vectorised step's infos; ValueError when the envs do not report it."""
    try:
        return np.array([float(info[EPISODE_COST_KEY]) for info in infos])
    except KeyError:
        raise ValueError("constrained PPO needs envs wrapped in envs.rl.cost.ConstraintCost (no info['episode_cost'])"
                         ) from None


def decision_costs(totals: np.ndarray, previous: np.ndarray, episode_starts: np.ndarray) -> np.ndarray:
    """(n_envs,) cost of each env's last decision: its episode cost now (`totals`) minus at its previous decision
    (`previous`), or all of it where the decision began an episode (`episode_starts`: the env had just reset)."""
    return totals - np.where(np.asarray(episode_starts, bool), 0.0, previous)


def add_constraint_arguments(p: argparse.ArgumentParser, defaults: Any) -> None:
    """`crowdnav train`'s --constraint, --cost-budget, --lambda-lr and --lambda-init (TrainConfig fields;
    `defaults`: a default TrainConfig, for the help)."""
    p.add_argument("--constraint", action="append", default=None, metavar="TERM=WEIGHT[,TERM=WEIGHT]",
                   help="train constrained PPO (PPO-Lagrangian, docs/rl.md), keeping the mean episode cost within "
                        "--cost-budget; cost terms (repeatable or comma-separated): collision (1 per collision), "
                        "group_intrusion (seconds inside a group), discomfort (seconds within 0.2 m of a person, "
                        "weighted by how near) (default: none, plain PPO)")
    flags = {"cost_budget": "constrained PPO: the mean episode cost allowed (collisions + intrusion and "
                            "discomfort seconds per episode, each times its --constraint weight)",
             "lambda_lr": "constrained PPO: the multiplier's step after each rollout, lambda += lr x (episode cost "
                          "- budget), floored at 0",
             "lambda_init": "constrained PPO: the multiplier at the start (>= 0)"}
    for name, text in flags.items():
        p.add_argument("--" + name.replace("_", "-"), type=float, default=argparse.SUPPRESS, dest=name,
                       help=f"{text} (default: {getattr(defaults, name)})")
    p.add_argument("--cost-source", choices=COST_SOURCES, default=argparse.SUPPRESS, dest="cost_source",
                   help="constrained PPO: the episode cost the multiplier steps on: the exploring policy's after each "
                        "rollout, or the deterministic policy's collision rate after each evaluation (every "
                        "--eval-every-steps; --lambda-lr then steps once per evaluation) "
                        f"(default: {defaults.cost_source})")
