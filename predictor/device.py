"""Where models run: one place that turns ``--device cpu|cuda|auto`` into a ``torch.device``.

Only the model's forward and backward passes move to the device. Everything random (shuffling, rotations,
the latent draws of evaluation and prediction) is drawn by numpy Generators on the CPU, so a given seed gives
the same draws on every device, and checkpoints always hold CPU tensors (``predictor.checkpoint``).
"""

from __future__ import annotations

from collections.abc import Callable

import torch

DEVICES = ("cpu", "cuda", "auto")


def resolve_device(name: str, cuda_available: Callable[[], bool] | None = None) -> torch.device:
    """The ``torch.device`` for ``name``: 'cpu', 'cuda', or 'auto' (cuda when available, else cpu).

    ``cuda_available`` (default ``torch.cuda.is_available``) is asked only for 'cuda' and 'auto'. Raises
    ValueError, with a one-line message, for another name or for 'cuda' without a usable CUDA device.
    """
    if name not in DEVICES:
        raise ValueError(f"--device must be one of {', '.join(DEVICES)}, got {name!r}")
    if name == "cpu":
        return torch.device("cpu")
    available = bool((cuda_available or torch.cuda.is_available)())
    if name == "auto":
        return torch.device("cuda" if available else "cpu")
    if not available:
        raise ValueError("--device cuda: no CUDA device is available to torch (use --device cpu or auto)")
    return torch.device("cuda")


def model_device(module: torch.nn.Module) -> torch.device:
    """The device of ``module``'s first parameter (CPU for a module without parameters)."""
    param = next(module.parameters(), None)
    return param.device if param is not None else torch.device("cpu")
