"""The typed per-episode record, its JSON form, and the append-only JSONL store behind resumable benchmarks.

A record file holds one JSON object per line. `RecordStore.append` writes a line atomically (one O_APPEND
write, fsync), so a killed run leaves complete lines plus at most one partial last line, which `read_records`
skips; a resumed run then redoes only the episodes that have no record. Records of the same episode made on
several machines merge when they agree on the episode's fingerprint (suite, cell and policy settings).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from envs.atomic import append_line

OUTCOMES = ("success", "collision", "timeout", "error")
# Who is at fault for a collision (`envs.scoring.collisions`): "robot", it moved into a pedestrian or wall;
# "pedestrian", who walked into a stopped or retreating robot; "spawn", a replayed track began within contact
# distance of the robot.
AT_FAULT = ("robot", "pedestrian", "spawn")
AVOIDABLE_AT_FAULT = ("robot", "pedestrian")
# Record fields renamed since records were first written: old name -> new name (old files still load).
RENAMED_FIELDS = {"collision_kind": "at_fault"}
# The float-valued social-navigation fields (`envs.scoring.social_metrics`); with group_collision, collision_course and
# itr_states, every field a record written before them lacks (they load as None: "n/a").
SOCIAL_FLOAT_FIELDS = ("time_intimate_s", "intimate_fraction", "time_personal_s", "personal_fraction",
                       "time_social_s", "social_fraction", "path_irregularity_rad", "jerk_mps3", "min_ttc_s", "spl",
                       "itr", "itr_sd_m")


def finite_or_none(value: Any) -> float | None:
    """value as a float, or None when it is missing, NaN or infinite (JSON has no NaN/inf)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class EpisodeRecord:
    """One episode of one policy. Times s, distances m; None where a value does not exist (e.g. time to goal
    of a failed episode, min distance when nobody was ever in the scene).

    outcome: "success" | "collision" | "timeout" | "error" (the policy raised; `error` has the message).
    collision_with: what the robot touched, "pedestrian" | "wall" | None. at_fault: who caused it, one of `AT_FAULT`
    or None (written as `collision_kind` before; such records still load, `RENAMED_FIELDS`).
    collision_time_s: time of the (first, episode-ending) collision. spawn_contacts: contacts of kind "spawn" that
    did not end the episode (`CrowdNavConfig.spawn_contact_ends_episode`). plans/fallbacks: planner calls and
    fallbacks; solve_times_ms: the wall time of every plan that ran the solver (`PlanResult.plan_time_s`, the whole
    `plan()` call; records written before 2026-11-27 hold the solver call, route and shield only, 7-15 ms less).
    group_intrusion / intrusion_fraction: None where the crowd had no group labels
        (`envs.crowds.crowd.Crowd.group_labels`).
    fingerprint: identifies the settings the episode ran under (suite, cell, policy); records merge only when it agrees.

    The social-navigation metrics (`envs.scoring.social_metrics`; None in records written before they existed, in error
    records, and where a metric is undefined): time_<intimate|personal|social>_s / <zone>_fraction, time (s) and
    fraction of the episode's steps with the nearest person in that Hall zone; group_collision, contact with a
    member of a group of >= 2 (None also without group labels); path_irregularity_rad; jerk_mps3 (m/s^3);
    min_ttc_s, the smallest time to collision (s), with collision_course False when the robot was never on one
    (then min_ttc_s is None: JSON has no inf; `min_ttc` gives inf); spl, success weighted by path length;
    itr, CrowdNav++'s intrusion ratio (fraction of the episode's states with the robot closer than the radii sum
    to where a person will be 0.25-1.25 s later, `social_metrics.future_intrusions`), itr_states its intruding
    states and itr_sd_m the social distance during them (mean smallest centre distance, m; None without any).
    """

    policy: str
    seed: int
    outcome: str
    cell: str = ""
    collision_with: str | None = None
    at_fault: str | None = None
    collision_time_s: float | None = None
    steps: int = 0
    time_s: float = 0.0
    time_to_goal_s: float | None = None
    path_length_m: float = 0.0
    min_distance_m: float | None = None
    discomfort_frequency: float = 0.0
    group_intrusion: bool | None = False
    intrusion_fraction: float | None = 0.0
    spawn_contacts: int = 0
    plans: int = 0
    fallbacks: int = 0
    ret: float = 0.0
    wall_time_s: float = 0.0
    time_intimate_s: float | None = None
    intimate_fraction: float | None = None
    time_personal_s: float | None = None
    personal_fraction: float | None = None
    time_social_s: float | None = None
    social_fraction: float | None = None
    group_collision: bool | None = None
    path_irregularity_rad: float | None = None
    jerk_mps3: float | None = None
    min_ttc_s: float | None = None
    collision_course: bool | None = None
    spl: float | None = None
    itr: float | None = None
    itr_states: int | None = None
    itr_sd_m: float | None = None
    error: str | None = None
    fingerprint: str = ""
    solve_times_ms: tuple[float, ...] = field(default=(), repr=False)

    def __post_init__(self) -> None:
        if self.outcome not in OUTCOMES:
            raise ValueError(f"unknown episode outcome {self.outcome!r}; valid: {', '.join(OUTCOMES)}")
        if self.at_fault is not None and self.at_fault not in AT_FAULT:
            raise ValueError(f"unknown at_fault value {self.at_fault!r}; valid: {', '.join(AT_FAULT)}")

    @property
    def key(self) -> tuple[str, str, int]:
        """(cell, policy, seed): one episode of a benchmark."""
        return self.cell, self.policy, self.seed

    @property
    def min_ttc(self) -> float | None:
        """The smallest time to collision, s: inf when never on a collision course, None when not measured."""
        if self.collision_course is None:
            return None
        return self.min_ttc_s if self.collision_course else math.inf

    @property
    def avoidable_collision(self) -> bool:
        return self.outcome == "collision" and self.at_fault in AVOIDABLE_AT_FAULT

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["solve_times_ms"] = [round(t, 3) for t in self.solve_times_ms]
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> EpisodeRecord:
        """A record from its JSON form; fields under an old name (`RENAMED_FIELDS`) are read as the new one."""
        d = dict(d)
        for old, new in RENAMED_FIELDS.items():
            if old in d:
                if new in d and d[new] != d[old]:
                    raise ValueError(f"record has both {old!r} ({d[old]!r}) and {new!r} ({d[new]!r})")
                d[new] = d.pop(old)
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown record field(s) {sorted(unknown)}")
        d["solve_times_ms"] = tuple(float(t) for t in d.get("solve_times_ms", ()))
        return cls(**d)


def read_records(path: str | Path) -> list[EpisodeRecord]:
    """The records of a JSONL file, in file order. A last line without its newline (a write cut short by a
    kill) is skipped; any other malformed line raises ValueError naming `path:line`. A missing file is empty."""
    path = Path(path)
    if not path.exists():
        return []
    text = path.read_text()
    lines = text.split("\n")
    complete = lines[:-1]  # the piece after the last newline is a partial line or ""
    out = []
    for lineno, line in enumerate(complete, start=1):
        if not line.strip():
            continue
        try:
            out.append(EpisodeRecord.from_json(json.loads(line)))
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{path}:{lineno}: malformed episode record: {exc}") from exc
    return out


def merge_records(groups: Iterable[Iterable[EpisodeRecord]]) -> list[EpisodeRecord]:
    """One record per episode key from several sources (first seen wins, except that a result replaces an error:
    an episode that failed and was run again counts by its result). Two records of the same key with different
    fingerprints ran under different settings: ValueError."""
    seen: dict[tuple[str, str, int], EpisodeRecord] = {}
    for records in groups:
        for r in records:
            old = seen.get(r.key)
            if old is None:
                seen[r.key] = r
            elif old.fingerprint != r.fingerprint:
                raise ValueError(f"episode {r.key} was recorded under different settings "
                                 f"(fingerprints {old.fingerprint} and {r.fingerprint}); refusing to merge")
            elif old.outcome == "error" and r.outcome != "error":
                seen[r.key] = r
    return list(seen.values())


class RecordStore:
    """An append-only JSONL file of episode records (see the module docstring); one writing process at a time
    (the benchmark's parent process appends as results come in)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def read(self) -> list[EpisodeRecord]:
        return read_records(self.path)

    def append(self, record: EpisodeRecord) -> None:
        self._drop_partial_tail()
        append_line(self.path, json.dumps(record.to_json(), allow_nan=False, separators=(",", ":")))

    def _drop_partial_tail(self) -> None:
        """Cut a partial last line (from a killed writer) so the next append starts on a fresh line."""
        if not self.path.exists() or self.path.stat().st_size == 0:
            return
        with open(self.path, "rb+") as f:
            f.seek(-1, 2)
            if f.read(1) == b"\n":
                return
            f.seek(0)
            content = f.read()
            f.truncate(content.rfind(b"\n") + 1)
