"""GP-Graph pedestrian trajectory prediction (Bae et al., ECCV 2022) with SGCN and Social-STGCNN backbones.

The public names below load torch lazily, on first use, so that torch-free submodules (`predictor.ethucy`, the
ETH/UCY reader that `envs` replays with) can be imported without it.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "ConstantVelocityConfig": "predictor.api",
    "ConstantVelocityPredictor": "predictor.api",
    "GPGraphPredictor": "predictor.api",
    "Prediction": "predictor.api",
    "load_predictor": "predictor.api",
    "set_threads": "predictor.api",
    "GPGraph": "predictor.model",
    "GPGraphConfig": "predictor.model",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'predictor' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
