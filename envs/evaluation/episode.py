"""One episode: run a policy in the env (`run_episode`), and one benchmark task (`EpisodeTask` -> `run_task`).

`run_episode` resets the env with a seed, acts with the policy until the episode ends and collects its metrics,
trajectories and planner statistics. `run_task(task)` builds (once per process, cached by settings) the env and
the policy, runs the task's episode and returns its typed record (and, on request, the trajectories for plots).
Every episode starts from a reset env and policy with the task's seed, so a record does not depend on which
process ran it (`envs.evaluation.pool`). A policy that raises inside an episode yields a record with outcome
"error" and the traceback in `error_dir`; the run goes on.
"""

from __future__ import annotations

import hashlib
import json
import math
import pickle
import time
import traceback
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from envs.config import CrowdNavConfig
from envs.drawing.video import DEFAULT_SIZE_PX, check_video_settings, record_video
from envs.env import CrowdNavEnv
from envs.evaluation.records import SOCIAL_FLOAT_FIELDS, EpisodeRecord, finite_or_none
from envs.policies import PolicyConfig, decide, make_policy


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
    env.reset(seed=seed)
    policy.reset(seed)
    calls0, fallbacks0, times0 = _counts(policy)
    robot, ret, done, info = [env.robot_state[:2].copy()], 0.0, False, {}
    peds, groups = [], []
    scalars: dict[str, float] = {}
    while not done:
        decision = decide(policy, env)
        if observer is not None:
            observer.log(env.frame(scalars))
        if keep_scene:
            p = env.pedestrians()
            peds.append(p.pos.copy())
            groups.append(p.group_id.copy())
        _, reward, terminated, truncated, info = env.step_decision(decision)
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


@dataclass(frozen=True)
class VideoSpec:
    """A video of an episode: file `path`, format `fmt` (mp4 or gif), square frames of `size_px` px (even)."""

    path: str
    fmt: str = "mp4"
    size_px: int = DEFAULT_SIZE_PX

    def __post_init__(self) -> None:
        check_video_settings(self.fmt, self.size_px)


class _Observers:
    """Hands every frame to each of several observers (a rerun recording and a video)."""

    def __init__(self, observers: list[Any]) -> None:
        self.observers = observers

    def log(self, frame: Any) -> None:
        for observer in self.observers:
            observer.log(frame)


@dataclass(frozen=True)
class EpisodeTask:
    """One episode: env config, policy config, seed; `cell` names the benchmark cell ("" outside one).
    keep_scene: also return trajectories; rrd_path: write a rerun recording; video: write a video (drawn in the
    process that runs the episode, frame rate the env's `render_fps`); error_dir: tracebacks go here."""

    env: CrowdNavConfig
    policy: PolicyConfig
    seed: int
    cell: str = ""
    fingerprint: str = ""
    keep_scene: bool = False
    rrd_path: str | None = None
    error_dir: str | None = None
    video: VideoSpec | None = None


def fingerprint(*parts: Any) -> str:
    """A short stable hash of JSON-able settings (identifies what an episode ran under)."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def record_of(task: EpisodeTask, result: Any, policy_name: str) -> EpisodeRecord:
    """The typed record of an `EpisodeResult` run for `task`."""
    return episode_record(result, policy_name, task.seed, task.cell, task.fingerprint)


def episode_record(result: Any, policy_name: str, seed: int, cell: str = "", fingerprint: str = "") -> EpisodeRecord:
    """The typed record of an `EpisodeResult` (also for episodes run outside a task, e.g. the
    training evaluation of `envs.rl.monitor`)."""
    m = result.metrics
    return EpisodeRecord(
        policy=policy_name, seed=int(seed), outcome=m["outcome"], cell=cell,
        collision_with=m["collision_with"] or None, at_fault=m["at_fault"] or None,
        collision_time_s=finite_or_none(m["collision_time_s"]), steps=int(m["steps"]), time_s=float(m["time_s"]),
        time_to_goal_s=finite_or_none(m["time_to_goal_s"]), path_length_m=float(m["path_length_m"]),
        min_distance_m=finite_or_none(m["min_distance_m"]), discomfort_frequency=float(m["discomfort_frequency"]),
        group_intrusion=None if m["group_intrusion"] is None else bool(m["group_intrusion"]),
        intrusion_fraction=finite_or_none(m["intrusion_fraction"]),
        spawn_contacts=int(m["spawn_contacts"]), plans=int(m["plans"]), fallbacks=int(m["fallbacks"]),
        ret=float(result.ret),
        wall_time_s=float(result.wall_time_s), fingerprint=fingerprint,
        solve_times_ms=tuple(float(t) for t in result.solve_times_ms), **social_fields(m))


def social_fields(m: dict[str, Any]) -> dict[str, Any]:
    """The social-navigation fields of a record from `EpisodeMetrics.as_dict()` (None where a value is missing)."""
    out = {k: finite_or_none(m.get(k)) for k in SOCIAL_FLOAT_FIELDS}
    ttc = m.get("min_ttc_s")
    out["collision_course"] = None if ttc is None else bool(math.isfinite(ttc))
    out["group_collision"] = None if m.get("group_collision") is None else bool(m["group_collision"])
    out["itr_states"] = None if m.get("itr_states") is None else int(m["itr_states"])
    return out


class _Runner:
    """One env and one policy, built once and reused for every episode of a process."""

    def __init__(self, env_config: CrowdNavConfig, policy_config: PolicyConfig) -> None:
        self.env = CrowdNavEnv(env_config)
        self.policy = make_policy(policy_config, self.env)
        self.policy_name = policy_config.name

    def run(self, task: EpisodeTask) -> dict[str, Any]:
        try:
            result = self._episode(task)
        except Exception as exc:  # a (plug-in) policy failed inside the episode: record it and go on
            return {"record": _error_record(task, self.policy_name, exc)}
        out: dict[str, Any] = {"record": record_of(task, result, self.policy_name)}
        if task.keep_scene:
            out["scene"] = {"seed": int(task.seed), "outcome": result.metrics["outcome"], "robot_xy": result.robot_xy,
                            "goal": result.goal, "ped_xy": result.ped_xy, "ped_groups": result.ped_groups,
                            "walls": np.asarray(self.env.crowd.walls, float).reshape(-1, 2, 2),
                            "bounds": tuple(self.env.crowd.bounds)}
        return out

    def _episode(self, task: EpisodeTask) -> EpisodeResult:
        """Run the task's episode with its observers: a rerun recording and/or a video (written atomically)."""
        with ExitStack() as stack:
            observers: list[Any] = []
            if task.rrd_path is not None:
                from envs.drawing.rerun_observer import RerunObserver

                observers.append(stack.enter_context(RerunObserver(task.rrd_path)))

            def play(*more: Any) -> EpisodeResult:
                obs = [*observers, *more]
                return run_episode(task.env, task.policy, task.seed, task.keep_scene,
                                   _Observers(obs) if obs else None, self.env, self.policy)

            if task.video is None:
                return play()
            v = task.video
            return record_video(v.path, play, fmt=v.fmt, fps=self.env.metadata["render_fps"], size_px=v.size_px)


def _error_record(task: EpisodeTask, policy_name: str, exc: BaseException) -> EpisodeRecord:
    message = f"{type(exc).__name__}: {exc}".splitlines()[0][:500]
    if task.error_dir is not None:
        path = Path(task.error_dir) / f"{task.cell or 'episode'}_{policy_name.replace('/', '_')}_seed{task.seed}.txt"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(traceback.format_exception(exc)))
        message += f" (traceback: {path})"
    return EpisodeRecord(policy=policy_name, seed=int(task.seed), outcome="error", cell=task.cell, error=message,
                         fingerprint=task.fingerprint)


def error_record(task: EpisodeTask, message: str) -> EpisodeRecord:
    """The error record of a task that produced no episode (e.g. its worker process died twice), with `message`."""
    return EpisodeRecord(policy=task.policy.name, seed=int(task.seed), outcome="error", cell=task.cell,
                         error=message, fingerprint=task.fingerprint)


_CACHE: dict[bytes, _Runner] = {}  # per process: runners by settings (few distinct ones per run)


def run_task(task: EpisodeTask) -> dict[str, Any]:
    """Run one episode (building this process's runner for the task's settings on first use)."""
    key = pickle.dumps((task.env, task.policy))
    runner = _CACHE.get(key)
    if runner is None:
        if len(_CACHE) >= 8:
            _CACHE.clear()
        runner = _CACHE[key] = _Runner(task.env, task.policy)
    return runner.run(task)
