"""Episode runner: one task = one episode of one policy in one env config, run locally or on Ray.

`run_task(task)` builds (once per process, cached by settings) the env and the policy, runs the episode and
returns its typed record (and, on request, the trajectories for plots). Every episode starts from a reset env
and policy with the task's seed, so a record does not depend on which process ran it: the local process pool
(the default; "forkserver" on Linux, since torch is not fork-safe), a single process, and Ray tasks give
identical records. A policy that raises inside an episode yields a record with outcome "error" and the
traceback in `error_dir`; the run goes on.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import pickle
import sys
import traceback
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from envs.config import CrowdNavConfig
from envs.policies import PolicyConfig
from envs.records import EpisodeRecord, finite_or_none

BACKENDS = ("local", "ray")


@dataclass(frozen=True)
class EpisodeTask:
    """One episode: env config, policy config, seed; `cell` names the benchmark cell ("" outside one).
    keep_scene: also return trajectories; rrd_path: write a rerun recording; error_dir: tracebacks go here."""

    env: CrowdNavConfig
    policy: PolicyConfig
    seed: int
    cell: str = ""
    fingerprint: str = ""
    keep_scene: bool = False
    rrd_path: str | None = None
    error_dir: str | None = None


def fingerprint(*parts: Any) -> str:
    """A short stable hash of JSON-able settings (identifies what an episode ran under)."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def record_of(task: EpisodeTask, result: Any, policy_name: str) -> EpisodeRecord:
    """The typed record of an `envs.rollout.EpisodeResult` run for `task`."""
    return episode_record(result, policy_name, task.seed, task.cell, task.fingerprint)


def episode_record(result: Any, policy_name: str, seed: int, cell: str = "", fingerprint: str = "") -> EpisodeRecord:
    """The typed record of an `envs.rollout.EpisodeResult` (also for episodes run outside a task, e.g. the
    training evaluation of `envs.train_monitor`)."""
    m = result.metrics
    return EpisodeRecord(
        policy=policy_name, seed=int(seed), outcome=m["outcome"], cell=cell,
        collision_with=m["collision_with"] or None, collision_kind=m["collision_kind"] or None,
        collision_time_s=finite_or_none(m["collision_time_s"]), steps=int(m["steps"]), time_s=float(m["time_s"]),
        time_to_goal_s=finite_or_none(m["time_to_goal_s"]), path_length_m=float(m["path_length_m"]),
        min_distance_m=finite_or_none(m["min_distance_m"]), discomfort_frequency=float(m["discomfort_frequency"]),
        group_intrusion=bool(m["group_intrusion"]), intrusion_fraction=float(m["intrusion_fraction"]),
        spawn_contacts=int(m["spawn_contacts"]), plans=int(m["plans"]), fallbacks=int(m["fallbacks"]),
        ret=float(result.ret),
        wall_time_s=float(result.wall_time_s), fingerprint=fingerprint,
        solve_times_ms=tuple(float(t) for t in result.solve_times_ms))


class _Runner:
    """One env and one policy, built once and reused for every episode of a process."""

    def __init__(self, env_config: CrowdNavConfig, policy_config: PolicyConfig) -> None:
        from envs.env import CrowdNavEnv
        from envs.policies import make_policy

        self.env = CrowdNavEnv(env_config)
        self.policy = make_policy(policy_config, self.env)
        self.policy_name = policy_config.name

    def run(self, task: EpisodeTask) -> dict[str, Any]:
        from envs.rollout import run_episode

        try:
            if task.rrd_path is not None:
                from envs.rerun_observer import RerunObserver

                with RerunObserver(task.rrd_path) as observer:
                    result = run_episode(task.env, task.policy, task.seed, task.keep_scene, observer, self.env,
                                         self.policy)
            else:
                result = run_episode(task.env, task.policy, task.seed, task.keep_scene, None, self.env, self.policy)
        except Exception as exc:  # a (plug-in) policy failed inside the episode: record it and go on
            return {"record": _error_record(task, self.policy_name, exc)}
        out: dict[str, Any] = {"record": record_of(task, result, self.policy_name)}
        if task.keep_scene:
            out["scene"] = {"seed": int(task.seed), "outcome": result.metrics["outcome"], "robot_xy": result.robot_xy,
                            "goal": result.goal, "ped_xy": result.ped_xy, "ped_groups": result.ped_groups,
                            "walls": np.asarray(self.env.crowd.walls, float).reshape(-1, 2, 2),
                            "bounds": tuple(self.env.crowd.bounds)}
        return out


def _error_record(task: EpisodeTask, policy_name: str, exc: BaseException) -> EpisodeRecord:
    message = f"{type(exc).__name__}: {exc}".splitlines()[0][:500]
    if task.error_dir is not None:
        path = Path(task.error_dir) / f"{task.cell or 'episode'}_{policy_name.replace('/', '_')}_seed{task.seed}.txt"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(traceback.format_exception(exc)))
        message += f" (traceback: {path})"
    return EpisodeRecord(policy=policy_name, seed=int(task.seed), outcome="error", cell=task.cell, error=message,
                         fingerprint=task.fingerprint)


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


def _mp_context() -> multiprocessing.context.BaseContext:
    if sys.platform.startswith("linux") and "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["envs.runner", "envs.rollout"])  # imports once (no torch: not fork-safe)
        return ctx
    return multiprocessing.get_context("spawn")


def run_tasks(tasks: Sequence[EpisodeTask], workers: int = 1, backend: str = "local",
              address: str | None = None) -> Iterator[tuple[int, dict[str, Any]]]:
    """Run the tasks, yielding (index into `tasks`, result) as each finishes (order not guaranteed).

    backend "local": `workers` processes (1: this process); "ray": Ray tasks on the cluster at `address`
    ("auto", "HOST:PORT") or, with None, a local Ray instance of `workers` CPUs. An error that is not a
    policy's (e.g. an env that cannot be built) stops the run and is raised.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; valid names: {', '.join(BACKENDS)}")
    if backend == "ray":
        from envs.ray_backend import run_on_ray

        yield from run_on_ray(tasks, workers, address)
    elif workers <= 1 or len(tasks) <= 1:
        for i, task in enumerate(tasks):
            yield i, run_task(task)
    else:
        with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=_mp_context()) as pool:
            futures = {pool.submit(run_task, task): i for i, task in enumerate(tasks)}
            pending = set(futures)
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in done:
                        yield futures[fut], fut.result()
            finally:
                for fut in pending:
                    fut.cancel()
