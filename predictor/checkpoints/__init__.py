"""Packaged checkpoints (``<name>.safetensors``), loadable by name with ``predictor.load_predictor``.

This package imports no torch: `checkpoint_file` tells which file a name or path loads (used by
`predictor.checkpoint.resolve` and by `envs.policies.identity` to fingerprint the weights behind a name).
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_CHECKPOINTS = Path(__file__).parent


def checkpoint_file(name_or_path: str | Path) -> Path | None:
    """The file `name_or_path` loads: the path itself when it is a file, else the packaged
    ``<name>.safetensors``; None when it is neither."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    packaged = PACKAGE_CHECKPOINTS / f"{name_or_path}.safetensors"
    return packaged if packaged.is_file() else None
