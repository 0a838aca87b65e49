"""Dependency rules between the packages, checked on the source's import statements."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CORE = ("crowdsim", "predictor", "planner")
RL_MODULES = {"envs/extractor.py", "envs/imitation.py", "envs/train_monitor.py"}


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
    ("rerun", {"crowdsim/recording.py", "envs/rerun_observer.py", "envs/recording.py"}),
    ("torch", RL_MODULES),  # torch inside predictor/, and in envs only where SB3 needs it (the rl extra)
    ("stable_baselines3", {*RL_MODULES, "envs/sb3_io.py", "envs/train.py"}),
    ("casadi", None),  # casadi only inside planner/
    ("ray", {"crowdsim/distributed.py"}),  # the optional Ray backend (envs reuses it)
])
def test_heavy_dependencies_stay_in_their_place(module, allowed):
    home = {"torch": "predictor", "casadi": "planner"}.get(module)
    for package in (*CORE, "envs"):
        for path in _sources(package):
            rel = path.relative_to(ROOT).as_posix()
            if module in _imports(path):
                ok = (allowed is not None and rel in allowed) or (home is not None and rel.startswith(f"{home}/"))
                assert ok, f"{rel} imports {module}"
