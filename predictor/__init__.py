"""GP-Graph pedestrian trajectory prediction (Bae et al., ECCV 2022) with SGCN and Social-STGCNN backbones."""

from predictor.api import (
    ConstantVelocityConfig,
    ConstantVelocityPredictor,
    GPGraphPredictor,
    Prediction,
    load_predictor,
    set_threads,
)
from predictor.model import GPGraph, GPGraphConfig

__all__ = [
    "ConstantVelocityConfig",
    "ConstantVelocityPredictor",
    "GPGraph",
    "GPGraphConfig",
    "GPGraphPredictor",
    "Prediction",
    "load_predictor",
    "set_threads",
]
