"""Dependency rules between the packages, checked on the source's import statements."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CORE = ("crowdsim", "predictor", "planner")
RL_MODULES = {"envs/rl/extractor.py", "envs/rl/imitation.py", "envs/rl/monitor.py", "envs/rl/lagrangian.py",
              "envs/policies/sb3_actor.py"}


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("package", CORE)
def test_core_packages_never_import_each_other(package):
    others = set((*CORE, "envs")) - {package}
    for path in _sources(package):
        assert not (_imports(path) & others), f"{path.relative_to(ROOT)} imports {_imports(path) & others}"


@pytest.mark.parametrize("module, allowed", [
    ("pymunk", {"crowdsim/world.py"}),
    ("rerun", {"crowdsim/recording.py", "envs/drawing/rerun_observer.py"}),
    ("torch", RL_MODULES),  # torch inside predictor/, and in envs only where SB3 needs it (the rl extra)
    ("stable_baselines3", {*RL_MODULES, "envs/policies/sb3_files.py", "envs/rl/train.py"}),
    ("casadi", None),  # casadi only inside planner/
    ("ray", {"crowdsim/distributed.py"}),  # the optional Ray backend (envs reuses it)
    ("imageio_ffmpeg", {"envs/drawing/video.py"}),  # the MP4 encoder (the optional video extra)
    ("imageio", {"envs/drawing/video.py"}),
    ("PIL", {"envs/drawing/video.py"}),  # GIF frames; matplotlib uses Pillow on its own
])
def test_heavy_dependencies_stay_in_their_place(module, allowed):
    home = {"torch": "predictor", "casadi": "planner"}.get(module)
    for package in (*CORE, "envs"):
        for path in _sources(package):
            rel = path.relative_to(ROOT).as_posix()
            if module in _imports(path):
                ok = (allowed is not None and rel in allowed) or (home is not None and rel.startswith(f"{home}/"))
                assert ok, f"{rel} imports {module}"


# envs/ is seven rooms. Each room may import the rooms listed for it (and itself). The core (the env, its config,
# observation, rewards and the policy contract) stands on three rooms below it, which import no other room: crowds
# (the crowd sources behind the `Crowd` protocol), scoring (metrics, collisions, geometry) and drawing (frames,
# images, rerun). The core imports no room above it; the rooms above it may use the three below.
# The two entry points of the package (its __init__, which registers the env and re-exports the policy registry,
# and the `crowdnav` command line) may import every room.
BELOW_CORE = {"crowds", "scoring", "drawing"}
ROOMS = {
    **{room: set() for room in BELOW_CORE},
    "core": BELOW_CORE,
    "policies": {"core", *BELOW_CORE},
    "evaluation": {"core", "policies", *BELOW_CORE},
    "rl": {"core", "policies", "evaluation", *BELOW_CORE},
}
ENTRY_POINTS = {"envs/__init__.py", "envs/cli.py", "envs/cli_options.py"}


def _room(module: str) -> str:
    """The room of a module name inside envs ('envs.policies.registry' -> 'policies', 'envs.env' -> 'core')."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in ROOMS else "core"


def _envs_imports(path: Path) -> set[str]:
    """Every module of envs that `path` imports, at any depth (lazy imports inside functions included)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names if a.name.split(".")[0] == "envs")
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "envs":
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names if _room(f"{node.module}.{a.name}") != "core")
    return names


def test_every_envs_module_lives_in_one_of_the_rooms():
    for path in _sources("envs"):
        rel = path.relative_to(ROOT / "envs").parts
        assert len(rel) == 1 or rel[0] in ROOMS, f"envs/{'/'.join(rel)} is outside the rooms {sorted(ROOMS)}"


def test_the_core_hall_stays_small():
    """Families of modules live in their rooms; at most 15 modules (its __init__ counted) stay directly in envs/."""
    hall = sorted(path.name for path in (ROOT / "envs").glob("*.py"))
    assert "env.py" in hall and len(hall) <= 15, hall


def test_rooms_import_only_the_rooms_below_them():
    for path in _sources("envs"):
        rel = path.relative_to(ROOT).as_posix()
        if rel in ENTRY_POINTS:
            continue
        parts = path.relative_to(ROOT / "envs").parts
        room = parts[0] if len(parts) > 1 else "core"
        for name in _envs_imports(path):
            target = _room(name)
            assert target == room or target in ROOMS[room], f"{rel} ({room}) imports {name} ({target})"


def test_the_room_rule_catches_an_upward_import(tmp_path):
    """The rule above can fail: the core importing the evaluation room is seen, lazily or not."""
    bad = tmp_path / "env.py"
    bad.write_text("def f():\n    from envs.evaluation.pool import run_tasks\n")
    assert {_room(n) for n in _envs_imports(bad)} == {"evaluation"}
    bad.write_text("from envs import rl\n")
    assert {_room(n) for n in _envs_imports(bad)} == {"core", "rl"}
    bad.write_text("from envs.drawing.frame import SceneFrame\n")
    assert {_room(n) for n in _envs_imports(bad)} == {"drawing"}


def test_a_room_below_the_core_may_not_import_it(tmp_path):
    """Even a type-only import of the core from a room below it breaks the rule (it would make a room circle)."""
    bad = tmp_path / "metrics.py"
    bad.write_text("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from envs.view import Pedestrians\n")
    targets = {_room(n) for n in _envs_imports(bad)}
    assert targets == {"core"}
    assert not targets <= ROOMS["scoring"] | {"scoring"}


def _module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph(root: Path, package: str = "envs") -> dict[str, set[str]]:
    """Each module of `package` under `root` -> the modules of `package` it imports, lazy imports inside functions
    and `TYPE_CHECKING` imports included. `from a.b import c` names the module a.b.c where that is a module, else
    a.b (a package's __init__ where a.b is a package)."""
    modules = {_module_name(path, root): path for path in sorted((root / package).rglob("*.py"))}

    def resolve(name: str) -> str:  # the deepest module a dotted name reaches; "" for a name outside `package`
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    graph = {}
    for name, path in modules.items():
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets.update(resolve(alias.name) for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets.update(resolve(f"{node.module}.{alias.name}") for alias in node.names)
        graph[name] = targets - {"", name}
    return graph


def _circle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of `graph` (its modules in import order, the first repeated at the end), or None."""
    state: dict[str, str] = {}  # "open": on the current path; "done": no circle through it
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = "open"
        path.append(node)
        for target in sorted(graph.get(node, ())):
            if state.get(target) == "open":
                return [*path[path.index(target):], target]
            if target not in state and (found := visit(target)):
                return found
        state[node] = "done"
        path.pop()
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_envs_modules_import_one_another_without_a_circle():
    graph = _import_graph(ROOT)
    assert {"envs.config", "envs.view"} <= graph["envs.env"]  # the graph sees real imports
    assert _circle(graph) is None, f"import circle: {' -> '.join(_circle(graph) or ())}"


def test_the_circle_check_finds_a_planted_circle_through_a_lazy_import(tmp_path):
    package = tmp_path / "envs"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from envs.b import B\n")
    (package / "b.py").write_text("B = 1\n")
    (package / "c.py").write_text("from envs import a\n")
    assert _circle(_import_graph(tmp_path)) is None
    (package / "b.py").write_text("B = 1\n\n\ndef f():\n    from envs.c import x\n")
    assert _circle(_import_graph(tmp_path)) == ["envs.a", "envs.b", "envs.c", "envs.a"]
