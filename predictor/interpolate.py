"""Weight-space interpolation of a pretrained model and its fine-tuned copy (WiSE-FT).

Wortsman et al., "Robust fine-tuning of zero-shot models" (CVPR 2022): the weights
``(1 - alpha) * start + alpha * end`` of a pretrained model (``start``, e.g. the crowdsim-only
``gpgraph-stgcnn-synthetic-conv``) and the same model fine-tuned from it (``end``, e.g. a leave-one-scene-out
ETH/UCY run) often predict an unseen scene better than either end. Fine-tuning on four ETH/UCY scenes erases much
of what crowdsim taught about the fifth (RESULTS.md, "What crowdsim pretraining buys on real data"); the
interpolation keeps part of it.

Both checkpoints must have the same architecture (every ``GPGraphConfig`` field that shapes the weights; the
loss-only ``bce_weight`` may differ) and the same parameter names and shapes. The result takes ``end``'s config,
grouping calibration (threshold scale, mode) and meta, and records the interpolation in the meta under
``"interpolation"``. ``alpha`` 0 gives ``start``'s weights and 1 ``end``'s, exactly.
"""

from __future__ import annotations

from pathlib import Path

import torch

from predictor.checkpoint import CheckpointError, load_model, save_model
from predictor.model import GPGraph
from predictor.train import architecture_differences

META_INTERPOLATION = "interpolation"


def check_alpha(alpha: float) -> float:
    """``alpha`` as a float in [0, 1]; ValueError otherwise (NaN included)."""
    a = float(alpha)
    if not 0.0 <= a <= 1.0:
        raise ValueError(f"alpha must be a number in [0, 1] (0: the start weights, 1: the end weights), got {alpha!r}")
    return a


def interpolate_models(start: GPGraph, end: GPGraph, alpha: float) -> dict[str, torch.Tensor]:
    """The state dict ``(1 - alpha) * start + alpha * end`` (float tensors; any other dtype must be equal in both
    and is taken from ``end``). ValueError when the architectures, names or shapes differ."""
    alpha = check_alpha(alpha)
    diff = architecture_differences(start.config, end.config)
    if diff:
        raise ValueError(f"cannot interpolate models of different architectures: {diff}")
    sa, sb = start.state_dict(), end.state_dict()
    if set(sa) != set(sb):
        raise ValueError(f"cannot interpolate: parameters only in one model: {sorted(set(sa) ^ set(sb))[:4]}")
    out = {}
    for name, wb in sb.items():
        wa = sa[name]
        if wa.shape != wb.shape:
            raise ValueError(f"cannot interpolate {name}: shapes {tuple(wa.shape)} and {tuple(wb.shape)}")
        if wb.is_floating_point():
            out[name] = wa if alpha == 0.0 else wb if alpha == 1.0 else (1.0 - alpha) * wa + alpha * wb
        elif torch.equal(wa, wb):
            out[name] = wb
        else:
            raise ValueError(f"cannot interpolate {name}: a non-float tensor ({wb.dtype}) that differs")
    return out


def interpolate_checkpoints(start: str | Path, end: str | Path, alpha: float, out: str | Path) -> dict:
    """Write the interpolated checkpoint (this package's ``.pt`` format, atomically) to ``out``; returns its meta.
    ``start``/``end``: packaged names or paths. CheckpointError/ValueError on unreadable or mismatched input,
    before anything is written."""
    alpha = check_alpha(alpha)
    start_model, _ = load_model(start)
    end_model, meta = load_model(end)
    state = interpolate_models(start_model, end_model, alpha)
    if not all(bool(torch.isfinite(v).all()) for v in state.values() if v.is_floating_point()):
        raise CheckpointError(f"interpolating {start} and {end} gives non-finite weights (a corrupt checkpoint?)")
    end_model.load_state_dict(state)
    meta = {**meta, META_INTERPOLATION: {"start": str(start), "end": str(end), "alpha": alpha,
                                         "method": "WiSE-FT: (1 - alpha) * start + alpha * end"}}
    save_model(end_model, out, meta=meta)
    return meta
