"""User plug-ins: policies and predictors named `module:factory`, and stable-baselines3 agents (`sb3:PATH.zip`).

Protocols (also in docs/envs.md; the README has a worked example):

    Policy      name: str; reset(seed) -> None; act(view: envs.view.PolicyView) -> envs.view.Decision;
                optional `stats` (a `planner.PlanStats`) for plan/fallback/solve-time counts, and
                `reads_history = False` for a policy that reads only `view.obs` (`view.history` is then None).
                A policy factory is called as factory(config: PolicyConfig, env: CrowdNavEnv): it may read the
                env's settings there (config, spaces), but `act` sees only the view. A policy of the old
                protocol (`reset(env, seed)`, `act(obs, env) -> action`) still runs, with a DeprecationWarning
                (`envs.policies.registry.LegacyPolicy`).
    Predictor   predict(history (obs_len, N, 2) m, n_samples: int, rng: np.random.Generator) -> an object with
                `samples` (K, pred_len, N, 2) m and `group_id` (N,); optional attributes step_s, obs_len, pred_len
                (default 0.4 s, 8, 12). A predictor factory is called with no arguments.

SB3 agents load without unpickling Python objects from the file (`sb3_files`): pickled settings are replaced
(spaces by the env's, schedules by constants, policy_kwargs rebuilt with allow-listed classes), the weights load
with `weights_only=True`, and an agent trained on another observation layout is refused with the mismatch named.
An agent trained with a decision period of k env steps (`crowdnav train --decision-every-steps k`, recorded in its
file) acts every k steps here too and holds its action in between.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from envs.policies.sb3_actor import mean_actor
from envs.policies.sb3_files import SB3_ALGOS, decision_period, load_agent, read_agent
from envs.view import Decision, PolicyView

SB3_PREFIX = "sb3:"


def parse_sb3(spec: str) -> tuple[str, Path]:
    """(algorithm, path) of `sb3:PATH.zip` (PPO) or `sb3:ALGO:PATH.zip`; ValueError when malformed."""
    rest = spec[len(SB3_PREFIX):]
    algo, _, tail = rest.partition(":")
    if tail and algo.upper() in SB3_ALGOS:
        algo, path = algo.upper(), Path(tail)
    else:
        algo, path = "PPO", Path(rest)
    if path.suffix != ".zip":
        raise ValueError(f"{spec!r}: expected sb3:PATH.zip or sb3:ALGO:PATH.zip (ALGO one of {', '.join(SB3_ALGOS)})")
    return algo, path


class SB3Policy:
    """A stable-baselines3 agent acting on the env's observation (deterministic by default), every
    `decision_every_steps` env steps (its recorded decision period), holding its action in between."""

    reads_history = False  # it reads `view.obs` only

    def __init__(self, spec: str, env: Any, deterministic: bool = True, threads: int = 1) -> None:
        algo, path = parse_sb3(spec)
        from predictor import set_threads  # torch stays behind the predictor package

        set_threads(threads)
        try:
            self.model = load_agent(path, algo, env, extra_ok=True)  # predictions it was not trained on: ignored
            self.decision_every_steps = decision_period(read_agent(path)[1])
        except ValueError as exc:
            raise ValueError(f"{spec!r}: {exc}") from exc
        self._keys = list(self.model.observation_space.spaces)  # of the env's observation, those it reads
        self._fast = mean_actor(self.model) if deterministic else None  # predict's action, less overhead
        self._action: np.ndarray | None = None
        self._age = 0  # env steps since the held action was chosen
        self.name, self.deterministic = f"sb3:{path.stem}", deterministic
        try:  # a model trained on another observation layout fails here, not mid-episode
            self.model.predict(self._own(env.observation_space.sample()), deterministic=True)
        except (ValueError, RuntimeError, KeyError) as exc:
            raise ValueError(f"{path}: the agent does not fit this env's observation space ({exc})") from exc

    def reset(self, seed: int | None = None) -> None:
        self._action, self._age = None, 0

    def _own(self, obs: dict[str, Any]) -> dict[str, Any]:
        """The keys of `obs` the agent reads (an env may observe predictions it was not trained on)."""
        return obs if len(obs) == len(self._keys) else {k: obs[k] for k in self._keys}

    def act(self, view: PolicyView) -> Decision:
        if self._action is None or self._age >= self.decision_every_steps:
            obs = self._own(view.obs)
            if self._fast is not None:
                action = self._fast(obs)
            else:
                action, _ = self.model.predict(obs, deterministic=self.deterministic)
            self._action, self._age = np.asarray(action, np.float32).reshape(2), 0
        self._age += 1
        return Decision(action=self._action.copy())
