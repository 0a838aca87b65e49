"""`evaluate`: one policy over a fixed list of episode seeds in one env config, summarised and reported.

Episodes use seeds seed, seed + 1, ..., seed + episodes - 1 (the env's `reset(seed)` fixes the crowd and the
robot's route, so every policy meets the same episodes) and run through `envs.evaluation.pool` (local process pool by
default, or Ray). Outputs in `out_dir`: `<stem>.json` (the returned summary), `<stem>.md`, `<stem>.png`
(rates and example trajectories), `<stem>_seed<S>.rrd` for the first `record` episodes and
`videos/<stem>-<scenario>-seed<S>.mp4` (or .gif) for the first `video` episodes (none by default). Metric
definitions: docs/envs.md, "Evaluation metrics (envs)", and `envs.evaluation.stats.aggregate`.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from contextlib import closing
from pathlib import Path
from typing import Any

from crowdsim.scenarios import is_scenario_file, scenario_digest, scenario_label
from envs.atomic import check_writable_dir, write_json_atomic, write_text_atomic
from envs.config import REPLAY_SCENARIO, CrowdNavConfig
from envs.drawing.video import DEFAULT_SIZE_PX, check_video_options, video_name
from envs.evaluation.episode import EpisodeTask, VideoSpec, fingerprint
from envs.evaluation.pool import run_tasks
from envs.evaluation.records import EpisodeRecord
from envs.evaluation.report import N_DRAWN, markdown_table, plot_result
from envs.evaluation.stats import aggregate
from envs.policies import PolicyConfig
from envs.policies.identity import policy_identity


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a run (`evaluate`, `envs.evaluation.benchmark.run_benchmark`); `str()` says in one line what
    was done and what of it was kept. Still a KeyboardInterrupt, so code that stops on Ctrl-C keeps doing so."""


# packages whose code runs as callbacks from C, where a raised exception is printed and dropped: CasADi polls for
# signals during a solve; pymunk's cffi callbacks (collision handlers, the finaliser that frees a space) print
# "Exception ignored ... Traceback" (a CI run's Ctrl-C test, 2026-11-29)
CALLBACK_PACKAGES = tuple(f"{os.sep}{name}{os.sep}" for name in ("casadi", "pymunk"))


class CtrlC:
    """While entered (in the main thread, under Python's default Ctrl-C handling): Ctrl-C raises KeyboardInterrupt
    as usual, except inside a `CALLBACK_PACKAGES` callback (a CasADi solve, a pymunk finaliser), where it is only
    remembered and stops the run when the running episode ends (`check`; that episode is kept). An interrupt raised
    there is printed and dropped: in a one-process run about a third of all Ctrl-C presses landed in a solve and were
    lost."""

    def __init__(self) -> None:
        self.pressed = False
        self._previous: Any = None

    def __enter__(self) -> CtrlC:
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum: int, frame: Any) -> None:
        self.pressed = True
        if frame is None or not any(p in frame.f_code.co_filename for p in CALLBACK_PACKAGES):
            raise KeyboardInterrupt

    def check(self) -> None:
        """Raise KeyboardInterrupt if Ctrl-C was pressed (and swallowed) since entering."""
        if self.pressed:
            raise KeyboardInterrupt

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def config_summary(config: CrowdNavConfig) -> dict[str, Any]:
    """The settings a published number needs next to it (crowd size, visibility, kinematics, time limit, dt)."""
    replay = config.scenario == REPLAY_SCENARIO
    from_file = {"scenario_sha256": scenario_digest(config.scenario)} if is_scenario_file(config.scenario) else {}
    obs = config.observation
    limited = {"fov_deg": obs.fov_deg, "occlusion": obs.occlusion} if obs.limited_view else {}
    return {
        "scenario": config.scenario,
        **from_file,  # a scenario file's bytes: a changed file is not resumed into the records of the old one
        **limited,  # a limited view (fov_deg, occlusion) only where set: every other summary stays as it was
        "n_pedestrians": None if replay else config.n_pedestrians,
        "robot_visible": None if replay else config.robot_visible,
        "scenario_options": [list(o) for o in config.scenario_options],
        "robot_model": config.robot.model,
        "robot_radius_m": config.robot.radius_m,
        "robot_max_speed_mps": config.robot.max_speed_mps,
        "time_limit_s": config.time_limit_s,
        "dt_s": config.dt_s,
        "goal_tolerance_m": config.goal_tolerance_m,
        "discomfort_distance_m": config.discomfort_distance_m,
        "group_space_m": config.group_space_m,
        "replay_file": str(config.replay.path) if replay else None,
        "replay_frame_step_s": config.replay.frame_step_s if replay else None,
        "groups_file": str(config.replay.groups_path) if replay and config.replay.groups_path else None,
    }


def episode_list(records: list[EpisodeRecord]) -> list[dict[str, Any]]:
    """The per-episode part of a results JSON (records without their solver times)."""
    return [{k: v for k, v in r.to_json().items() if k != "solve_times_ms"} for r in records]


def check_setup(policy: PolicyConfig, config: CrowdNavConfig) -> None:
    """Build the env and the policy once, so that a bad config or plug-in fails before any episode runs."""
    from envs.env import CrowdNavEnv
    from envs.policies import make_policy

    make_policy(policy, CrowdNavEnv(config))


def evaluate(policy: str | PolicyConfig, config: CrowdNavConfig, episodes: int = 20, seed: int = 0, workers: int = 1,
             record: int = 0, out_dir: str | Path | None = None, *, stem: str | None = None, draw: int = N_DRAWN,
             progress: bool = True, backend: str = "local", address: str | None = None,
             check: bool = True, video: int = 0, video_format: str = "mp4",
             video_size: int = DEFAULT_SIZE_PX) -> dict[str, Any]:
    """Evaluate a policy (a name, or a `PolicyConfig`) on episodes seed .. seed + episodes - 1.

    Args:
        workers: processes (or Ray CPUs for a local Ray); 1 runs in this process. Records do not depend on it.
        record: the first `record` episodes are written as rerun recordings (needs `out_dir`; about 11 MB per
            plaza episode, so none by default).
        out_dir: where `<stem>.json/.md/.png` and the recordings go (checked before any episode); None: no files.
        stem: file name stem of the outputs (default: the policy name).
        draw: episodes drawn in the PNG's trajectories panels (the first ones).
        progress: show a tqdm bar over episodes (on stderr).
        backend, address: `envs.evaluation.pool.run_tasks`.
        check: build the env and policy once first (`check_setup`); False when the caller already did.
        video: the first `video` episodes are written as videos `videos/<stem>-<scenario>-seed<S>.<video_format>`
            (needs `out_dir`), drawn by `envs.drawing.render.render_rgb` in the process that runs the episode;
            video_format: mp4 (the 'video' extra) or gif; video_size: frame side, px (even).

    Ctrl-C raises `Interrupted` saying how many episodes were done (nothing of this policy is written then, but the
    recordings and videos of finished episodes; never a half-written one).

    Returns the JSON-ready summary (`stats.aggregate` plus policy, predictor (the one it ran, None for a
    policy without one), policy_config, scenario, seed, config,
    episode_list and run: workers, backend, wall time, files written).
    """
    from tqdm.auto import tqdm

    pcfg = policy if isinstance(policy, PolicyConfig) else PolicyConfig(name=policy)
    if episodes < 1 or seed < 0 or workers < 1 or record < 0 or video < 0:
        raise ValueError(f"need episodes >= 1, seed >= 0, workers >= 1, record >= 0, video >= 0; got {episodes}, "
                         f"{seed}, {workers}, {record}, {video}")
    if video > 0:
        if out_dir is None:
            raise ValueError("videos need an output folder (out_dir)")
        check_video_options(video_format, video_size)
    stem = stem or pcfg.name.replace("/", "_").replace(":", "_")
    out = check_writable_dir(out_dir) if out_dir is not None else None
    if check:
        check_setup(pcfg, config)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(seed, seed + episodes))
    where = scenario_label(config.scenario)  # a scenario file: its stem, in video names
    fp = fingerprint(config_summary(config), *policy_identity(pcfg))  # with the weights' digest
    tasks = [EpisodeTask(config, pcfg, s, fingerprint=fp, keep_scene=out is not None and i < draw,
                         rrd_path=str(out / f"{stem}_seed{s}.rrd") if out is not None and i < record else None,
                         error_dir=str(out / "errors") if out is not None else None,
                         video=VideoSpec(str(out / "videos" / video_name(stem, where, s, video_format)),
                                         video_format, video_size) if out is not None and i < video else None)
             for i, s in enumerate(seeds)]
    start = time.perf_counter()
    runs: dict[int, dict[str, Any]] = {}
    try:
        with CtrlC() as ctrl_c, tqdm(total=len(tasks), desc=stem, unit="ep", disable=not progress) as bar, \
                closing(run_tasks(tasks, workers, backend, address)) as results:
            for i, res in results:
                runs[i] = res
                bar.update(1)
                ctrl_c.check()
    except KeyboardInterrupt:
        raise Interrupted(f"{len(runs)} of {len(tasks)} episodes of {stem} done, not saved") from None
    wall = time.perf_counter() - start
    records = [runs[i]["record"] for i in range(len(tasks))]
    result: dict[str, Any] = {"policy": records[0].policy, "predictor": pcfg.predictor_used(),
                              "policy_config": pcfg.to_json(),
                              "scenario": config.scenario, "seed": seed, **aggregate(records),
                              "config": config_summary(config), "episode_list": episode_list(records)}
    files = []
    if out is not None:
        files = [f"{stem}.json", f"{stem}.md", f"{stem}.png"] + [Path(t.rrd_path).name for t in tasks if t.rrd_path]
        files += [f"videos/{Path(t.video.path).name}" for t in tasks if t.video is not None]
    result["run"] = {"workers": workers, "backend": backend, "wall_time_s": wall,
                     "episode_wall_time_s": sum(r.wall_time_s for r in records) / len(records), "files": files}
    if out is not None:
        write_text_atomic(out / f"{stem}.md", markdown_table(result) + "\n")
        plot_result(result, [runs[i]["scene"] for i in range(len(tasks)) if "scene" in runs[i]], out / f"{stem}.png")
        write_json_atomic(out / f"{stem}.json", result)
    return result
