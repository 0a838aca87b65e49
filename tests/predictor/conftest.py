"""Shared fixtures for the predictor tests: locate ../shared (the repository's sibling folder)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from predictor.ethucy import DEFAULT_DATA_DIR

SHARED = Path(__file__).resolve().parents[2] / ".." / "shared"
ETH_UCY = DEFAULT_DATA_DIR
REFERENCE = SHARED / "reference" / "gpgraph_sgcn"
SCENES = ("eth", "hotel", "univ", "zara1", "zara2")

torch.set_num_threads(1)


@pytest.fixture
def eth_ucy() -> Path:
    if not ETH_UCY.is_dir():
        pytest.skip(f"ETH/UCY data not found at {ETH_UCY} (needs the sibling ../shared folder, or ETH_UCY_DIR)")
    return ETH_UCY


@pytest.fixture
def reference() -> Path:
    if not (REFERENCE / "golden_outputs.npz").is_file():
        pytest.skip(f"reference checkpoints not found at {REFERENCE} (needs the sibling ../shared folder)")
    return REFERENCE


def write_synthetic_split(folder: Path, n_frames: int = 40, seed: int = 0) -> None:
    """A small crowdsim-style split: pairs walking side by side plus loners, with a group file."""
    import numpy as np

    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    rows, groups = [], []
    for pair in range(3):
        start = rng.uniform(-5, 5, size=2)
        vel = rng.normal(size=2) * 0.3
        ids = (2 * pair + 1, 2 * pair + 2)
        groups.append(ids)
        for f in range(n_frames):
            for k, pid in enumerate(ids):
                p = start + vel * f + np.array([0.0, 0.6 * k]) + rng.normal(scale=0.01, size=2)
                rows.append(f"{10 * f}\t{pid}\t{p[0]:.4f}\t{p[1]:.4f}\n")
    for pid in (7, 8):
        start, vel = rng.uniform(-5, 5, size=2), rng.normal(size=2) * 0.3
        for f in range(n_frames):
            p = start + vel * f
            rows.append(f"{10 * f}\t{pid}\t{p[0]:.4f}\t{p[1]:.4f}\n")
    rows.sort(key=lambda r: int(r.split()[0]))
    (folder / "sim.txt").write_text("".join(rows))
    (folder / "sim.groups.txt").write_text("\n".join(" ".join(map(str, g)) for g in groups) + "\n\n")


@pytest.fixture
def synthetic_data(tmp_path: Path) -> Path:
    root = tmp_path / "synthetic"
    for i, split in enumerate(("train", "val", "test")):
        write_synthetic_split(root / split, seed=i)
    return root
