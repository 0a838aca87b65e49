"""Evaluation harness: a policy over a fixed list of episode seeds, aggregated metrics, and report files.

`evaluate(policy, config, episodes, seed, workers, record, out_dir)` runs the episodes with seeds
seed, seed + 1, ..., seed + episodes - 1 (the env's `reset(seed)` fixes the crowd and the robot's route, so
every policy sees the same episodes), in `workers` processes ("forkserver" on Linux, "spawn" elsewhere: torch
is not fork-safe), each building its env and policy once. Every episode starts from a reset env and policy, so
the per-episode results do not depend on the worker count. Definitions of the metrics: the README's
"Evaluation metrics (envs)" section and `aggregate`.

Outputs in `out_dir`: `<stem>.json` (the dict returned; written atomically), `<stem>.md` (a markdown table),
`<stem>.png` (rates and example trajectories) and `<stem>_seed<S>.rrd` for the first `record` episodes
(`envs.rerun_observer.RerunObserver`). `stem` defaults to the policy name. `compare(results)` and
`compare_png(results, path)` put several policies side by side.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import pickle
import sys
import tempfile
import time
from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from envs.config import REPLAY_SCENARIO, CrowdNavConfig

Z95 = 1.959963984540054  # two-sided 95% normal quantile
N_DRAWN = 3  # episodes drawn in the trajectories panel of the PNG
RATE_KEYS = ("success_rate", "collision_rate", "timeout_rate", "group_intrusion_rate")
RATE_LABELS = {"success_rate": "success", "collision_rate": "collision", "timeout_rate": "timeout",
               "group_intrusion_rate": "group intrusion"}
EPISODE_KEYS = ("seed", "outcome", "collision_with", "steps", "time_s", "time_to_goal_s", "path_length_m",
                "min_distance_m", "discomfort_frequency", "group_intrusion", "intrusion_fraction", "plans",
                "fallbacks", "solver_calls", "return")


# ------------------------------------------------------------------------------------------ statistics
def wilson_interval(k: int, n: int, z: float = Z95) -> list[float] | None:
    """The Wilson score interval [lo, hi] for k successes in n trials (None when n == 0)."""
    if n <= 0:
        return None
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return [max(0.0, centre - half), min(1.0, centre + half)]


def _finite(value: Any) -> float | None:
    """value as a float, or None when it is missing, NaN or infinite (JSON has no NaN/inf)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def config_summary(config: CrowdNavConfig) -> dict[str, Any]:
    """The settings a published number needs next to it (crowd size, visibility, kinematics, time limit, dt)."""
    replay = config.scenario == REPLAY_SCENARIO
    return {
        "scenario": config.scenario,
        "n_pedestrians": None if replay else config.n_pedestrians,
        "robot_visible": None if replay else config.robot_visible,
        "robot_model": config.robot.model,
        "robot_radius_m": config.robot.radius_m,
        "time_limit_s": config.time_limit_s,
        "dt_s": config.dt_s,
        "goal_tolerance_m": config.goal_tolerance_m,
        "discomfort_distance_m": config.discomfort_distance_m,
        "group_space_m": config.group_space_m,
        "replay_file": str(config.replay.path) if replay else None,
        "groups_file": str(config.replay.groups_path) if replay and config.replay.groups_path else None,
    }


def aggregate(records: list[dict[str, Any]], policy: str = "", config: CrowdNavConfig | None = None,
              seed: int | None = None) -> dict[str, Any]:
    """Aggregate per-episode records (see `episode_record`) into the evaluation summary.

    Rates are over all episodes (`group_intrusion_rate_success` over successful ones); time to goal and path
    length are over successful episodes; min distance is the mean of the per-episode minima (episodes in which
    no pedestrian was ever in the scene are left out) and `min_distance_overall_m` their minimum; solve-time
    percentiles are over every solver call of every episode (None without any); fallback rate = fallbacks /
    plans (None without plans). Each record needs: outcome ("success" | "collision" | "timeout"),
    time_to_goal_s, path_length_m, min_distance_m, discomfort_frequency, group_intrusion, plans, fallbacks and
    solve_times_ms (a list).
    """
    n = len(records)
    if n == 0:
        raise ValueError("no episodes to aggregate")
    outcomes = [r["outcome"] for r in records]
    bad = sorted(set(outcomes) - {"success", "collision", "timeout"})
    if bad:
        raise ValueError(f"unknown episode outcome(s) {bad}")
    k_succ, k_coll, k_time = (outcomes.count(o) for o in ("success", "collision", "timeout"))
    succ = [r for r in records if r["outcome"] == "success"]
    k_intr = sum(bool(r["group_intrusion"]) for r in records)
    ttg = [v for v in (_finite(r["time_to_goal_s"]) for r in succ) if v is not None]
    mind = [v for v in (_finite(r["min_distance_m"]) for r in records) if v is not None]
    times = np.concatenate([np.asarray(r.get("solve_times_ms", []), float) for r in records])
    plans = int(sum(r["plans"] for r in records))
    fallbacks = int(sum(r["fallbacks"] for r in records))
    out: dict[str, Any] = {
        "policy": policy,
        "scenario": config.scenario if config is not None else None,
        "seed": seed,
        "episodes": n,
        "success_rate": k_succ / n,
        "collision_rate": k_coll / n,
        "timeout_rate": k_time / n,
        "group_intrusion_rate": k_intr / n,
        "group_intrusion_rate_success": (sum(bool(r["group_intrusion"]) for r in succ) / len(succ)) if succ
        else None,
        "success_rate_ci95": wilson_interval(k_succ, n),
        "collision_rate_ci95": wilson_interval(k_coll, n),
        "timeout_rate_ci95": wilson_interval(k_time, n),
        "group_intrusion_rate_ci95": wilson_interval(k_intr, n),
        "wall_collisions": sum(r.get("collision_with") == "wall" for r in records),
        "time_to_goal_s": _mean(ttg),
        "time_to_goal_median_s": float(np.median(ttg)) if ttg else None,
        "path_length_m": _mean([float(r["path_length_m"]) for r in succ]),
        "min_distance_m": _mean(mind),
        "min_distance_overall_m": min(mind) if mind else None,
        "discomfort_frequency": _mean([float(r["discomfort_frequency"]) for r in records]),
        "solve_time_p50_ms": float(np.percentile(times, 50)) if times.size else None,
        "solve_time_p95_ms": float(np.percentile(times, 95)) if times.size else None,
        "solver_calls": int(times.size),
        "plans": plans,
        "fallbacks": fallbacks,
        "fallback_rate": fallbacks / plans if plans else None,
        "mean_return": _mean([float(r["return"]) for r in records if "return" in r]),
        "config": config_summary(config) if config is not None else None,
        "episode_list": [{k: r.get(k) for k in EPISODE_KEYS} for r in records],
    }
    return out


# ------------------------------------------------------------------------------------ running episodes
def episode_record(result: Any) -> dict[str, Any]:
    """A JSON-ready per-episode record of an `envs.rollout.EpisodeResult` (non-finite numbers become None);
    it keeps the episode's solver times (`solve_times_ms`) for `aggregate`."""
    m = result.metrics
    return {
        "seed": int(result.seed), "outcome": m["outcome"], "collision_with": m["collision_with"] or None,
        "steps": int(m["steps"]), "time_s": float(m["time_s"]), "time_to_goal_s": _finite(m["time_to_goal_s"]),
        "path_length_m": float(m["path_length_m"]), "min_distance_m": _finite(m["min_distance_m"]),
        "discomfort_frequency": float(m["discomfort_frequency"]), "group_intrusion": bool(m["group_intrusion"]),
        "intrusion_fraction": float(m["intrusion_fraction"]), "plans": int(m["plans"]),
        "fallbacks": int(m["fallbacks"]), "solver_calls": len(result.solve_times_ms), "return": float(result.ret),
        "solve_times_ms": [float(t) for t in result.solve_times_ms], "wall_time_s": float(result.wall_time_s),
    }


class _Runner:
    """One env and one policy, built once and reused for every episode of a process."""

    def __init__(self, config: CrowdNavConfig, policy: str, predictor: str | None) -> None:
        from envs.env import CrowdNavEnv
        from envs.policies import GPGraphPolicy, make_policy
        from planner import MPCConfig

        self.config, self.policy_name = config, policy
        self.env = CrowdNavEnv(config)
        if policy == "mpc-gpgraph" and predictor is not None:
            self.policy = GPGraphPolicy(replace(MPCConfig(), robot=config.robot), predictor=predictor)
        else:
            self.policy = make_policy(policy, self.env)

    def run(self, seed: int, keep_scene: bool, rrd_path: str | None) -> dict[str, Any]:
        from envs.rollout import run_episode

        if rrd_path is not None:
            from envs.rerun_observer import RerunObserver

            with RerunObserver(rrd_path) as observer:
                result = run_episode(self.config, self.policy_name, seed, keep_scene, observer, self.env,
                                     self.policy)
        else:
            result = run_episode(self.config, self.policy_name, seed, keep_scene, None, self.env, self.policy)
        out = {"record": episode_record(result)}
        if keep_scene:
            out["scene"] = {"seed": int(seed), "outcome": result.metrics["outcome"], "robot_xy": result.robot_xy,
                            "goal": result.goal, "ped_xy": result.ped_xy, "ped_groups": result.ped_groups,
                            "walls": np.asarray(self.env.crowd.walls, float).reshape(-1, 2, 2),
                            "bounds": tuple(self.env.crowd.bounds)}
        return out


_WORKER: tuple[bytes, _Runner] | None = None  # the runner of a pool process, with the key it was built for


def _worker_run(key: bytes, seed: int, keep_scene: bool, rrd_path: str | None) -> dict[str, Any]:
    """Run one episode in a pool process, building its runner on the first call (errors reach the parent)."""
    global _WORKER
    if _WORKER is None or _WORKER[0] != key:
        config, policy, predictor = pickle.loads(key)
        _WORKER = (key, _Runner(config, policy, predictor))
    return _WORKER[1].run(seed, keep_scene, rrd_path)


def _mp_context() -> multiprocessing.context.BaseContext:
    if sys.platform.startswith("linux") and "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["envs.evaluate", "envs.rollout"])  # imports once (no torch: not fork-safe)
        return ctx
    return multiprocessing.get_context("spawn")


def run_episodes(policy: str, config: CrowdNavConfig, seeds: list[int], workers: int = 1,
                 record: set[int] = frozenset(), draw: set[int] = frozenset(), out_dir: Path | None = None,
                 stem: str | None = None, predictor: str | None = None, progress: bool = True) -> list[dict[str, Any]]:
    """Run the episodes of `seeds` (in order of the list; results in the same order): `{"record": ...}` each,
    plus `"scene"` (trajectories) for seeds in `draw`; seeds in `record` are written to
    `out_dir/<stem>_seed<S>.rrd`."""
    from tqdm.auto import tqdm

    stem = stem or policy
    jobs = [(s, s in draw, str(Path(out_dir) / f"{stem}_seed{s}.rrd") if s in record and out_dir else None)
            for s in seeds]
    results: dict[int, dict[str, Any]] = {}
    bar = tqdm(total=len(jobs), desc=stem, unit="ep", disable=not progress, file=sys.stderr)
    try:
        if workers <= 1 or len(jobs) <= 1:
            runner = _Runner(config, policy, predictor)
            for i, job in enumerate(jobs):
                results[i] = runner.run(*job)
                bar.update(1)
        else:
            key = pickle.dumps((config, policy, predictor))
            with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=_mp_context()) as pool:
                futures = {pool.submit(_worker_run, key, *job): i for i, job in enumerate(jobs)}
                pending = set(futures)
                while pending:
                    done, pending = wait(pending, return_when=FIRST_EXCEPTION)
                    for fut in done:
                        if fut.exception() is not None:
                            for other in pending:
                                other.cancel()
                            raise fut.exception()
                        results[futures[fut]] = fut.result()
                        bar.update(1)
    finally:
        bar.close()
    return [results[i] for i in range(len(jobs))]


def evaluate(policy: str, config: CrowdNavConfig, episodes: int = 20, seed: int = 0, workers: int = 1,
             record: int = 2, out_dir: str | Path | None = None, *, predictor: str | None = None,
             stem: str | None = None, draw: int = N_DRAWN, progress: bool = True) -> dict[str, Any]:
    """Evaluate `policy` (a name of `envs.policies.POLICIES`) on episodes seed .. seed + episodes - 1.

    Args:
        workers: processes; 1 runs in this process. The per-episode results do not depend on it.
        record: the first `record` episodes are written as rerun recordings (needs `out_dir`).
        out_dir: where `<stem>.json/.md/.png` and the recordings go; None writes nothing.
        predictor: for mpc-gpgraph, a predictor name or checkpoint path instead of the policy's default.
        stem: file name stem of the outputs (default: the policy name).
        draw: episodes drawn in the PNG's trajectories panels (the first ones).
        progress: show a tqdm bar over episodes (on stderr).

    Returns the JSON-ready summary (see `aggregate`) with `run` (workers, wall time, files written).
    """
    from envs.policies import POLICIES

    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; valid names: {', '.join(POLICIES)}")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if config.scenario != REPLAY_SCENARIO:
        config.sim_config()  # raises ValueError on an inconsistent crowd before any worker starts
    stem = stem or policy
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(seed, seed + episodes))
    record_seeds = set(seeds[:max(0, record)]) if out is not None else set()
    draw_seeds = set(seeds[:max(0, draw)]) if out is not None else set()
    start = time.perf_counter()
    runs = run_episodes(policy, config, seeds, workers, record_seeds, draw_seeds, out, stem, predictor, progress)
    wall = time.perf_counter() - start
    records = [r["record"] for r in runs]
    result = aggregate(records, policy, config, seed)
    result["predictor"] = predictor
    files = []
    if out is not None:
        files = [f"{stem}.json", f"{stem}.md", f"{stem}.png"] + [f"{stem}_seed{s}.rrd" for s in sorted(record_seeds)]
    result["run"] = {"workers": workers, "wall_time_s": wall,
                     "episode_wall_time_s": _mean([r["wall_time_s"] for r in records]), "files": files}
    if out is not None:
        write_text_atomic(out / f"{stem}.md", markdown_table(result) + "\n")
        plot_result(result, [r["scene"] for r in runs if "scene" in r], out / f"{stem}.png")
        write_json_atomic(out / f"{stem}.json", result)
    return result


# ---------------------------------------------------------------------------------------------- output
_FILE_MODE = 0o644  # mkstemp creates 0600 files; reports are meant to be shared


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write text to a temporary file in the same folder, then rename it over `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, _FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json_atomic(path: str | Path, obj: Any) -> None:
    """JSON (strict: no NaN or inf) written atomically."""
    write_text_atomic(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


def _fmt(value: Any, digits: int = 2) -> str:
    if value is None:
        return "–"
    if isinstance(value, float | np.floating):
        return f"{value:.{digits}f}"
    return str(value)


def _rate(result: dict[str, Any], key: str) -> str:
    ci = result.get(f"{key}_ci95")
    text = _fmt(result[key])
    return f"{text} [{ci[0]:.2f}, {ci[1]:.2f}]" if ci else text


def describe_config(result: dict[str, Any]) -> str:
    """One line: scenario, crowd, visibility, time limit, dt, seeds."""
    c = result.get("config") or {}
    crowd = (f"replay of {c.get('replay_file')}" if c.get("scenario") == REPLAY_SCENARIO else
             f"{c.get('n_pedestrians')} pedestrians, {'visible' if c.get('robot_visible') else 'invisible'} robot")
    seeds = f"seeds {result['seed']}..{result['seed'] + result['episodes'] - 1}" if result.get("seed") is not None \
        else f"{result['episodes']} episodes"
    return (f"{c.get('scenario')}: {crowd} ({c.get('robot_model')}), time limit {_fmt(c.get('time_limit_s'), 0)} s, "
            f"dt {c.get('dt_s')} s, {seeds}")


def markdown_table(result: dict[str, Any]) -> str:
    """A markdown table of one policy's summary."""
    rows = [
        ("episodes", str(result["episodes"])),
        ("success rate [95% CI]", _rate(result, "success_rate")),
        ("collision rate [95% CI]", _rate(result, "collision_rate")),
        ("timeout rate", _fmt(result["timeout_rate"])),
        ("group intrusion rate (all episodes)", _fmt(result["group_intrusion_rate"])),
        ("group intrusion rate (successes)", _fmt(result["group_intrusion_rate_success"])),
        ("time to goal, mean / median (s)",
         f"{_fmt(result['time_to_goal_s'])} / {_fmt(result['time_to_goal_median_s'])}"),
        ("path length (m)", _fmt(result["path_length_m"])),
        ("min distance, mean / overall (m)",
         f"{_fmt(result['min_distance_m'])} / {_fmt(result['min_distance_overall_m'])}"),
        ("discomfort frequency", _fmt(result["discomfort_frequency"], 3)),
        ("solve time p50 / p95 (ms)",
         f"{_fmt(result['solve_time_p50_ms'], 1)} / {_fmt(result['solve_time_p95_ms'], 1)}"),
        ("fallback rate", _fmt(result["fallback_rate"], 3)),
    ]
    lines = [f"**{result['policy']}** — {describe_config(result)}", "", "| metric | value |", "|---|---|"]
    lines += [f"| {name} | {value} |" for name, value in rows]
    return "\n".join(lines)


COMPARE_COLUMNS = (
    ("success [95% CI]", lambda r: _rate(r, "success_rate")),
    ("collision [95% CI]", lambda r: _rate(r, "collision_rate")),
    ("timeout", lambda r: _fmt(r["timeout_rate"])),
    ("intrusion", lambda r: _fmt(r["group_intrusion_rate"])),
    ("intrusion (succ.)", lambda r: _fmt(r["group_intrusion_rate_success"])),
    ("time to goal (s)", lambda r: _fmt(r["time_to_goal_s"])),
    ("path (m)", lambda r: _fmt(r["path_length_m"])),
    ("min dist (m)", lambda r: _fmt(r["min_distance_m"])),
    ("discomfort", lambda r: _fmt(r["discomfort_frequency"], 3)),
    ("solve p50/p95 (ms)", lambda r: f"{_fmt(r['solve_time_p50_ms'], 1)}/{_fmt(r['solve_time_p95_ms'], 1)}"),
    ("fallback", lambda r: _fmt(r["fallback_rate"], 3)),
)


def compare(results: list[dict[str, Any]]) -> str:
    """One markdown table, a row per policy, the key metrics as columns (config line from the first)."""
    if not results:
        raise ValueError("nothing to compare")
    header = "| policy | episodes | " + " | ".join(name for name, _ in COMPARE_COLUMNS) + " |"
    lines = [describe_config(results[0]), "", header, "|" + "---|" * (len(COMPARE_COLUMNS) + 2)]
    for r in results:
        lines.append(f"| {r['policy']} | {r['episodes']} | " + " | ".join(f(r) for _, f in COMPARE_COLUMNS) + " |")
    return "\n".join(lines)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save_figure(fig: Any, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, format="png", dpi=110)
        os.chmod(tmp, _FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _rate_errors(results: list[dict[str, Any]], key: str) -> np.ndarray:
    """(2, P) asymmetric error bars of the rate `key` from its Wilson interval (zeros where there is none)."""
    err = np.zeros((2, len(results)))
    for j, r in enumerate(results):
        ci = r.get(f"{key}_ci95")
        if ci:
            err[:, j] = [max(0.0, r[key] - ci[0]), max(0.0, ci[1] - r[key])]
    return err


def _rates_panel(ax: Any, results: list[dict[str, Any]]) -> None:
    """Grouped bars: the rates (groups) x policies (bars), with the 95% Wilson intervals."""
    width = 0.8 / len(results)
    x = np.arange(len(RATE_KEYS))
    for j, r in enumerate(results):
        vals = [r[k] for k in RATE_KEYS]
        err = np.concatenate([_rate_errors([r], k) for k in RATE_KEYS], axis=1)
        bars = ax.bar(x + (j - (len(results) - 1) / 2) * width, vals, width, yerr=err, capsize=3,
                      label=r["policy"])
        for b, v, top in zip(bars, vals, err[1], strict=True):
            ax.text(b.get_x() + b.get_width() / 2, v + top + 0.02, f"{v:.2f}", ha="center", va="bottom",
                    fontsize=7)
    ax.set_xticks(x, [RATE_LABELS[k] for k in RATE_KEYS])
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("fraction of episodes (95% Wilson CI)")
    ax.grid(axis="y", alpha=0.3)


def _trajectory_panel(ax: Any, scene: dict[str, Any]) -> None:
    from crowdsim.recording import N_COLOURS, palette

    colours = palette(N_COLOURS) / 255.0
    for wall in scene["walls"]:
        ax.plot(wall[:, 0], wall[:, 1], color="0.25", lw=2)
    if scene["ped_xy"]:
        pos = np.concatenate(scene["ped_xy"])
        gid = np.concatenate(scene["ped_groups"]).astype(int)
        if len(pos):
            ax.scatter(pos[:, 0], pos[:, 1], s=2.0, c=colours[gid % N_COLOURS], alpha=0.3, lw=0)
    xy = scene["robot_xy"]
    ax.plot(xy[:, 0], xy[:, 1], color="k", lw=1.8)
    ax.plot(*xy[0], "o", color="tab:green", ms=7, label="start")
    ax.plot(*scene["goal"], "*", color="tab:red", ms=12, label="goal")
    ax.plot(*xy[-1], "o", mfc="none", mec="k", ms=7)
    x0, y0, x1, y1 = scene["bounds"]
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_title(f"seed {scene['seed']}: {scene['outcome']}", fontsize=9)
    ax.tick_params(labelsize=7)


def plot_result(result: dict[str, Any], scenes: list[dict[str, Any]], path: str | Path) -> None:
    """PNG: the rates with their 95% intervals, and one panel per example episode (walls, robot path from start
    to goal, the pedestrians' positions over the episode faint in their group's colour)."""
    plt = _pyplot()
    n = len(scenes)
    fig, axes = plt.subplots(1, 1 + n, figsize=(4.8 + 3.6 * n, 4.2), squeeze=False,
                             gridspec_kw={"width_ratios": [1.3] + [1.0] * n})
    _rates_panel(axes[0, 0], [result])
    axes[0, 0].set_title(f"{result['policy']} ({result['episodes']} episodes)", fontsize=10)
    for ax, scene in zip(axes[0, 1:], scenes, strict=True):
        _trajectory_panel(ax, scene)
    if n:
        axes[0, 1].legend(loc="upper right", fontsize=7)
    fig.suptitle(describe_config(result), fontsize=9)
    fig.tight_layout()
    _save_figure(fig, Path(path))
    plt.close(fig)


def compare_png(results: list[dict[str, Any]], path: str | Path) -> None:
    """PNG: grouped bars of the rates (success, collision, timeout, group intrusion) per policy, with the 95%
    Wilson intervals."""
    if not results:
        raise ValueError("nothing to compare")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(RATE_KEYS) * max(1, len(results)) / 2), 4.2))
    _rates_panel(ax, results)
    ax.legend(fontsize=8)
    ax.set_title(describe_config(results[0]), fontsize=9)
    fig.tight_layout()
    _save_figure(fig, Path(path))
    plt.close(fig)


def compare_json(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The combined JSON of several policies: one entry per policy, keyed by name."""
    return {"policies": [r["policy"] for r in results], "results": {r["policy"]: r for r in results}}
