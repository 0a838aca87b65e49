"""Backbone registry: a new backbone is one module implementing ``predictor.backbones.base.Backbone``."""

from __future__ import annotations

from predictor.backbones.base import Backbone
from predictor.backbones.sgcn import SGCN
from predictor.backbones.stgcnn import STGCNN
from predictor.names import unknown_name

BACKBONES: dict[str, type[Backbone]] = {"sgcn": SGCN, "stgcnn": STGCNN}


def check_backbone(name: str) -> None:
    """Raise ValueError listing the valid names when ``name`` is not registered."""
    if name not in BACKBONES:
        raise ValueError(unknown_name("backbone", name, sorted(BACKBONES), label="valid backbones"))


def make_backbone(name: str) -> Backbone:
    """A fresh backbone by registry name."""
    check_backbone(name)
    return BACKBONES[name]()


__all__ = ["BACKBONES", "Backbone", "check_backbone", "make_backbone"]
