"""What each packaged checkpoint is, in one line, from its own metadata (`gpgraph list`).

torch-free: the metadata is read from the safetensors header (8 bytes of little-endian length, then JSON whose
"__metadata__" holds our "config", "meta" and "format" strings), not by loading the weights. The checkpoint files
are never rewritten for this: their bytes are fingerprinted into benchmark records (`envs.policies.identity`).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

from predictor.checkpoints import PACKAGE_CHECKPOINTS

# Roles that live outside the checkpoint (who loads it by default). The only names of other packages' settings in
# predictor; tests/predictor/test_catalog.py checks them against envs.config.DEFAULT_PREDICTOR (NAME+RULE).
ROLES = {
    "gpgraph-stgcnn-synthetic": "role: grouping by the coherent-motion rule (gpgraph-stgcnn-synthetic+coherent-"
                                "motion), the default predictor of mpc-gpgraph (and of every crowdnav policy that "
                                "predicts)",
    "gpgraph-stgcnn-synthetic-conv": "role: the previous default (GP-Graph's own assigner), kept for comparison",
}
CONSTANT_VELOCITY = "model-free baseline: each person keeps their last velocity (no weights)"
ETH_UCY_SCENES = ("eth", "hotel", "univ", "zara1", "zara2")


def read_metadata(path: str | Path) -> dict[str, Any]:
    """{"config": dict, "meta": dict, "format": str} from a packaged ``.safetensors`` file's header (ValueError
    when the file has none)."""
    with open(path, "rb") as fh:
        (size,) = struct.unpack("<Q", fh.read(8))
        if size > 100_000_000:
            raise ValueError(f"{path}: not a safetensors file")
        header = json.loads(fh.read(size))
    raw = header.get("__metadata__") or {}
    if "config" not in raw:
        raise ValueError(f"{path}: no model config in its metadata")
    return {"config": json.loads(raw["config"]), "meta": json.loads(raw.get("meta", "{}")),
            "format": raw.get("format", "")}


def _model(config: dict[str, Any]) -> str:
    backbone = str(config.get("backbone", "?")).upper()
    if not (config.get("inter_branch") or config.get("intra_branch")):
        return f"{backbone} (no group branches)"
    assigner = config.get("assigner", "conv")
    assigner_text = "pairwise group assigner" if assigner == "pairwise" else "GP-Graph's own group assigner"
    return f"GP-Graph-{backbone}, {assigner_text}"


def _grouping(config: dict[str, Any], meta: dict[str, Any]) -> str:
    if not (config.get("inter_branch") or config.get("intra_branch")):
        return ""
    mode = meta.get("group_mode") or f"{config.get('grouping', 'exact')} grouping"
    mode = f"{mode} linkage" if mode in ("average", "single", "complete") else mode
    scale = meta.get("group_threshold_scale")
    return f"{mode} at {scale:g} x the learned threshold" if scale else mode


def _data(meta: dict[str, Any]) -> str:
    scene = meta.get("scene", "")
    data = meta.get("data") or {}
    init = (meta.get("train") or {}).get("init") or ""
    if scene == "synthetic":
        counts = "/".join(str(len(data.get(s, []))) for s in ("train", "val", "test"))
        text = f"crowdsim synthetic data ({counts} train/val/test recordings)" if data else "crowdsim synthetic data"
    elif scene in ETH_UCY_SCENES:
        text = f"ETH/UCY minus {scene} (leave-one-out: {scene} is its test scene)"
    else:
        text = f"scene {scene or 'unknown'}"
    text = f"{text}, fine-tuned from {init}" if init else text
    mix = meta.get("interpolation")
    if isinstance(mix, dict) and "alpha" in mix:  # predictor.interpolate (WiSE-FT)
        a = float(mix["alpha"])
        text += f", then weights {1 - a:g} x {mix.get('start')} + {a:g} x the fine-tuned ones"
    return text


def _metrics(meta: dict[str, Any]) -> str:
    epoch, loss = meta.get("epoch"), meta.get("val_loss")
    epochs = (meta.get("train") or {}).get("epochs")
    if loss is None:
        return ""
    kept = f"epoch {epoch} of {epochs}" if epochs else f"epoch {epoch}"
    whose = "the fine-tuned run's " if "interpolation" in meta else ""
    return f"{whose}val loss {loss:.3f} ({kept} kept)"


def catalog(checkpoints: Path = PACKAGE_CHECKPOINTS) -> list[tuple[str, str]]:
    """(name, description) of every packaged checkpoint, by name, then the constant-velocity baseline."""
    names = sorted(p.name[: -len(".safetensors")] for p in Path(checkpoints).glob("*.safetensors"))
    return [(n, describe(n, checkpoints)) for n in names] + [("constant-velocity", CONSTANT_VELOCITY)]


def describe(name: str, checkpoints: Path = PACKAGE_CHECKPOINTS) -> str:
    """One line on packaged checkpoint `name`: model and assigner; grouping; training data; validation loss; its
    role (ROLES) or the note it was packaged with."""
    info = read_metadata(Path(checkpoints) / f"{name}.safetensors")
    config, meta = info["config"], info["meta"]
    parts = [_model(config), _grouping(config, meta), f"trained on {_data(meta)}", _metrics(meta)]
    if name in ROLES:
        parts.append(ROLES[name])
    elif meta.get("note"):
        parts.append(f"note: {meta['note']}")
    return "; ".join(p for p in parts if p)
