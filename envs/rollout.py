"""Run one episode of a policy in the env and collect its metrics, trajectories and planner statistics."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from envs.config import CrowdNavConfig
from envs.env import CrowdNavEnv
from envs.policies import PolicyConfig, make_policy


@dataclass
class EpisodeResult:
    """One episode.

    metrics: `EpisodeMetrics.as_dict()` plus the planner's plan count, fallback count and solve times (ms).
    robot_xy: (T + 1, 2) robot positions, m. goal: (2,) m. ret: the undiscounted return.
    ped_xy: per step (N_t, 2) positions and group ids (kept only when `keep_scene` is set).
    """

    seed: int
    policy: str
    metrics: dict[str, Any]
    robot_xy: np.ndarray
    goal: np.ndarray
    ret: float
    solve_times_ms: list[float] = field(default_factory=list)
    ped_xy: list[np.ndarray] = field(default_factory=list)
    ped_groups: list[np.ndarray] = field(default_factory=list)
    wall_time_s: float = 0.0


def run_episode(config: CrowdNavConfig, policy_spec: str | PolicyConfig, seed: int, keep_scene: bool = False,
                observer: Any = None, env: CrowdNavEnv | None = None, policy: Any = None) -> EpisodeResult:
    """Reset with `seed`, act with the policy (a name or `PolicyConfig`; or `policy`, already built) until the
    episode ends. `observer.log(frame)` (e.g. a `RerunObserver`) receives every frame. Pass env/policy to reuse
    them across episodes."""
    start = time.perf_counter()
    env = env or CrowdNavEnv(config)
    policy = policy or make_policy(policy_spec, env)
    obs, _ = env.reset(seed=seed)
    policy.reset(env, seed)
    calls0, fallbacks0, times0 = _counts(policy)
    robot, ret, done, info = [env.robot_state[:2].copy()], 0.0, False, {}
    peds, groups = [], []
    scalars: dict[str, float] = {}
    while not done:
        action = policy.act(obs, env)
        if observer is not None:
            observer.log(env.frame(scalars))
        if keep_scene:
            p = env.pedestrians()
            peds.append(p.pos.copy())
            groups.append(p.group_id.copy())
        obs, reward, terminated, truncated, info = env.step(action)
        robot.append(env.robot_state[:2].copy())
        ret += reward
        done = terminated or truncated
        scalars = {**info["reward_terms"], "reward": reward, "goal_distance_m": info["goal_distance_m"],
                   "min_surface_distance_m": min(info["min_surface_distance_m"], 99.0)}
    if observer is not None:
        observer.log(env.frame(scalars))
    calls1, fallbacks1, times1 = _counts(policy)
    metrics = dict(info["episode_metrics"])
    metrics.update(plans=calls1 - calls0, fallbacks=fallbacks1 - fallbacks0)
    return EpisodeResult(seed, policy.name, metrics, np.array(robot), env.goal.copy(), ret,
                         [t * 1e3 for t in times1[len(times0):]], peds, groups, time.perf_counter() - start)


def _counts(policy: Any) -> tuple[int, int, list[float]]:
    """(plans, fallbacks, solve times s) so far; zeros for a policy without `stats` (e.g. a plug-in)."""
    stats = getattr(policy, "stats", None)
    if stats is None:
        return 0, 0, []
    fallbacks = sum(v for k, v in stats.counts.items() if k.startswith("fallback_"))
    return stats.counts["calls"], fallbacks, list(stats.solve_times_s)
