"""`run_bounds`: the any-robot bound (`envs.evaluation.reachability`) of every episode of a suite's cells whose crowd
ignores the robot (the real cells and the invisible-robot cells), resumable, and its summary.

One JSON line per episode in `<out>/bounds.jsonl`: {"cell", "seed", "verdict", "earliest_arrival_s",
"witness_arrival_s", "robot_witness", "fingerprint", "reach" (the grid, `ReachConfig`), "wall_time_s"}.
robot_witness (feasible episodes only, else null): "success" when the benchmark's own robot, tracking a roomier
witness path in the env (`envs.evaluation.witness`, ROBOT_ATTEMPTS), wins the episode, "failed" otherwise;
"robot_attempt": which of ROBOT_ATTEMPTS won (1-based; null: none). "sensing_witness" / "sensing_attempt" (every
episode not proven infeasible, else null): the same for the witness that knows only the people it has sensed
(`envs.evaluation.sensing`), a floor for a robot that senses and predicts perfectly.

A rerun with the same `--out` skips the episodes already there (a killed run resumes); a line made under other
settings (suite version, cell, grid) raises. The benchmark's leaderboard reads this file when it lies in the same
folder: a failure on an "infeasible" episode is one no robot could have avoided. Cells where people see the robot
have no fixed course: they are listed as skipped.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from envs.atomic import append_line, check_writable_dir, write_text_atomic
from envs.config import CrowdNavConfig
from envs.evaluation.episode import fingerprint
from envs.evaluation.reachability import VERDICTS, Course, ReachConfig, course_of, crowd_is_fixed, reach, roomy_path
from envs.evaluation.sensing import sensing_path
from envs.evaluation.suite import DEFAULT_DATA, Cell, Suite
from envs.evaluation.witness import track

BOUNDS = "bounds.jsonl"
METHOD_VERSION = 3  # bump when the bound's computation changes (old lines then no longer match)
# (speed fraction, extra clearance m) of the roomy witness paths the benchmark's robot tracks, tried in order
ROBOT_ATTEMPTS = ((0.85, 0.1), (0.7, 0.2), (1.0, 0.1))
_FIELDS = {"cell": str, "seed": int, "verdict": str, "fingerprint": str, "reach": dict}


@dataclass(frozen=True)
class BoundTask:
    """One episode's bound: its env config and seed, the cell's name, the settings' fingerprint and grid."""

    config: CrowdNavConfig
    seed: int
    cell: str
    fingerprint: str
    reach: ReachConfig


def run_bound_task(task: BoundTask) -> dict[str, Any]:
    """The bound line of one episode (module docstring)."""
    start = time.perf_counter()
    course = course_of(task.config, task.seed)
    r = reach(course, task.reach)
    robot = sensing = (None, None)
    if r.verdict == "feasible":  # can the benchmark's own robot win it too? (envs.evaluation.witness)
        robot = _attempts(task, lambda fraction, extra: roomy_path(course, task.reach, fraction, extra))
    if r.verdict != "infeasible":  # and knowing only whom it has sensed? (envs.evaluation.sensing)
        sensing = _attempts(task, lambda fraction, extra: _sensing(course, task, fraction, extra))
    return {"cell": task.cell, "seed": task.seed, "verdict": r.verdict, "earliest_arrival_s": r.earliest_arrival_s,
            "witness_arrival_s": r.witness_arrival_s, "robot_witness": robot[0], "robot_attempt": robot[1],
            "sensing_witness": sensing[0], "sensing_attempt": sensing[1], "fingerprint": task.fingerprint,
            "reach": asdict(task.reach), "wall_time_s": round(time.perf_counter() - start, 3)}


def _attempts(task: BoundTask, path_of: Callable[[float, float], np.ndarray | None]) -> tuple[str, int | None]:
    """("success", the 1-based attempt) for the first of ROBOT_ATTEMPTS whose path the benchmark's robot wins by
    tracking it in the env, else ("failed", None)."""
    for i, (fraction, extra) in enumerate(ROBOT_ATTEMPTS, start=1):
        path = path_of(fraction, extra)
        if path is not None and track(task.config, task.seed, path) == "success":
            return "success", i
    return "failed", None


def _sensing(course: Course, task: BoundTask, fraction: float, extra: float) -> np.ndarray:
    """The sensing witness's path for one of ROBOT_ATTEMPTS (its plan count dropped)."""
    return sensing_path(course, task.reach, task.config.observation.sensor_range_m, fraction, extra)[0]


def bound_fingerprint(suite: Suite, cell: Cell, config: ReachConfig) -> str:
    return fingerprint(suite.name, suite.version, cell.fingerprint_spec, cell.defaults, "reach", METHOD_VERSION,
                       asdict(config))


def read_bounds(path: str | Path) -> dict[tuple[str, int], dict[str, Any]]:
    """The lines of a bounds file by (cell, seed). A last line without its newline (a write cut short) is skipped;
    any other malformed line raises ValueError naming `path:line`. A missing file is empty."""
    path = Path(path)
    if not path.exists():
        return {}
    out = {}
    for lineno, line in enumerate(path.read_text().split("\n")[:-1], start=1):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
            if not isinstance(d, dict) or any(not isinstance(d.get(k), t) for k, t in _FIELDS.items()) \
                    or d["verdict"] not in VERDICTS:
                raise ValueError(f"needs {sorted(_FIELDS)} with verdict one of {', '.join(VERDICTS)}")
        except ValueError as exc:
            raise ValueError(f"{path}:{lineno}: malformed bound line: {exc}") from exc
        out[(d["cell"], d["seed"])] = d
    return out


def current_bounds(suite: Suite, cells: Sequence[Cell], lines: dict[tuple[str, int], dict[str, Any]],
                   where: str | Path) -> dict[tuple[str, int], dict[str, Any]]:
    """The lines of the selected cells' episodes, each checked against the suite as it is now (its fingerprint
    under the grid it records); one made for another suite version or cell raises ValueError naming `where`."""
    out = {}
    for cell in cells:
        for seed in cell.seeds:
            line = lines.get((cell.name, seed))
            if line is None:
                continue
            try:
                fp = bound_fingerprint(suite, cell, ReachConfig(**line["reach"]))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: {cell.name}/seed {seed}: bad grid {line['reach']}: {exc}") from None
            if fp != line["fingerprint"]:
                raise ValueError(f"{where} holds {cell.name}/seed {seed} made for another version of suite "
                                 f"{suite.name} or of the cell; remove it or recompute it in a new folder")
            out[(cell.name, seed)] = line
    return out


def plan_bounds(suite: Suite, cells: Sequence[Cell], done: dict[tuple[str, int], dict[str, Any]],
                config: ReachConfig, data: Path = DEFAULT_DATA) -> tuple[list[BoundTask], list[str]]:
    """The tasks not yet in `done`, and the cells skipped (their crowd sees the robot). A line of `done` made under
    other settings raises ValueError."""
    todo, skipped = [], []
    for cell in cells:
        if not crowd_is_fixed(cell.env_config(cell.seeds[0], data)):
            skipped.append(cell.name)
            continue
        grid = config.resolved(cell.env_config(cell.seeds[0], data).dt_s)
        fp = bound_fingerprint(suite, cell, grid)
        for seed in cell.seeds:
            old = done.get((cell.name, seed))
            if old is None:
                todo.append(BoundTask(cell.env_config(seed, data), seed, cell.name, fp, grid))
            elif old["fingerprint"] != fp:
                raise ValueError(f"the bounds file holds {cell.name}/seed {seed} made under other settings (another "
                                 "suite version or grid); use a new --out folder")
    return todo, skipped


def run_bounds(suite: Suite, cells: Sequence[Cell], out: str | Path, *, config: ReachConfig | None = None,
               data: Path = DEFAULT_DATA, workers: int = 1, progress: bool = True) -> dict[str, Any]:
    """Compute what is missing, then write `<out>/bounds.md`. Returns the summary (`bounds_summary`) with
    `skipped` (cells whose crowd sees the robot) and `run` (episodes computed / resumed, wall time, and `died`: the
    episodes whose worker process died twice, left out of the file so that a rerun computes them)."""
    from tqdm.auto import tqdm

    from crowdsim.distributed import WorkerDied, process_context, run_in_processes

    cfg = config or ReachConfig()
    out = check_writable_dir(out)
    suite.check_data(list(cells), data)
    path = out / BOUNDS
    todo, skipped = plan_bounds(suite, cells, read_bounds(path), cfg, data)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    if workers <= 1 or len(todo) <= 1:
        results = ((i, run_bound_task(t)) for i, t in enumerate(todo))
    else:
        results = run_in_processes(run_bound_task, todo, min(workers, len(todo)),
                                   process_context(["envs.evaluation.bounds"]))
    died = []
    with tqdm(total=len(todo), desc=f"{suite.name} bounds", unit="ep", disable=not progress) as bar, \
            closing(results) as res:
        for i, line in res:
            if isinstance(line, WorkerDied):  # not written: a rerun of the same command computes it again
                died.append(f"{todo[i].cell}/seed {todo[i].seed}: {line}")
            else:
                append_line(path, json.dumps(line, allow_nan=False, separators=(",", ":")))
            bar.update(1)
    wanted = {(c.name, s) for c in cells if c.name not in skipped for s in c.seeds}
    lines = {k: v for k, v in read_bounds(path).items() if k in wanted}
    summary = bounds_summary(suite, cells, lines)
    summary["skipped"] = skipped
    summary["run"] = {"episodes_run": len(todo) - len(died), "episodes_resumed": len(wanted) - len(todo),
                      "wall_time_s": time.perf_counter() - start, "died": died}
    write_text_atomic(out / "bounds.md", "\n".join(bounds_table(summary)) + "\n")
    return summary


def bounds_summary(suite: Suite, cells: Sequence[Cell], lines: dict[tuple[str, int], dict[str, Any]]) -> dict[str, Any]:
    """Per cell and pool (real, synthetic): episodes, verdict counts, the success ceiling (share of episodes not
    proven infeasible: no policy can do better), the floor of what a holonomic robot could do (share proven
    feasible), of what the benchmark's robot could do knowing the future (share it won tracking a witness) and knowing
    only the people it has sensed (`envs.evaluation.sensing`), and the mean earliest arrival over the
    feasible-or-open episodes."""
    def count(rows: list[dict[str, Any]]) -> dict[str, Any]:
        n = len(rows)
        c = {v: sum(r["verdict"] == v for r in rows) for v in VERDICTS}
        arrivals = [r["earliest_arrival_s"] for r in rows if r["earliest_arrival_s"] is not None]
        won = sum(r.get("robot_witness") == "success" for r in rows)
        sensed = sum(r.get("sensing_witness") == "success" for r in rows)
        return {"episodes": n, **c, "robot_wins": won, "sensing_wins": sensed,
                "success_ceiling": (n - c["infeasible"]) / n if n else None,
                "holonomic_floor": c["feasible"] / n if n else None, "robot_floor": won / n if n else None,
                "sensing_floor": sensed / n if n else None,
                "mean_earliest_arrival_s": sum(arrivals) / len(arrivals) if arrivals else None}

    per_cell = {c.name: count([lines[(c.name, s)] for s in c.seeds if (c.name, s) in lines]) for c in cells}
    pools = {}
    for pool, real in (("real", True), ("synthetic", False)):
        rows = [v for (name, _), v in lines.items() if any(c.name == name and c.is_real == real for c in cells)]
        if rows:
            pools[pool] = count(rows)
    return {"suite": suite.name, "version": suite.version, "cells": {k: v for k, v in per_cell.items()
                                                                     if v["episodes"]}, "pooled": pools}


def bounds_table(summary: dict[str, Any]) -> list[str]:
    """Markdown: the any-robot bound per cell and pool."""
    lines = [f"### What any robot could do: suite {summary['suite']} v{summary['version']}", "",
             "Episodes whose crowd ignores the robot (real cells, invisible robot), by reachable sets over the "
             "scene (envs.evaluation.reachability): infeasible = no robot at the robot's top speed could reach the "
             "goal in time without contact; feasible = a holonomic robot at that speed has a contact-free path; open "
             "= neither bound decides; robot wins = feasible episodes the benchmark's own robot won, knowing the "
             "future, by tracking a witness path in the env; sensing robot wins = episodes it won knowing the future "
             "only of the people it has sensed (within its sensor range so far; envs.evaluation.sensing). Success "
             "ceiling = share not infeasible (no policy can do better); robot floor = share the robot won (a policy "
             "with foresight can do at least that); sensing floor = share the sensing robot won (a policy that "
             "predicts the people it senses perfectly can do at least that).", "",
             "| cell or pool | episodes | infeasible | open | feasible | robot wins | sensing robot wins | success "
             "ceiling | robot floor | sensing floor | earliest arrival (s, mean) |", "|---|---|---|---|---|---|---|---|"
             "---|---|---|"]
    rows = [*summary["cells"].items(), *((f"**pooled {k}**", v) for k, v in summary["pooled"].items())]
    for where, c in rows:
        arr = "–" if c["mean_earliest_arrival_s"] is None else f"{c['mean_earliest_arrival_s']:.1f}"
        lines.append(f"| {where} | {c['episodes']} | {c['infeasible']} | {c['open']} | {c['feasible']} | "
                     f"{c['robot_wins']} | {c['sensing_wins']} | {c['success_ceiling']:.2f} | {c['robot_floor']:.2f} | "
                     f"{c['sensing_floor']:.2f} | {arr} |")
    if summary.get("skipped"):
        lines += ["", f"Not bounded (people there see the robot, so its course depends on the robot): "
                      f"{', '.join(summary['skipped'])}."]
    return lines
