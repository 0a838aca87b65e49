"""Constrained PPO by a Lagrange multiplier (PPO-Lagrangian: Ray, Achiam & Amodei 2019, "Benchmarking Safe
Exploration in Deep Reinforcement Learning"): maximise the return while the mean episode cost stays within a budget.

- Cost: each decision's cost c_t (`envs.rl.cost`: collisions and seconds inside groups, weighted); an episode's cost
  J is their undiscounted sum (collisions + intrusion seconds per episode, in the weights' units).
- Cost critic: V_c(s), a small MLP (`CostActorCriticPolicy.cost_net`) on the policy's critic features, detached: the
  features stay the reward critic's and actor's. Fitted after each PPO update by regression on the rollout's cost
  returns (its own minibatch order, from its own generator: the PPO update's random stream is untouched).
- Cost advantage: GAE on the costs with the run's gamma and gae_lambda (`gae`), bootstrapped with V_c at the
  rollout's end and at time-outs, as SB3 does for the reward.
- Multiplier: after each rollout, lambda <- max(0, lambda + lambda_lr x (J_c - budget)) (`next_multiplier`), J_c the
  mean cost of the rollout's finished episodes (when none finished: of the last `stats_window_size`, 100, finished
  episodes; before the first one, lambda stays). With `cost_source="evaluation"` the rollouts leave lambda alone and
  each evaluation of the deterministic policy steps it instead (`observe_evaluation_cost`, called by the training
  monitor with the evaluation's collision rate times the weight): the exploring policy's noise collides, and its J_c
  stays over any budget the deployed, deterministic policy meets.
- Policy loss: PPO's clipped surrogate on the advantage (A_r - lambda A_c) / (1 + lambda) (`combined_advantage`),
  which SB3's PPO then normalises per minibatch as it does A_r: so lambda weighs one cost unit against reward
  units, and the update moves towards lower cost only as lambda grows. With lambda = 0 the update is PPO's, bit for
  bit (tested).

`PPOLagrangian` is SB3's PPO with two overrides: `collect_rollouts` (also the costs and cost values) and `train`
(the multiplier and the combined advantage before PPO's own update, the cost critic after it). Saved files keep the
cost critic (part of the policy's weights) and the multiplier (a plain number in the file's data); they load without
unpickling (`envs.policies.sb3_files`, which recognises the class by name). Logged to SB3's logger (progress.csv,
tb/), in each rollout's row: constraint/episode_cost (its J_c), constraint/lagrange_multiplier (the multiplier it
was collected with; the next row's is the one updated from this J_c); and train/cost_value_loss (like SB3's train/
values, in the row after the update's rollout).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, ClassVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import DictRolloutBuffer
from stable_baselines3.common.policies import BasePolicy, MultiInputActorCriticPolicy
from stable_baselines3.common.utils import obs_as_tensor

from envs.rl.cost import COST_SOURCES, decision_costs, episode_costs_of


# ------------------------------------------------------------------------------------------ the pieces
def next_multiplier(multiplier: float, episode_cost: float, budget: float, lr: float) -> float:
    """The multiplier after one rollout whose mean episode cost was `episode_cost`: gradient ascent on
    lambda x (J_c - budget), projected on lambda >= 0."""
    return max(0.0, multiplier + lr * (episode_cost - budget))


def combined_advantage(reward_adv: np.ndarray, cost_adv: np.ndarray, multiplier: float) -> np.ndarray:
    """(A_r - lambda A_c) / (1 + lambda): the advantage of the Lagrangian, scaled to stay bounded as lambda grows."""
    return (reward_adv - multiplier * cost_adv) / (1.0 + multiplier)


def gae(rewards: np.ndarray, values: np.ndarray, episode_starts: np.ndarray, last_values: np.ndarray,
        dones: np.ndarray, gamma: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """(advantages, returns), each (n_steps, n_envs), of a rollout by GAE(lambda), as SB3's buffer computes them:
    rewards, values, episode_starts (n_steps, n_envs); last_values (n_envs,) the values after the last step and
    dones (n_envs,) whether it ended an episode. Returns = advantages + values (the TD(lambda) targets)."""
    advantages = np.zeros_like(rewards, dtype=np.float32)
    running = np.zeros(rewards.shape[1], dtype=np.float32)
    n = len(rewards)
    for t in reversed(range(n)):
        last = t == n - 1
        non_terminal = 1.0 - (np.asarray(dones, np.float32) if last else episode_starts[t + 1])
        next_values = last_values if last else values[t + 1]
        delta = rewards[t] + gamma * next_values * non_terminal - values[t]
        running = delta + gamma * lam * non_terminal * running
        advantages[t] = running
    return advantages, advantages + values


class CostActorCriticPolicy(MultiInputActorCriticPolicy):
    """SB3's actor-critic policy for Dict observations with a cost critic `cost_net` (features -> V_c, an MLP of
    two 64-unit layers) on the critic's features, detached. Its weights are in the policy's state and optimiser."""

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        act = self.activation_fn
        with th.random.fork_rng(devices=[]):  # its initial weights leave the sampling stream as PPO's
            self.cost_net = th.nn.Sequential(th.nn.Linear(self.features_dim, 64), act(), th.nn.Linear(64, 64), act(),
                                             th.nn.Linear(64, 1))
            if self.ortho_init:
                for layer, gain in zip(self.cost_net[::2], (np.sqrt(2), np.sqrt(2), 1.0), strict=True):
                    self.init_weights(layer, gain=gain)
        # the optimiser over every weight, the cost critic's last; a step moves only the weights with gradients
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def critic_features(self, obs: Any) -> th.Tensor:
        """The features the value critic reads (the shared extractor's, or the critic's own)."""
        return BasePolicy.extract_features(self, obs, self.vf_features_extractor)

    def predict_cost_values(self, obs: Any) -> th.Tensor:
        """V_c (batch, 1) of a batch of observations (tensors); no gradient reaches the features."""
        return self.cost_net(self.critic_features(obs).detach())


class CostRolloutBuffer(DictRolloutBuffer):
    """SB3's Dict rollout buffer with each step's cost and cost value, and the cost advantages and returns (all
    (n_steps, n_envs))."""

    def reset(self) -> None:
        super().reset()
        shape = (self.buffer_size, self.n_envs)
        self.costs, self.cost_values = np.zeros(shape, np.float32), np.zeros(shape, np.float32)
        self.cost_advantages, self.cost_returns = np.zeros(shape, np.float32), np.zeros(shape, np.float32)

    def add(self, *args: Any, cost: np.ndarray, cost_value: th.Tensor, **kwargs: Any) -> None:  # type: ignore[override]
        """SB3's `add` (obs, action, reward, episode_start, value, log_prob) and this step's costs (n_envs,) and
        cost values (n_envs, 1)."""
        self.costs[self.pos] = cost
        self.cost_values[self.pos] = cost_value.detach().cpu().numpy().flatten()
        super().add(*args, **kwargs)

    def compute_cost_advantage(self, last_cost_values: th.Tensor, dones: np.ndarray) -> None:
        """The cost advantages and returns (`gae`), after the rollout's last step (V_c there, its dones)."""
        last = last_cost_values.detach().cpu().numpy().flatten()
        self.cost_advantages, self.cost_returns = gae(self.costs, self.cost_values, self.episode_starts, last, dones,
                                                      self.gamma, self.gae_lambda)

    def cost_regression_data(self) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """(observations, cost returns) of every step, flattened in the same order (SB3's `get` flattens the
        observations env-major once; before that they are step-major)."""
        if self.generator_ready:
            return self.observations, self.swap_and_flatten(self.cost_returns).reshape(-1)
        obs = {k: v.reshape(-1, *v.shape[2:]) for k, v in self.observations.items()}
        return obs, self.cost_returns.reshape(-1)


# ------------------------------------------------------------------------------------------ the algorithm
class PPOLagrangian(PPO):
    """SB3's PPO under a cost budget (module docstring). `cost_budget`: the mean episode cost allowed (cost units
    per episode, >= 0); `lambda_lr`: the multiplier's step per rollout per cost unit of excess (> 0);
    `lambda_init`: the multiplier at the start (>= 0); `cost_source`: "rollout" (each rollout's J_c steps the
    multiplier) or "evaluation" (`observe_evaluation_cost` does). The envs must report `info["episode_cost"]`
    (`envs.rl.cost.wrap_for_cost`); Box actions, no state-dependent exploration."""

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MultiInputPolicy": CostActorCriticPolicy}

    def __init__(self, policy: Any, env: Any, cost_budget: float = 0.0, lambda_lr: float = 0.05,
                 lambda_init: float = 0.0, cost_source: str = "rollout", **kwargs: Any) -> None:
        for name, value, low_ok in (("cost_budget", cost_budget, True), ("lambda_lr", lambda_lr, False),
                                    ("lambda_init", lambda_init, True)):
            if not (math.isfinite(value) and (value >= 0 if low_ok else value > 0)):
                raise ValueError(f"{name} must be finite and {'>=' if low_ok else '>'} 0, got {value}")
        if cost_source not in COST_SOURCES:
            raise ValueError(f"unknown cost_source {cost_source!r}; valid: {', '.join(COST_SOURCES)}")
        self.cost_source = cost_source
        if kwargs.get("use_sde"):
            raise ValueError("PPOLagrangian does not support state-dependent exploration (use_sde)")
        self.cost_budget, self.lambda_lr = float(cost_budget), float(lambda_lr)
        self.lagrange_multiplier = float(lambda_init)
        self.episode_cost: float | None = None  # J_c of the last rollout (None: no episode finished yet)
        self.cost_value_loss: float | None = None
        super().__init__(policy, env, **kwargs)  # builds the model (`_setup_model`), unless SB3's `load` does later

    def _reset_cost_tracking(self) -> None:
        """The per-env episode cost at the last decision, and the costs of the last finished episodes."""
        self._cost_so_far = np.zeros(self.n_envs if self.n_envs else 1)
        self.recent_episode_costs: deque[float] = deque(maxlen=self._stats_window_size)
        self._cost_rng = np.random.default_rng(self.seed)  # the cost critic's minibatch order

    def _setup_model(self) -> None:
        self.rollout_buffer_class = CostRolloutBuffer  # also when loaded (the file's own entry is never unpickled)
        super()._setup_model()
        if not isinstance(self.action_space, spaces.Box) or not isinstance(self.policy, CostActorCriticPolicy):
            raise ValueError("PPOLagrangian needs Box actions and its CostActorCriticPolicy ('MultiInputPolicy')")
        self._reset_cost_tracking()

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_cost_so_far", "recent_episode_costs", "_cost_rng"]

    # -------------------------------------------------------------------------------------- the multiplier
    def lagrangian_state(self) -> dict[str, Any]:
        """What a resumed run needs to continue with the same multiplier (JSON: checkpoints/state.json)."""
        return {"multiplier": self.lagrange_multiplier, "episode_cost": self.episode_cost,
                "recent_episode_costs": [float(c) for c in self.recent_episode_costs]}

    def load_lagrangian_state(self, state: dict[str, Any]) -> None:
        self.lagrange_multiplier = float(state["multiplier"])
        self.episode_cost = None if state.get("episode_cost") is None else float(state["episode_cost"])
        self.recent_episode_costs.clear()
        self.recent_episode_costs.extend(float(c) for c in state.get("recent_episode_costs", []))

    def observe_evaluation_cost(self, episode_cost: float) -> None:
        """Step the multiplier on the mean episode cost of an evaluation of the deterministic policy (with
        `cost_source="evaluation"`; ignored otherwise)."""
        if self.cost_source == "evaluation" and math.isfinite(episode_cost):
            self.lagrange_multiplier = next_multiplier(self.lagrange_multiplier, float(episode_cost), self.cost_budget,
                                                       self.lambda_lr)

    def _measure_episode_cost(self, finished: list[float]) -> None:
        """J_c after a rollout: the mean cost of its finished episodes, else of the last finished ones."""
        self.recent_episode_costs.extend(finished)
        pool = finished or list(self.recent_episode_costs)
        self.episode_cost = float(np.mean(pool)) if pool else None

    # -------------------------------------------------------------------------------------- SB3 overrides
    def collect_rollouts(self, env: Any, callback: Any, rollout_buffer: CostRolloutBuffer,
                         n_rollout_steps: int) -> bool:
        """SB3's `collect_rollouts` (Box actions, no SDE), also storing each decision's cost and V_c."""
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        finished: list[float] = []
        for _ in range(n_rollout_steps):
            with th.no_grad():
                obs_tensor = obs_as_tensor(self._last_obs, self.device)
                actions, values, log_probs = self.policy(obs_tensor)
                cost_values = self.policy.predict_cost_values(obs_tensor)
            actions = actions.cpu().numpy()
            clipped_actions = np.clip(actions, self.action_space.low, self.action_space.high)
            new_obs, rewards, dones, infos = env.step(clipped_actions)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            totals = episode_costs_of(infos)
            costs = decision_costs(totals, self._cost_so_far, self._last_episode_starts)
            self._cost_so_far = totals
            finished += [float(totals[i]) for i in np.flatnonzero(dones)]
            self._bootstrap_time_outs(rewards, costs, dones, infos)
            rollout_buffer.add(self._last_obs, actions, rewards, self._last_episode_starts, values, log_probs,
                               cost=costs, cost_value=cost_values)
            self._last_obs, self._last_episode_starts = new_obs, dones
        with th.no_grad():
            obs_tensor = obs_as_tensor(new_obs, self.device)
            values, cost_values = self.policy.predict_values(obs_tensor), self.policy.predict_cost_values(obs_tensor)
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        rollout_buffer.compute_cost_advantage(cost_values, dones)
        self._measure_episode_cost(finished)
        self.logger.record("constraint/episode_cost", np.nan if self.episode_cost is None else self.episode_cost)
        self.logger.record("constraint/lagrange_multiplier", self.lagrange_multiplier)  # in effect in this rollout
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def _bootstrap_time_outs(self, rewards: np.ndarray, costs: np.ndarray, dones: np.ndarray,
                             infos: list[dict[str, Any]]) -> None:
        """Where an episode was cut by its time limit, add gamma x V (and gamma x V_c) of its last observation to
        the reward (cost), as SB3 does: the episode did not end there for the agent."""
        for i in np.flatnonzero(dones):
            last = infos[i].get("terminal_observation")
            if last is None or not infos[i].get("TimeLimit.truncated", False):
                continue
            obs = self.policy.obs_to_tensor(last)[0]
            with th.no_grad():
                rewards[i] += self.gamma * self.policy.predict_values(obs)[0]
                costs[i] += self.gamma * float(self.policy.predict_cost_values(obs)[0, 0])

    def train(self) -> None:
        """Update the multiplier from the rollout's episode cost, PPO's update on the combined advantage, then fit
        the cost critic."""
        if self.episode_cost is not None and self.cost_source == "rollout":
            self.lagrange_multiplier = next_multiplier(self.lagrange_multiplier, self.episode_cost, self.cost_budget,
                                                       self.lambda_lr)
        buffer = self.rollout_buffer
        buffer.advantages = combined_advantage(buffer.advantages, buffer.cost_advantages, self.lagrange_multiplier)
        super().train()
        self.cost_value_loss = self._fit_cost_critic()
        self.logger.record("train/cost_value_loss", self.cost_value_loss)

    def _fit_cost_critic(self) -> float:
        """`n_epochs` passes of minibatch regression of V_c on the rollout's cost returns (the policy's optimiser,
        which moves only the cost critic: no other weight has a gradient); the mean squared error over them."""
        obs, targets = self.rollout_buffer.cost_regression_data()
        policy = self.policy
        with th.no_grad():  # the features do not change in this fit: computed once
            features = policy.critic_features(obs_as_tensor(obs, self.device))
        target = th.as_tensor(targets, device=self.device)
        losses = []
        for _ in range(self.n_epochs):
            order = self._cost_rng.permutation(len(target))
            for start in range(0, len(order), self.batch_size):
                idx = th.as_tensor(order[start:start + self.batch_size], device=self.device)
                loss = th.nn.functional.mse_loss(policy.cost_net(features[idx]).flatten(), target[idx])
                policy.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                th.nn.utils.clip_grad_norm_(policy.cost_net.parameters(), self.max_grad_norm)
                policy.optimizer.step()
                losses.append(loss.item())
        return float(np.mean(losses))
