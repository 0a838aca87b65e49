"""Scenario registry: geometry (wall segments), where groups come from and where they go.

A scenario is data plus three small methods. Every scenario is a TOML file (`crowdsim.scenario_files` describes the
format): the built-in ones ship in `crowdsim/builtin_scenarios/<name>.toml`, and any other file is named by its
path. `make_scenario(name_or_path, options)` builds one and raises an error listing the valid names for an unknown
one.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from crowdsim.names import did_you_mean, unknown_name
from crowdsim.scenario_files import ScenarioFile, ScenarioFileError, read_scenario_file

Rect = tuple[float, float, float, float]  # xmin, ymin, xmax, ymax in metres


@dataclass(frozen=True)
class Flow:
    """Groups appear in `spawn` and head to a point drawn in `target` (both rectangles, m)."""

    spawn: Rect
    target: Rect


@dataclass(frozen=True)
class Scenario:
    """Static description of one scene.

    walls: (S, 2, 2) segments in metres. flows: origin/destination rectangles. on_arrival: "remove"
    (leave the scene), "stop" (stand at the goal) or "new_goal" (draw a new destination). continuous:
    keep the crowd size by spawning new groups as others leave. periodic_x: (x0, x1) wraps a pedestrian
    who passes x1 back to x0 (used to hold a corridor at a fixed density). stop_areas and pois: where groups
    that stop (`crowdsim.behaviours`) stand; none means nobody stops in this scene.
    """

    name: str
    walls: np.ndarray
    bounds: Rect
    flows: tuple[Flow, ...]
    on_arrival: str = "remove"
    continuous: bool = True
    periodic_x: tuple[float, float] | None = None
    exit_radius_m: float = 1.0
    dense_spawn: Rect | None = None  # initial crowd placed on a lattice here instead of by flows
    interior: Rect | None = None  # initial groups start anywhere in here (instead of along their flow)
    stop_areas: tuple[Rect, ...] = ()  # where a group may stop and stand (BehaviourConfig stops)
    pois: tuple[tuple[float, float], ...] = ()  # points of interest (x, y) m that people stop at
    options: Mapping[str, float] = field(default_factory=dict)
    robot_start: Rect | None = None  # where the robot starts (envs); None: the env's route for the scenario
    robot_goal: Rect | None = None  # where its goal is drawn (with robot_start)
    robot_both_ways: bool = False  # whether start and goal swap at random (half of the episodes)

    def __post_init__(self) -> None:
        if self.on_arrival not in ("remove", "stop", "new_goal"):
            raise ValueError(f"on_arrival must be remove, stop or new_goal, got {self.on_arrival!r}")
        walls = np.asarray(self.walls, dtype=float).reshape(-1, 2, 2)
        if not np.all(np.isfinite(walls)):
            raise ValueError(f"scenario {self.name}: wall coordinates must be finite")
        object.__setattr__(self, "walls", walls)
        for k, flow in enumerate(self.flows):
            for what, rect in (("spawn", flow.spawn), ("target", flow.target)):
                _check_rect(self.name, f"flow {k} {what}", rect, walls)
        for k, rect in enumerate(self.stop_areas):
            _check_rect(self.name, f"stop area {k}", rect, walls)
        if (self.robot_start is None) != (self.robot_goal is None):
            raise ValueError(f"scenario {self.name}: robot_start and robot_goal go together")
        for what, rect in (("robot start", self.robot_start), ("robot goal", self.robot_goal)):
            if rect is not None:
                _check_rect(self.name, what, rect, walls)

    def draw_flow(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A group's origin (2,) and destination (2,), metres."""
        flow = self.flows[int(rng.integers(len(self.flows)))]
        return _uniform_in(rng, flow.spawn), _uniform_in(rng, flow.target)

    def new_destination(self, rng: np.random.Generator, pos: np.ndarray) -> np.ndarray:
        """A destination (2,) for a group at pos (2,) that needs a new goal: the target of a random flow
        whose target does not contain pos."""
        for _ in range(20):
            flow = self.flows[int(rng.integers(len(self.flows)))]
            if not _contains(flow.target, pos):
                return _uniform_in(rng, flow.target)
        return _uniform_in(rng, self.flows[0].target)


def _uniform_in(rng: np.random.Generator, rect: Rect) -> np.ndarray:
    return np.array([rng.uniform(rect[0], rect[2]), rng.uniform(rect[1], rect[3])])


def _contains(rect: Rect, p: np.ndarray) -> bool:
    return bool(rect[0] <= p[0] <= rect[2] and rect[1] <= p[1] <= rect[3])


def _segment_hits_rect(a: np.ndarray, b: np.ndarray, rect: Rect) -> bool:
    """Whether segment ab passes through the open interior of rect (Liang–Barsky clipping)."""
    x0, y0, x1, y1 = rect
    d = b - a
    t0, t1 = 0.0, 1.0
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if abs(p) < 1e-12:
            if q <= 0:
                return False
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 >= t1:
            return False
    return True


def _check_rect(name: str, what: str, rect: Rect, walls: np.ndarray) -> None:
    if len(rect) != 4 or not all(np.isfinite(rect)) or rect[0] > rect[2] or rect[1] > rect[3]:
        raise ValueError(f"scenario {name}: {what} area {rect} must be (xmin, ymin, xmax, ymax)")
    for a, b in walls:
        if _segment_hits_rect(a, b, rect):
            raise ValueError(f"scenario {name}: {what} area {rect} lies across the wall {a.tolist()}-{b.tolist()}")


BUILTIN_DIR = Path(__file__).resolve().parent / "builtin_scenarios"  # package data: <name>.toml each
BUILTIN_ORDER = ("corridor", "crossing", "bottleneck", "plaza", "circle_crossing", "open")


def is_scenario_file(name: str) -> bool:
    """Whether a scenario name is the path of a scenario file (it ends in .toml) rather than a built-in's name."""
    return str(name).endswith(".toml")


def scenario_label(name: str) -> str:
    """A scenario's name for file names and progress bars: a built-in's name, or a scenario file's stem."""
    return Path(name).stem if is_scenario_file(name) else name


def _builtins() -> dict[str, ScenarioFile]:
    files = {p.stem: read_scenario_file(p) for p in sorted(BUILTIN_DIR.glob("*.toml"))}
    order = [n for n in BUILTIN_ORDER if n in files] + sorted(set(files) - set(BUILTIN_ORDER))
    for name in order:
        if files[name].name != name:
            raise ScenarioFileError(f"{files[name].source}: name: expected {name!r} (the file's stem)")
    return {name: files[name] for name in order}


# The built-in scenarios, read from their files (name -> parsed file).
SCENARIOS: dict[str, ScenarioFile] = _builtins()

# The options each built-in scenario reads (`SimConfig.scenario_options`), with their defaults: the files'
# [options]. Lengths (`_m`) must be > 0; `density` (people/m², dense initial placement) >= 0; a flag (an option
# whose default the file gives as true/false) is 0 or 1.
SCENARIO_OPTIONS: dict[str, dict[str, float]] = {name: dict(f.options) for name, f in SCENARIOS.items()}


@functools.lru_cache(maxsize=64)
def _read_cached(path: str, mtime_ns: int, size: int) -> ScenarioFile:
    return read_scenario_file(path)


def scenario_file(name: str) -> ScenarioFile:
    """The parsed file of a scenario: a built-in's by name, or the file at a path ending in .toml (re-read when it
    changes). ValueError listing the valid names for an unknown name; ScenarioFileError for a bad file."""
    if is_scenario_file(name):
        try:
            stat = Path(name).stat()
        except OSError as exc:
            raise ScenarioFileError(f"{name}: cannot read the scenario file: {(exc.strerror or str(exc)).lower()}") \
                from None
        return _read_cached(str(name), stat.st_mtime_ns, stat.st_size)
    if name not in SCENARIOS:
        raise ValueError(unknown_name("scenario", name, sorted(SCENARIOS)) + "; or the path of a .toml scenario file")
    return SCENARIOS[name]


def builtin_name(name: str) -> str | None:
    """The built-in scenario `name` stands for: itself for a built-in's name; for a scenario file with the bytes of
    a built-in's file (the shipped file run by its path, or a copy), that built-in's name; else None."""
    if not is_scenario_file(name):
        return name if name in SCENARIOS else None
    digest = scenario_file(name).sha256
    return next((n for n, f in SCENARIOS.items() if f.sha256 == digest), None)


def scenario_digest(name: str) -> str | None:
    """The sha256 of a scenario file's bytes (what records of it depend on), None for a built-in name."""
    return scenario_file(name).sha256 if is_scenario_file(name) else None


def check_options(name: str, options: Mapping[str, float]) -> None:
    """Raise ValueError for an unknown scenario, an option it does not read (listing the valid ones) or a value
    out of range (lengths > 0, density >= 0, flags 0 or 1, everything finite). A scenario file is also built under
    the options (ScenarioFileError: a bad value, an area lying across a wall)."""
    file = scenario_file(name)
    valid = file.options
    for key, value in options.items():
        if key not in valid:
            raise ValueError(f"scenario {name!r} has no option {key!r};{did_you_mean(key, valid)} valid options: "
                             f"{', '.join(valid)}")
        value = float(value)
        if not np.isfinite(value):
            raise ValueError(f"scenario option {key} must be finite, got {value!r}")
        if key.endswith("_m") and value <= 0:
            raise ValueError(f"scenario option {key} must be > 0 m, got {value!r}")
        if key == "density" and value < 0:
            raise ValueError(f"scenario option density must be >= 0 people/m^2, got {value!r}")
        if key in file.flags and value not in (0.0, 1.0):
            raise ValueError(f"scenario option {key} is a flag: 0 or 1, got {value!r}")
    if is_scenario_file(name):
        _build(file, dict(options))


def make_scenario(name: str, options: Mapping[str, float] | None = None) -> Scenario:
    """Build a scenario: a built-in by name (`SCENARIOS`) or a scenario file by its path (ending in .toml), under
    `options` (the file's defaults for the others). An unknown name or option raises a ValueError listing the valid
    ones; a bad file, or an area lying across a wall, a ScenarioFileError naming the file."""
    opt = dict(options or {})
    check_options(name, opt)
    return _build(scenario_file(name), opt)


def _build(file: ScenarioFile, options: dict[str, float]) -> Scenario:
    fields = file.fields(options)
    fields["flows"] = tuple(Flow(spawn, target) for spawn, target in fields["flows"])
    try:
        return Scenario(**fields, options=options)
    except ValueError as exc:
        raise ScenarioFileError(f"{file.source}: {exc}") from None
