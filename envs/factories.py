"""`module:factory` names: how a user's policy or predictor is named on the command line and in configs.

The module is imported like `python -m` would: installed packages first, then the current folder (so a plug-in
file beside where the command runs is found without setting PYTHONPATH; the benchmark's worker processes start in
the same folder and find it too).
"""

from __future__ import annotations

import importlib
import os
import re
import sys
from typing import Any

PLUGIN_RE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


def is_plugin(spec: str) -> bool:
    """Whether `spec` names a `module:factory` plug-in."""
    return bool(PLUGIN_RE.match(spec))


def _import(module_name: str) -> Any:
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        here = os.getcwd()
        if exc.name != module_name.split(".")[0] or here in sys.path or "" in sys.path:
            raise
        sys.path.append(here)  # after every installed package: a local file never shadows one
        return importlib.import_module(module_name)


def load_factory(spec: str) -> Any:
    """The callable `factory` of `module:factory`; ValueError when the module or the name is missing."""
    if not is_plugin(spec):
        raise ValueError(f"plug-in {spec!r} must look like module:factory")
    module_name, attr = spec.split(":")
    try:
        module = _import(module_name)
    except ImportError as exc:
        raise ValueError(f"plug-in {spec!r}: cannot import module {module_name!r} ({exc})") from exc
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise ValueError(f"plug-in {spec!r}: module {module_name!r} has no callable {attr!r}")
    return factory
