"""Checkpoint files: this package's own format and the authors' published GP-Graph-SGCN state_dicts.

Our format is a plain dict, loadable with ``torch.load(..., weights_only=True)``:
``{"format": FORMAT, "config": GPGraphConfig.to_dict(), "state_dict": {...}, "meta": {...}}``.
The meta is free-form (training epoch, recipe, data, ...) except for two optional keys read back at loading:
``"group_threshold_scale"``, a calibrated ``GPGraph.group_threshold_scale`` (absent: 1.0, the learned threshold
as is), and ``"group_mode"``, a ``GPGraph.group_mode`` (absent: None, the config's grouping as trained); the
savers below write them only when the model's value is not the default.
Nothing is ever unpickled without ``weights_only=True``. Files always hold CPU tensors, whatever device the
model trained on (``save_atomic`` moves them), and reading maps everything to the CPU first; callers move the
model to their device afterwards.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save_file

from predictor.backbones import BACKBONES
from predictor.checkpoints import PACKAGE_CHECKPOINTS, checkpoint_file
from predictor.ethucy import STEP_S
from predictor.files import write_atomic
from predictor.group_rules import get_rule
from predictor.model import GPGraph, GPGraphConfig, check_group_mode, check_group_threshold_scale
from predictor.names import did_you_mean

FORMAT = "predictor.gpgraph/1"
META_GROUP_THRESHOLD_SCALE = "group_threshold_scale"  # optional meta key, see the module docstring
META_GROUP_MODE = "group_mode"  # optional meta key, see the module docstring
# The time between the positions a model was trained on, s (written by `gpgraph train`; a file without it was trained
# on the ETH/UCY protocol's 0.4 s, as every packaged one). load_model refuses any other: the API serves STEP_S.
META_STEP_S = "step_s"


class CheckpointError(ValueError):
    """A checkpoint file is unreadable, truncated, or does not fit the model."""


def read_safetensors(path: Path) -> dict:
    """A packaged ``.safetensors`` checkpoint as our dict format (config and meta in its metadata)."""
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
            state = {k: f.get_tensor(k) for k in f.keys()}
        return {"format": meta["format"], "config": json.loads(meta["config"]), "state_dict": state,
                "meta": json.loads(meta.get("meta", "{}"))}
    except (SafetensorError, KeyError, ValueError, OSError) as exc:
        raise CheckpointError(f"cannot read packaged checkpoint {path}: {exc}") from None


def read_file(path: str | Path) -> dict:
    """``torch.load`` with weights_only=True (or safetensors) and a clear error for corrupt files."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    if path.suffix == ".safetensors":
        return read_safetensors(path)
    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for truncated or foreign files
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]  # torch's messages run to pages
        raise CheckpointError(f"cannot read checkpoint {path} (truncated or not a torch file?): {first}") from None
    if not isinstance(obj, dict):
        raise CheckpointError(f"checkpoint {path} holds a {type(obj).__name__}, expected a dict")
    return obj


def is_reference_state(state: dict) -> bool:
    """Whether a state_dict uses the authors' GP-Graph parameter names."""
    return any(k.startswith("baseline_model.") for k in state) and "group_gen.th" in state


def convert_reference_state(state: dict, backbone: str = "sgcn") -> dict:
    """Rename the authors' GP-Graph state_dict to this package's ``GPGraph`` names."""
    renames = BACKBONES[backbone].reference_renames()
    out = {}
    for key, value in state.items():
        if key.startswith("baseline_model."):
            name = key[len("baseline_model.") :]
            for pattern, repl in renames:
                name = re.sub(pattern, repl, name)
            out["backbones.0." + name] = value
        elif key == "group_gen.th":
            out["assigner.threshold"] = value
        elif key.startswith("group_gen.group_cnn.0."):
            out["assigner.embed." + key.rsplit(".", 1)[1]] = value
        elif key == "group_mix.st_gcns_mix.0.weight":
            out["integrator.act.weight"] = value
        elif key.startswith("group_mix.st_gcns_mix.1."):
            out["integrator.linear." + key.rsplit(".", 1)[1]] = value.reshape(value.shape[0], *value.shape[1:2])
        else:
            raise CheckpointError(f"unexpected parameter {key!r} in a reference checkpoint")
    return out


def load_state(model: GPGraph, state: dict, source: str) -> None:
    """Load ``state`` strictly, turning mismatches into one readable CheckpointError."""
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        first = str(exc).splitlines()[:4]
        raise CheckpointError(
            f"checkpoint {source} does not fit a {model.config.backbone} GP-Graph "
            f"(another architecture or config?): {' '.join(first)}"
        ) from None


def resolve(name_or_path: str | Path) -> Path:
    """A file path as given, or a packaged checkpoint name such as 'gpgraph-stgcnn-hotel'."""
    path = checkpoint_file(name_or_path)
    if path is not None:
        return path
    found = PACKAGE_CHECKPOINTS.glob("*.safetensors") if PACKAGE_CHECKPOINTS.is_dir() else []
    names = sorted(p.stem for p in found)
    raise CheckpointError(f"no checkpoint file or packaged name {str(name_or_path)!r};"
                          f"{did_you_mean(str(name_or_path), names)} packaged: {', '.join(names)}")


def load_model(
    name_or_path: str | Path, backbone: str | None = None, grouping: str | None = None,
    group_threshold_scale: float | None = None, group_mode: str | None = None, group_rule: str | None = None,
) -> tuple[GPGraph, dict]:
    """Build a model from a checkpoint (ours or the authors'); returns (model in eval mode, meta).

    ``backbone`` and ``grouping`` override the config; for a reference checkpoint, whose file holds no
    config, the defaults are the published GP-Graph-SGCN with ``grouping`` ('official' to match its code).
    The model's ``group_threshold_scale`` is ``group_threshold_scale`` when given (finite, > 0), else the
    meta's ``"group_threshold_scale"`` when the file has one, else 1.0; likewise its ``group_mode`` is
    ``group_mode`` when given, else the meta's ``"group_mode"``, else None (the config's grouping).
    ``group_rule`` (a ``predictor.group_rules`` name) replaces the learned hard assignment at inference.
    """
    if group_threshold_scale is not None:
        group_threshold_scale = check_group_threshold_scale(group_threshold_scale)
    check_group_mode(group_mode)
    if group_rule is not None:
        get_rule(group_rule)  # before anything is read
    path = resolve(name_or_path)
    obj = read_file(path)
    if is_reference_state(obj):
        cfg = GPGraphConfig(backbone=backbone or "sgcn", grouping=grouping or "official")
        state, meta = convert_reference_state(obj, cfg.backbone), {"reference": True}
    elif obj.get("format") == FORMAT:
        d = dict(obj["config"])
        if grouping:
            d["grouping"] = grouping
        if backbone and backbone != d.get("backbone"):
            raise CheckpointError(f"checkpoint {path} is a {d.get('backbone')} model, not {backbone}")
        cfg, state, meta = GPGraphConfig.from_dict(d), obj["state_dict"], dict(obj.get("meta", {}))
    else:
        raise CheckpointError(f"{path} is neither a predictor checkpoint nor a reference GP-Graph state_dict")
    step = meta.get(META_STEP_S, STEP_S)
    if not isinstance(step, int | float) or abs(float(step) - STEP_S) > 1e-9:
        raise CheckpointError(f"checkpoint {path} was trained on positions {step!r} s apart; the predictor serves the "
                              f"ETH/UCY protocol's {STEP_S} s (8 observed, 12 predicted steps)")
    model = GPGraph(cfg)
    load_state(model, state, str(path))
    if group_threshold_scale is None:
        group_threshold_scale = _from_meta(meta, META_GROUP_THRESHOLD_SCALE, 1.0, check_group_threshold_scale, path)
    if group_mode is None:
        group_mode = _from_meta(meta, META_GROUP_MODE, None, check_group_mode, path)
    model.group_threshold_scale = group_threshold_scale
    model.group_mode = group_mode
    model.group_rule = group_rule
    return model.eval(), meta


def _from_meta(meta: dict, key: str, default: Any, check: Callable[[Any], Any], path: Path) -> Any:
    """``meta[key]`` (``default`` when absent) passed through ``check``; an invalid value is a CheckpointError."""
    try:
        return check(meta.get(key, default))
    except ValueError as exc:
        raise CheckpointError(f"checkpoint {path}: meta {exc}") from None


def meta_with_calibration(model: GPGraph, meta: dict | None) -> dict:
    """``meta`` plus the model's ``group_threshold_scale`` when it is not 1.0 and its ``group_mode`` when not
    None (else without those keys), so a file records the calibration its model was saved with and an
    uncalibrated one stays as before."""
    out = dict(meta or {})
    out.pop(META_GROUP_THRESHOLD_SCALE, None)
    out.pop(META_GROUP_MODE, None)
    if model.group_threshold_scale != 1.0:
        out[META_GROUP_THRESHOLD_SCALE] = model.group_threshold_scale
    if model.group_mode is not None:
        out[META_GROUP_MODE] = model.group_mode
    return out


def to_cpu(obj: Any) -> Any:
    """``obj`` with every tensor inside (nested dicts, lists, tuples) detached and moved to the CPU."""
    if isinstance(obj, torch.Tensor):
        return obj.detach().cpu()
    if isinstance(obj, dict):
        return {k: to_cpu(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [to_cpu(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(to_cpu(v) for v in obj)
    return obj


def save_atomic(obj: dict, path: str | Path) -> None:
    """Write ``obj`` (its tensors moved to the CPU) with torch.save to a temporary file in the same folder,
    then rename over ``path``."""
    obj = to_cpu(obj)
    write_atomic(path, lambda tmp: torch.save(obj, tmp))


def save_model(model: GPGraph, path: str | Path, meta: dict | None = None) -> None:
    """Save a model with its config inside (atomic); ``meta`` gains the model's calibration
    (``meta_with_calibration``)."""
    save_atomic(
        {"format": FORMAT, "config": model.config.to_dict(), "state_dict": model.state_dict(),
         "meta": meta_with_calibration(model, meta)},
        path,
    )


def export_packaged(model: GPGraph, path: str | Path, meta: dict | None = None) -> None:
    """Write a model as ``.safetensors`` with its config and ``meta`` (plus the model's calibration,
    ``meta_with_calibration``) as JSON metadata (for shipping)."""
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    metadata = {"format": FORMAT, "config": json.dumps(model.config.to_dict()),
                "meta": json.dumps(meta_with_calibration(model, meta))}
    save_file(state, str(path), metadata=metadata)
    os.chmod(path, 0o644)
