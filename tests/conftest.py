"""Fixtures shared by every test package."""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"

# The suite builds MPCs of many configurations: solve them on CasADi's virtual machine (the same results) instead of
# compiling each (~30 s; planner/jit.py). tests/planner/test_jit.py compiles; subprocesses inherit the setting.
os.environ.setdefault("CROWDNAV_MPC_JIT", "off")


@pytest.fixture(scope="session")
def load_script() -> Callable[[str], ModuleType]:
    """Import `scripts/<name>.py` (the scripts folder is not a package) and return the module."""
    def load(name: str) -> ModuleType:
        spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
