"""Warm start from the MPC: demonstrations of a harness policy, behaviour cloning into an SB3 policy, DAgger.

`collect_demos` runs a registry policy (by default `mpc-gpgraph`) for whole episodes with fixed seeds and keeps
every step's observation, the action it took and the discounted return that followed. `behaviour_clone` fits
an SB3 actor-critic to them: the actor by maximum likelihood of the expert's actions (its Gaussian's mean
learns the action; its log-std is reset afterwards so PPO still explores), the critic by regression on the
returns, so that the first PPO updates do not tear the cloned actor down with a random critic.
DAgger (Ross et al. 2011) then rolls the cloned policy out, has the expert label the states the learner itself
reaches (`collect_demos(learner=...)`), and clones again on the aggregate, which fixes the compounding errors of
plain cloning: a learner that drifts off the expert's states has never been shown how to recover.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.distributed import RayUnavailableError, WorkerDied, check_backend, run_in_processes, run_on_ray
from envs.atomic import write_atomic
from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.policies import PolicyConfig, act, make_policy
from envs.rl.mix import Mix


@dataclass
class Demos:
    """Demonstrations: obs {key: (S, ...)} float32, actions (S, 2) in [-1, 1], returns (S,) discounted,
    episode_outcome (E,) strings, episode_seed (E,); S counts decision steps, one every `decision_every_steps` env
    steps (files saved before it was recorded: 1)."""

    obs: dict[str, np.ndarray]
    actions: np.ndarray
    returns: np.ndarray
    episode_outcome: np.ndarray
    episode_seed: np.ndarray
    decision_every_steps: int = 1

    @property
    def success_rate(self) -> float:
        return float(np.mean(self.episode_outcome == "success")) if len(self.episode_outcome) else 0.0

    def save(self, path: str | Path) -> None:
        """Written atomically (`envs.atomic`): a reader sees the old file or the complete new one."""
        arrays = {"actions": self.actions, "returns": self.returns, "episode_outcome": self.episode_outcome,
                  "episode_seed": self.episode_seed, "decision_every_steps": np.array(self.decision_every_steps),
                  **{f"obs.{k}": v for k, v in self.obs.items()}}

        def write(tmp: str) -> None:
            with open(tmp, "wb") as f:  # a file object: np.savez would append .npz to a bare name
                np.savez_compressed(f, **arrays)

        write_atomic(path, write)

    @classmethod
    def load(cls, path: str | Path) -> Demos:
        """Load demos saved by `save` (no pickles); ValueError when the file is not one."""
        try:
            with np.load(path, allow_pickle=False) as z:
                obs = {k[4:]: z[k] for k in z.files if k.startswith("obs.")}
                every = int(z["decision_every_steps"]) if "decision_every_steps" in z.files else 1
                return cls(obs, z["actions"], z["returns"], z["episode_outcome"], z["episode_seed"], every)
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: not a demonstrations file ({exc})") from exc


def _episode(env: CrowdNavEnv, expert: Any, seed: int, gamma: float, learner: Any = None,
             beta: float = 1.0, rng: np.random.Generator | None = None,
             every: int = 1) -> tuple[dict, np.ndarray, np.ndarray, str]:
    """One episode labelled by the expert, deciding every `every` env steps. At each decision step the expert's
    action is the label, and the action executed (and held for `every` env steps, or until the episode ends) is the
    expert's with probability beta, else the learner's (an SB3 policy, deterministic). The expert is asked at every
    env step, so that its own clock runs (a planner built with `replan_every_steps` = `every` re-plans exactly at
    the decision steps); its answers in between are not used. Returns per decision step: observation, label and
    the discounted return (per decision, of the rewards summed over its env steps)."""
    obs, _ = env.reset(seed=seed)
    expert.reset(seed)
    observations, actions, rewards, done, info = [], [], [], False, {}
    while not done:
        label = np.asarray(act(expert, env), np.float32)
        action = label
        if learner is not None and (rng is None or rng.random() >= beta):
            action = np.asarray(learner.predict(obs, deterministic=True)[0], np.float32).reshape(2)
        observations.append(obs)
        actions.append(label)
        total = 0.0
        for k in range(every):
            if k:
                act(expert, env)  # the expert's clock; the held action runs
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            done = terminated or truncated
            if done:
                break
        rewards.append(total)
    returns = np.zeros(len(rewards))
    acc = 0.0
    for i in range(len(rewards) - 1, -1, -1):
        acc = rewards[i] + gamma * acc
        returns[i] = acc
    stacked = {k: np.stack([o[k] for o in observations]) for k in observations[0]}
    return stacked, np.stack(actions), returns, info["episode_metrics"]["outcome"]


def _chunk(args: tuple) -> list[tuple[dict, np.ndarray, np.ndarray, str]]:
    from predictor import set_threads

    set_threads(1)
    config, policy, seeds, gamma, learner, beta, every, mpc = args
    if learner is not None:  # (class, constructor kwargs, state dict) -> the SB3 policy in this process
        cls, kwargs, state = learner
        learner = cls(**kwargs)
        learner.load_state_dict(state)
        learner.set_training_mode(False)
    built: dict[str, tuple[CrowdNavEnv, Any]] = {}  # one env and expert per cell (a mix has many)
    out = []
    for s in seeds:  # each episode's own generator (DAgger's mixing): the same labels however seeds are chunked
        rng = np.random.default_rng(s)
        label, cfg = config.cell_of(s) if isinstance(config, Mix) else ("", config)
        if label not in built:
            env = CrowdNavEnv(cfg)
            expert = make_policy(PolicyConfig(name=policy, replan_every_steps=every, **({"mpc": mpc} if mpc else {})),
                                 env)
            built[label] = env, decide_every(expert, every)
        out.append(_episode(*built[label], s, gamma, learner, beta, rng, every))
    return out


def decide_every(policy: Any, every: int) -> Any:
    """`policy` with a learned agent inside it (an SB3 agent, or one behind `+route` / `+shield`) deciding every
    `every` env steps, the learner's decision period, instead of its own recorded one: an agent expert labels each
    of the learner's decisions with a decision of its own, as a planner expert re-plans at them (`replan_every_steps`).
    Planners are returned unchanged."""
    inner = policy
    while inner is not None:
        if hasattr(inner, "decision_every_steps"):
            inner.decision_every_steps = every
        inner = getattr(inner, "inner", None)
    return policy


def collect_demos(config: CrowdNavConfig | Mix, policy: str = "mpc-gpgraph", episodes: int = 60, seed: int = 0,
                  gamma: float = 0.99, workers: int = 1, learner: Any = None, beta: float = 1.0,
                  every: int = 1, mpc: Any = None, successes_only: bool = False, backend: str = "local",
                  address: str | None = None) -> Demos:
    """`episodes` episodes labelled by `policy` (seeds seed .. seed + episodes - 1) over `workers` processes, in
    `config`'s env or, for an `envs.rl.mix.Mix`, in each seed's cell, at
    a decision every `every` env steps (`_episode`; a planner expert re-plans every `every` steps). With a
    `learner` (an SB3 policy), each decision runs the learner's action with probability 1 - beta (DAgger);
    `episode_outcome` is then the outcome of the executed (mixed) episode. `mpc` (a `planner.MPCConfig`): the
    expert MPC's settings (None: the env's, `envs.policies.ENV_MPC`), e.g. a benchmark suite's planner defaults.
    `successes_only`: keep only the episodes that ended in success (the expert's failures teach failing);
    ValueError when none did. `backend` "ray": one Ray task per episode, on the cluster at `address` ("auto",
    "HOST:PORT") or a local Ray instance of `workers` CPUs (the optional `ray` extra); the labels equal the local
    pool's (each episode depends on its seed alone)."""
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    if not isinstance(every, int) or every < 1:
        raise ValueError(f"every must be an integer >= 1, got {every!r}")
    seeds = list(range(seed, seed + episodes))
    if learner is not None:  # sent to the workers as its constructor and detached weights
        learner = (type(learner), learner._get_constructor_parameters(),
                   {k: v.detach().clone() for k, v in learner.state_dict().items()})
    check_backend(backend)
    groups = [[s] for s in seeds] if backend == "ray" else [seeds[i::workers] for i in range(workers)]
    chunks = [(config, policy, g, gamma, learner, beta, every, mpc) for g in groups if g]
    if backend == "ray":
        try:
            results = dict(run_on_ray(_chunk, chunks, address, None if address else workers))
        except RayUnavailableError as exc:
            raise ValueError(str(exc)) from exc
    elif len(chunks) == 1:
        results = {0: _chunk(chunks[0])}
    else:  # crowdsim's pool: a worker that dies (OOM) is replaced and its chunk rerun
        results = dict(run_in_processes(_chunk, chunks, len(chunks)))
    died = {i: r for i, r in results.items() if isinstance(r, WorkerDied)}
    if died:
        raise RuntimeError(f"demonstrations of seeds {[chunks[i][2] for i in died]} were lost: "
                           f"{next(iter(died.values()))}")
    parts = [results[i] for i in range(len(chunks))]
    order = sorted(((s, ep) for c, part in zip(chunks, parts, strict=True) for s, ep in zip(c[2], part, strict=True)),
                   key=lambda x: x[0])
    if successes_only:
        order = [(s, ep) for s, ep in order if ep[3] == "success"]
        if not order:
            raise ValueError(f"none of the {episodes} demonstrations by {policy} succeeded; nothing to learn from")
    eps = [ep for _, ep in order]
    obs = {k: np.concatenate([e[0][k] for e in eps]) for k in eps[0][0]}
    return Demos(obs, np.concatenate([e[1] for e in eps]).astype(np.float32),
                 np.concatenate([e[2] for e in eps]).astype(np.float32),
                 np.array([e[3] for e in eps]), np.array([s for s, _ in order]), every)


def check_demos(path: str | Path, config: CrowdNavConfig, every: int = 1) -> None:
    """ValueError unless `path` holds demonstrations recorded in `config`'s observation layout, deciding every
    `every` env steps, on episodes that no benchmark suite reports (`envs.rl.setting.suite_seed_ranges`)."""
    from envs.observation import observation_space
    from envs.rl.setting import suite_seed_ranges

    demos = Demos.load(path)
    want = {k: tuple(b.shape) for k, b in observation_space(config).spaces.items()}
    have = {k: tuple(v.shape[1:]) for k, v in demos.obs.items()}
    if want != have:
        raise ValueError(f"--demos {path}: recorded with observation {have}, this run observes {want}")
    if demos.decision_every_steps != every:
        raise ValueError(f"--demos {path}: recorded deciding every {demos.decision_every_steps} env steps, this run "
                         f"every {every}")
    reported = sorted({int(s) for s in demos.episode_seed for _, r in suite_seed_ranges() if s in r})
    if reported:
        raise ValueError(f"--demos {path}: episodes of seeds {reported[:5]}{' ...' if len(reported) > 5 else ''} "
                         "are reported by a benchmark suite; demonstrate on other seeds")


def concat(a: Demos, b: Demos) -> Demos:
    """The union of two demonstration sets (DAgger's aggregate); ValueError when their decision periods differ."""
    if a.decision_every_steps != b.decision_every_steps:
        raise ValueError(f"demonstrations at decision periods {a.decision_every_steps} and {b.decision_every_steps} "
                         "env steps do not mix")
    return Demos({k: np.concatenate([a.obs[k], b.obs[k]]) for k in a.obs}, np.concatenate([a.actions, b.actions]),
                 np.concatenate([a.returns, b.returns]), np.concatenate([a.episode_outcome, b.episode_outcome]),
                 np.concatenate([a.episode_seed, b.episode_seed]), a.decision_every_steps)


# The world-frame (x, y) pairs of a holonomic robot's observation (its frame is world-aligned): the goal and the
# velocity in `robot`, positions and velocities in `pedestrians`; every predicted point (last axis) in `predictions`.
ROTATABLE: dict[str, tuple[tuple[int, int], ...]] = {"robot": ((0, 1), (3, 4)), "pedestrians": ((0, 1), (2, 3)),
                                                     "predictions": ((0, 1),)}


def check_rotatable(config: CrowdNavConfig) -> None:
    """ValueError unless turning a whole scene of `config` about the robot is a symmetry of its decisions: a
    holonomic robot (world-aligned observation and action), no wall rays and no walls (which stay where they are)."""
    if config.robot.model != "holonomic":
        raise ValueError(f"rotation augmentation needs the holonomic robot (world-aligned frame); this env's robot is "
                         f"{config.robot.model}, whose observation is already in its own frame")
    if config.observation.wall_rays:
        raise ValueError("rotation augmentation does not turn wall rays; train without --wall-rays")
    if len(np.asarray(CrowdNavEnv(config).crowd.walls).reshape(-1, 4)):
        raise ValueError("rotation augmentation needs a scene without walls (the walls do not turn with the crowd)")


def rotate_scene(obs: dict[str, Any], actions: Any, theta: Any) -> tuple[dict[str, Any], Any]:
    """The same decisions in the scene turned by theta (B,) rad about a holonomic robot: obs {key: (B, ...)} and
    actions (B, 2) (vx, vy over the top speed) as torch tensors; every pair in `ROTATABLE` turns, distances, radii,
    masks and group ids stay (so does the nearest-first row order). A turned action keeps its length, so one inside
    the unit disc stays inside the action box."""
    import torch

    c, s = torch.cos(theta), torch.sin(theta)
    out = dict(obs)
    for key, pairs in ROTATABLE.items():
        if key not in obs:
            continue
        x, turned = obs[key], obs[key].clone()
        shape = (-1,) + (1,) * (x.dim() - 2)
        cb, sb = c.view(shape), s.view(shape)
        for i, j in pairs:
            turned[..., i] = cb * x[..., i] - sb * x[..., j]
            turned[..., j] = sb * x[..., i] + cb * x[..., j]
        out[key] = turned
    a0, a1 = actions[:, 0], actions[:, 1]
    return out, torch.stack([c * a0 - s * a1, s * a0 + c * a1], dim=-1).clamp(-1.0, 1.0)


def _evaluate(policy: Any, obs: dict[str, Any], actions: Any, detach_critic: bool) -> tuple[Any, Any]:
    """(values (B,), log-likelihood of actions (B,)) of an SB3 ActorCriticPolicy; with `detach_critic` the value
    regression does not reach the features the actor shares."""
    if not detach_critic:
        values, log_prob, _ = policy.evaluate_actions(obs, actions)
        return values.flatten(), log_prob
    features = policy.extract_features(obs)
    pi_f, vf_f = features if isinstance(features, tuple) else (features, features)
    latent_pi = policy.mlp_extractor.forward_actor(pi_f)
    latent_vf = policy.mlp_extractor.forward_critic(vf_f.detach())
    log_prob = policy._get_action_dist_from_latent(latent_pi).log_prob(actions)
    return policy.value_net(latent_vf).flatten(), log_prob


def behaviour_clone(model: Any, demos: Demos, epochs: int = 30, batch_size: int = 256, lr: float = 1e-3,
                    value_coef: float = 0.5, reset_log_std: float | None = -0.5, seed: int = 0,
                    rotations: bool = False, detach_critic: bool = False) -> list[float]:
    """Fit `model.policy` (an SB3 ActorCriticPolicy) to the demos; returns the mean loss per epoch.

    Loss per batch: -mean log-likelihood of the expert actions + value_coef x MSE(value, return). `rotations`:
    each sample is turned by its own random angle (`rotate_scene`; the caller checks `check_rotatable`), so the
    actor learns the scene's rotation symmetry instead of needing demonstrations at every heading.
    `detach_critic`: the return regression trains only the critic's own layers. Afterwards the log-std is set to
    `reset_log_std` (None keeps the fitted one). Non-finite loss raises RuntimeError."""
    import torch

    policy = model.policy
    gen = torch.Generator().manual_seed(seed)
    obs = {k: torch.as_tensor(v) for k, v in demos.obs.items()}
    actions, returns = torch.as_tensor(demos.actions), torch.as_tensor(demos.returns)
    opt = torch.optim.Adam(policy.parameters(), lr=lr)
    n, history = len(actions), []
    policy.set_training_mode(True)
    for _ in range(epochs):
        perm, total = torch.randperm(n, generator=gen), 0.0
        for start in range(0, n, batch_size):
            idx = perm[start:start + batch_size]
            batch, target = {k: v[idx] for k, v in obs.items()}, actions[idx]
            if rotations:
                batch, target = rotate_scene(batch, target, torch.rand(len(idx), generator=gen) * (2.0 * np.pi))
            values, log_prob = _evaluate(policy, batch, target, detach_critic)
            loss = -log_prob.mean() + value_coef * torch.nn.functional.mse_loss(values, returns[idx])
            if not torch.isfinite(loss):
                raise RuntimeError("behaviour cloning diverged (non-finite loss)")
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 0.5)
            opt.step()
            total += float(loss.detach()) * len(idx)
        history.append(total / n)
    policy.set_training_mode(False)
    if reset_log_std is not None and hasattr(policy, "log_std"):
        with torch.no_grad():
            policy.log_std.fill_(reset_log_std)
    return history
