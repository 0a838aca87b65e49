"""`run_benchmark`: every policy on every episode of a suite's cells, resumable, then the leaderboard.

Records go to `<out>/records.jsonl` as episodes finish (`envs.evaluation.records.RecordStore`); a rerun with the same
`--out` skips the episodes already recorded (a killed run resumes), and `merge` adds record files made
elsewhere (another machine, a Ray cluster). The leaderboard and the paired comparisons are rebuilt from all
records at the end (`envs.evaluation.leaderboard`), with the any-robot bounds of `<out>/bounds.jsonl` when `crowdnav
bounds` has written them there.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from contextlib import closing
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from envs.atomic import check_writable_dir
from envs.config import CrowdNavConfig
from envs.evaluation.bounds import BOUNDS, current_bounds, read_bounds
from envs.evaluation.episode import EpisodeTask, fingerprint
from envs.evaluation.evaluate import CtrlC, Interrupted, check_setup
from envs.evaluation.pool import run_tasks
from envs.evaluation.records import EpisodeRecord, RecordStore, merge_records, read_records
from envs.evaluation.suite import DEFAULT_DATA, Cell, Suite
from envs.policies import PolicyConfig
from envs.policies.identity import agent_observation, policy_identity

RECORDS = "records.jsonl"


@dataclass(frozen=True)
class BenchmarkPlan:
    """What a run will do: all tasks of the selection, and those not yet recorded."""

    tasks: tuple[EpisodeTask, ...]
    todo: tuple[EpisodeTask, ...]
    done: tuple[EpisodeRecord, ...]


def episode_fingerprint(suite: Suite, cell: Cell, policy: PolicyConfig, identity: list[Any] | None = None) -> str:
    """What an episode's record depends on: the suite version, the cell's definition, the policy config and the
    digest of the weight files it loads (`envs.policies.identity.policy_identity`, or `identity` when already known)."""
    return fingerprint(suite.name, suite.version, cell.fingerprint_spec, cell.defaults,
                       *(policy_identity(policy) if identity is None else identity))


def observed(config: CrowdNavConfig, fields: dict[str, Any]) -> CrowdNavConfig:
    """`config` observing what an agent was trained to observe (`envs.policies.identity.agent_observation`: wall
    rays, predictions and their calibration). Observing changes nothing in the world (the env's predictor draws from
    its own generator), so the other policies' episodes are the same; unchanged for {}."""
    if not fields or all(getattr(config.observation, k) == v for k, v in fields.items()):
        return config
    return replace(config, observation=replace(config.observation, **fields))


def plan_benchmark(suite: Suite, cells: Sequence[Cell], policies: Sequence[PolicyConfig], out: Path,
                   data: Path = DEFAULT_DATA, recorded: Sequence[EpisodeRecord] = ()) -> BenchmarkPlan:
    """The tasks of cells x policies x seeds and which of them are already `recorded` (records of the output
    folder and merged files; an episode recorded as an error is run again). A record of the same episode made under
    other settings raises ValueError."""
    names = [p.name for p in policies]
    if len(set(names)) != len(names):
        raise ValueError(f"a policy is named twice: {names}")
    existing = {r.key: r for r in recorded}
    identities: dict[PolicyConfig, list[Any]] = {}  # each policy's weight files are read once, not once per cell
    tasks, todo, done = [], [], []
    for cell in cells:
        for pcfg in (p.for_cell(cell.scene, cell.predictor) for p in policies):
            if pcfg not in identities:
                identities[pcfg] = policy_identity(pcfg)
            fp = episode_fingerprint(suite, cell, pcfg, identities[pcfg])
            seen = agent_observation(pcfg)
            for seed in cell.seeds:
                task = EpisodeTask(observed(cell.env_config(seed, data), seen), pcfg, seed, cell=cell.name,
                                   fingerprint=fp, error_dir=str(Path(out) / "errors"))
                tasks.append(task)
                old = existing.get((cell.name, pcfg.name, seed))
                if old is None:
                    todo.append(task)
                elif old.fingerprint != fp:
                    raise ValueError(f"the records hold {cell.name}/{pcfg.name}/seed {seed} run under other "
                                     "settings (another suite version or policy config); use a new --out folder")
                elif old.outcome == "error":  # a failed episode (a policy's exception, a worker that died) is retried
                    todo.append(task)
                else:
                    done.append(old)
    return BenchmarkPlan(tuple(tasks), tuple(todo), tuple(done))


def run_benchmark(suite: Suite, cells: Sequence[Cell], policies: Sequence[PolicyConfig], out: str | Path, *,
                  data: Path = DEFAULT_DATA, workers: int = 1, backend: str = "local", address: str | None = None,
                  merge: Sequence[Path] = (), progress: bool = True) -> dict[str, Any]:
    """Run what is missing, then write the leaderboard from every record of the selection. Returns the
    leaderboard JSON (see `envs.evaluation.leaderboard.leaderboard`) with `run` (episodes run / resumed, wall time).
    Ctrl-C while episodes run raises `envs.evaluation.evaluate.Interrupted` saying how many are saved (every
    finished one is: a rerun resumes from there)."""
    from tqdm.auto import tqdm

    from envs.evaluation.leaderboard import leaderboard, write_leaderboard

    out = check_writable_dir(out)
    suite.check_data(list(cells), data)
    store = RecordStore(out / RECORDS)
    recorded = merge_records([store.read(), *(read_records(p) for p in merge)])  # bad files fail here
    bounds = current_bounds(suite, cells, read_bounds(out / BOUNDS), out / BOUNDS)  # `crowdnav bounds`, if run
    plan = plan_benchmark(suite, cells, policies, out, data, recorded)
    for pcfg, task in {t.policy: t for t in plan.todo}.items():  # a bad plug-in fails here, not per episode
        check_setup(pcfg, task.env)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    wanted = {(t.cell, t.policy.name, t.seed) for t in plan.tasks}
    try:
        with CtrlC() as ctrl_c, \
                tqdm(total=len(plan.tasks), initial=len(plan.done), desc=suite.name, unit="ep",
                     disable=not progress) as bar, \
                closing(run_tasks(plan.todo, workers, backend, address)) as results:
            for _, res in results:
                store.append(res["record"])
                bar.update(1)
                ctrl_c.check()
    except KeyboardInterrupt:
        saved = len(wanted & {r.key for r in merge_records([recorded, store.read()])})  # wherever it landed
        raise Interrupted(f"{saved} of {len(plan.tasks)} episodes saved in {store.path}; "
                          "rerun the same command to resume") from None
    wall = time.perf_counter() - start
    records = [r for r in merge_records([recorded, store.read()]) if r.key in wanted]
    board = leaderboard(suite, list(cells), list(policies), records, bounds)
    board["run"] = {"episodes_run": len(plan.todo), "episodes_resumed": len(plan.done), "workers": workers,
                    "backend": backend, "wall_time_s": wall, "merged_files": [str(p) for p in merge],
                    "errors": sum(r.outcome == "error" for r in records)}
    write_leaderboard(board, out)
    return board
