"""Named, versioned benchmark suites: cells (an env config each) with fixed seed lists, read from package data.

A suite file `envs/evaluation/suites/<name>.json` holds {"name", "version", "description", "defaults", "cells": [...]}.
A cell is either simulated ({"name", "scenario", "n_pedestrians", "robot_visible", "options"?, "episodes",
"seed0"}; "scenario" is a built-in name or a .toml scenario file, a relative path starting in the suites' folder)
or a real-crowd replay ({"name", "replay": [files relative to the data folder], "frame_step_s",
"episodes", "seed0", "groups"?, "group_overlaps"?}). `groups` maps a replayed file to its group file (both
relative to the data folder, e.g. "../eth_ucy_groups/students003.groups.txt"); `group_overlaps` says what a
pedestrian listed in two groups does ("merge", or the default "error"; `envs.crowds.replay.ReplayConfig`). A recording
without a group file has no group labels: its group intrusion is "n/a". Any cell may name its `scene` (default:
"synthetic" for simulated cells) and the `predictor` that `mpc-gpgraph` uses there when none is given (real cells:
the scene's leave-one-out ETH/UCY checkpoint, trained without that scene). Episode i of a cell has seed seed0 + i;
a replay cell with several files replays file (seed mod number of files) from a start time drawn from the seed.
`defaults` are `CrowdNavConfig` fields (time limit, ...) applied to every cell. Every policy meets exactly the same
episodes. A simulated cell may also name its `crowd_model` ("social-force", the default, or "orca":
`envs.crowds.models`), the ORCA humans' settings `orca` (`envs.crowds.orca.OrcaCrowdConfig` fields) and the robot's
`robot` (`planner.RobotConfig` fields; default the env's unicycle) and `observation` (`envs.config.ObservationConfig`
fields, e.g. CrowdNav++'s 5 m sensor), its crowd's `crowd_groups` (`crowdsim.GroupConfig` fields: group sizes; default
max_size min(5, n_pedestrians)) and `behaviour` (`crowdsim.config.BehaviourConfig` fields: stops in F-formations,
meeting and parting; default none); unknown names or fields raise naming the valid ones.
A suite may set `planner` defaults for the planner policies run in it: {"replan_every_steps": k, "mpc": {MPCConfig
field: value}} (e.g. CrowdNav's 0.25 s decision period, and settings chosen on the suite's tuning twin); the command
line's --replan-every and --mpc still override them, and every record holds the config it ran.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from crowdsim import GroupConfig
from crowdsim.config import BehaviourConfig
from crowdsim.names import did_you_mean, unknown_name
from crowdsim.scenarios import is_scenario_file, scenario_digest
from envs.config import REPLAY_SCENARIO, CrowdNavConfig, ObservationConfig
from envs.crowds.orca import OrcaCrowdConfig
from planner import CROWD_MPC, MPCConfig, RobotConfig
from predictor.ethucy import DEFAULT_DATA_DIR

DEFAULT_DATA = DEFAULT_DATA_DIR  # predictor.ethucy owns the ETH/UCY data path (ETH_UCY_DIR overrides it)
_CELL_KEYS = {"name", "scenario", "n_pedestrians", "robot_visible", "options", "replay", "frame_step_s",
              "episodes", "seed0", "note", "scene", "predictor", "groups", "group_overlaps", "crowd_model", "orca",
              "robot", "observation", "crowd_groups", "behaviour"}
SUITES_DIR = Path(__file__).resolve().parent / "suites"  # the shipped suites; a cell's relative .toml path starts here
_SIM_ONLY_KEYS = {"crowd_model", "orca", "robot", "observation", "crowd_groups", "behaviour"}  # simulated cells only
# cell key -> the frozen config its fields build (and the env config field it sets)
_NESTED = {"orca": OrcaCrowdConfig, "robot": RobotConfig, "observation": ObservationConfig,
           "crowd_groups": GroupConfig, "behaviour": BehaviourConfig}
_FIELD = {"crowd_groups": "groups"}  # a cell key whose env config field has another name
SIMULATED_SCENE = "synthetic"
_DEFAULT_KEYS = {"time_limit_s", "dt_s", "warmup_s", "goal_tolerance_m", "spawn_contact_ends_episode"}
_PLANNER_KEYS = {"replan_every_steps", "mpc"}
# MPCConfig fields a suite may set (scalars; the robot comes from the cell, the weights and route stay the env's)
_SUITE_MPC_FIELDS = {f.name for f in fields(MPCConfig)} - {"robot", "weights", "route"}


def suite_names() -> list[str]:
    """The suites shipped in `envs/evaluation/suites/`."""
    return sorted(p.name[:-5] for p in resources.files("envs.evaluation.suites").iterdir() if p.name.endswith(".json"))


@dataclass(frozen=True)
class Cell:
    """One benchmark cell: how to build its env for a seed, and its seeds."""

    name: str
    spec: dict[str, Any]
    defaults: dict[str, Any]
    seeds: tuple[int, ...]

    @property
    def is_real(self) -> bool:
        return "replay" in self.spec

    @property
    def scene(self) -> str:
        """The scene name a `{scene}` predictor template takes here (simulated cells: "synthetic")."""
        return str(self.spec.get("scene", SIMULATED_SCENE))

    @property
    def predictor(self) -> str | None:
        """The predictor `mpc-gpgraph` uses in this cell unless one is given (None: the shipped default)."""
        return self.spec.get("predictor")

    @property
    def scenario(self) -> str:
        """A simulated cell's scenario: a built-in name, or a scenario file's path (one relative to the suites'
        folder, `envs/evaluation/suites/`, resolved there)."""
        name = str(self.spec["scenario"])
        return str(SUITES_DIR / name) if is_scenario_file(name) and not Path(name).is_absolute() else name

    @property
    def fingerprint_spec(self) -> dict[str, Any]:
        """The cell's definition as its records' fingerprints hold it: a scenario file's cell adds the sha256 of
        the file's bytes (an edited file is not resumed into the old records); other cells are their spec."""
        if self.is_real or not is_scenario_file(str(self.spec["scenario"])):
            return self.spec
        return {**self.spec, "scenario_sha256": scenario_digest(self.scenario)}

    def files(self, data: Path) -> list[Path]:
        return [Path(data) / f for f in self.spec["replay"]]

    def group_files(self, data: Path) -> dict[Path, Path]:
        """Replayed file -> its group file, for the recordings that have one."""
        return {Path(data) / f: Path(data) / g for f, g in self.spec.get("groups", {}).items()}

    def env_config(self, seed: int, data: Path = DEFAULT_DATA) -> CrowdNavConfig:
        """The env config of this cell's episode `seed` (for replay: the file it replays)."""
        kw: dict[str, Any] = dict(self.defaults)
        if self.is_real:
            from envs.crowds.replay import ReplayConfig

            files = self.files(data)
            limit = float(kw.get("time_limit_s", CrowdNavConfig.time_limit_s))
            groups = self.group_files(data)
            path = files[seed % len(files)]
            kw["replay"] = ReplayConfig(path=path, frame_step_s=float(self.spec["frame_step_s"]),
                                        min_remaining_s=limit, name=self.name, groups_path=groups.get(path),
                                        group_overlaps=str(self.spec.get("group_overlaps", "error")))
            return CrowdNavConfig(scenario=REPLAY_SCENARIO, **kw)
        n = int(self.spec["n_pedestrians"])
        kw["groups"] = replace(GroupConfig(), max_size=min(GroupConfig().max_size, n))
        for key, cls in _NESTED.items():
            if key in self.spec:
                base = kw["groups"] if key == "crowd_groups" else cls()
                kw[_FIELD.get(key, key)] = replace(base, **self.spec[key])
        if "crowd_model" in self.spec:
            kw["crowd_model"] = str(self.spec["crowd_model"])
        return CrowdNavConfig(scenario=self.scenario, n_pedestrians=n,
                              robot_visible=bool(self.spec["robot_visible"]),
                              scenario_options=tuple(sorted(self.spec.get("options", {}).items())), **kw)


@dataclass(frozen=True)
class Suite:
    name: str
    version: int
    description: str
    cells: tuple[Cell, ...]
    replan_every_steps: int | None = None  # planner policies' default here (None: the registry's)
    mpc: tuple[tuple[str, Any], ...] = ()  # MPCConfig overrides for the planner policies here, (field, value)

    def mpc_config(self, base: MPCConfig) -> MPCConfig:
        """`base` (the env's MPC) with this suite's planner overrides: what its MPC policies run."""
        return replace(base, **dict(self.mpc))

    def cell(self, name: str) -> Cell:
        for c in self.cells:
            if c.name == name:
                return c
        names = [c.name for c in self.cells]
        raise ValueError(f"unknown cell {name!r} in suite {self.name};{did_you_mean(name, names)} valid names: "
                         + ", ".join(names))

    def select(self, names: list[str] | None) -> list[Cell]:
        """The named cells (all when None), in suite order; unknown names raise listing the valid ones."""
        if not names:
            return list(self.cells)
        wanted = [self.cell(n).name for n in names]
        return [c for c in self.cells if c.name in wanted]

    def check_data(self, cells: list[Cell], data: Path) -> None:
        """Raise ValueError when a real cell's recording is missing under `data`."""
        for c in cells:
            if c.is_real:
                for f in c.files(data):
                    if not f.is_file():
                        raise ValueError(f"cell {c.name}: recording {f} not found; point --data at the ETH/UCY "
                                         "folder (with eth/, hotel/, ... inside) or choose --cells")
                for g in c.group_files(data).values():
                    if not g.is_file():
                        raise ValueError(f"cell {c.name}: group file {g} not found (group files are named relative "
                                         "to the --data folder) or choose --cells")


def _check_cell(c: dict[str, Any], where: str) -> None:
    unknown = set(c) - _CELL_KEYS
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {sorted(unknown)}")
    need = {"name", "episodes", "seed0"} | ({"replay", "frame_step_s"} if "replay" in c
                                            else {"scenario", "n_pedestrians", "robot_visible"})
    missing = need - set(c)
    if missing:
        raise ValueError(f"{where}: missing key(s) {sorted(missing)}")
    if int(c["episodes"]) < 1 or int(c["seed0"]) < 0:
        raise ValueError(f"{where}: episodes must be >= 1 and seed0 >= 0")
    stray = set(c.get("groups", {})) - set(c.get("replay", []))
    if stray:
        raise ValueError(f"{where}: groups name file(s) the cell does not replay: {sorted(stray)}")
    if "replay" in c and _SIM_ONLY_KEYS & set(c):
        raise ValueError(f"{where}: a replay cell takes no {sorted(_SIM_ONLY_KEYS & set(c))}")
    for key, cls in _NESTED.items():
        valid = {f.name for f in fields(cls)}
        if key in c and (not isinstance(c[key], dict) or set(c[key]) - valid):
            raise ValueError(f"{where}: {key} must map {cls.__name__} fields to values; unknown: "
                             f"{sorted(set(c[key]) - valid) if isinstance(c[key], dict) else c[key]!r}; "
                             f"valid: {', '.join(sorted(valid))}")
    if c.get("group_overlaps", "error") not in ("error", "merge"):
        raise ValueError(f"{where}: group_overlaps must be error or merge, got {c['group_overlaps']!r}")


def parse_suite(data: dict[str, Any], origin: str = "suite") -> Suite:
    """A `Suite` from its JSON data; ValueError naming the problem."""
    try:
        defaults = dict(data.get("defaults", {}))
        bad = set(defaults) - _DEFAULT_KEYS
        if bad:
            raise ValueError(f"{origin}: unknown default(s) {sorted(bad)}; valid: {sorted(_DEFAULT_KEYS)}")
        cells = []
        for i, c in enumerate(data["cells"]):
            _check_cell(c, f"{origin}: cell {i}")
            seeds = tuple(range(int(c["seed0"]), int(c["seed0"]) + int(c["episodes"])))
            cells.append(Cell(c["name"], dict(c), defaults, seeds))
        names = [c.name for c in cells]
        if len(set(names)) != len(names):
            raise ValueError(f"{origin}: cell names repeat")
        replan, mpc = _planner_defaults(data.get("planner", {}), origin)
        suite = Suite(str(data["name"]), int(data["version"]), str(data.get("description", "")), tuple(cells),
                      replan, mpc)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{origin}: malformed suite ({exc!r})") from exc
    for cell in suite.cells:  # every simulated cell's config must be valid
        if not cell.is_real:
            cell.env_config(cell.seeds[0]).sim_config()
    return suite


def _planner_defaults(spec: Any, origin: str) -> tuple[int | None, tuple[tuple[str, Any], ...]]:
    """(replan_every_steps, mpc overrides) of a suite's "planner" entry; ValueError naming the problem."""
    if not isinstance(spec, dict) or set(spec) - _PLANNER_KEYS:
        raise ValueError(f"{origin}: planner must map {sorted(_PLANNER_KEYS)} to values, got {spec!r}")
    replan = spec.get("replan_every_steps")
    if replan is not None and (not isinstance(replan, int) or isinstance(replan, bool) or replan < 1):
        raise ValueError(f"{origin}: planner.replan_every_steps must be an integer >= 1, got {replan!r}")
    mpc = spec.get("mpc", {})
    if not isinstance(mpc, dict) or set(mpc) - _SUITE_MPC_FIELDS:
        bad = sorted(set(mpc) - _SUITE_MPC_FIELDS) if isinstance(mpc, dict) else mpc
        raise ValueError(f"{origin}: planner.mpc sets unknown or fixed MPCConfig field(s) {bad}; valid: "
                         f"{', '.join(sorted(_SUITE_MPC_FIELDS))}")
    try:
        replace(CROWD_MPC, **mpc)  # the values are checked where they would be used
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{origin}: planner.mpc: {exc}") from exc
    return replan, tuple(sorted(mpc.items()))


REFERENCE_SUITE = "crowdnav-v1"  # its real cells say which scene, and so which predictor, each test recording has


def recording_cell(path: Path | str, suite: str = REFERENCE_SUITE) -> Cell | None:
    """The real cell of the shipped `suite` that replays the recording `path` (matched by file name: the ETH/UCY
    test files' names are unique, e.g. biwi_hotel.txt), None for any other file. Its `scene` and `predictor` are
    what `crowdnav evaluate --scenario replay` gives mpc-gpgraph there (`PolicyConfig.for_cell`), as the suite does."""
    name = Path(path).name
    return next((c for c in load_suite(suite).cells if c.is_real and name in {Path(f).name for f in c.spec["replay"]}),
                None)


def load_suite(name: str) -> Suite:
    """A shipped suite by name (`suite_names()`); unknown names raise listing the valid ones."""
    if name not in suite_names():
        raise ValueError(unknown_name("suite", name, suite_names()))
    text = resources.files("envs.evaluation.suites").joinpath(f"{name}.json").read_text()
    return parse_suite(json.loads(text), f"suite {name}")
