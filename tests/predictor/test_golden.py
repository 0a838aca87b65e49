"""The published GP-Graph-SGCN checkpoints reproduce the authors' raw outputs and groups."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from predictor.checkpoint import load_model

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")


def _window(g: np.lib.npyio.NpzFile, key: str) -> tuple[torch.Tensor, torch.Tensor]:
    obs_abs = torch.from_numpy(g[key + "obs_abs"]).permute(2, 0, 1)  # (8, N, 2)
    obs_rel = torch.from_numpy(g[key + "obs_rel"]).permute(2, 0, 1)
    return obs_abs, obs_rel


def _pad(items: list[torch.Tensor], n: int) -> torch.Tensor:
    return torch.stack([torch.nn.functional.pad(x, (0, 0, 0, n - x.shape[1])) for x in items])


@pytest.mark.parametrize("scene", SCENES)
def test_reference_checkpoint_reproduces_golden_outputs(reference: Path, scene: str) -> None:
    g = np.load(reference / "golden_outputs.npz")
    model, meta = load_model(reference / scene / "val_best.pth", backbone="sgcn", grouping="official")
    assert meta["reference"] and sum(p.numel() for p in model.parameters()) == 36287
    keys = sorted({k[: -len("out")] for k in g.files if k.startswith(scene + "_") and k.endswith("_out")})
    assert len(keys) == 6
    windows = [_window(g, k) for k in keys]
    with torch.no_grad():
        for key, (obs_abs, obs_rel) in zip(keys, windows, strict=True):
            out = model(obs_abs[None], obs_rel[None], torch.ones(1, obs_abs.shape[1], dtype=torch.bool))
            np.testing.assert_allclose(out.raw[0].permute(2, 0, 1).numpy(), g[key + "out"], atol=1e-4)
            np.testing.assert_array_equal(out.groups[0].numpy(), g[key + "groups"])
        # the same windows padded into one batch give the same outputs
        n = max(a.shape[1] for a, _ in windows)
        mask = torch.stack([torch.arange(n) < a.shape[1] for a, _ in windows])
        out = model(_pad([a for a, _ in windows], n), _pad([r for _, r in windows], n), mask)
    for i, key in enumerate(keys):
        k = windows[i][0].shape[1]
        np.testing.assert_allclose(out.raw[i, :, :k].permute(2, 0, 1).numpy(), g[key + "out"], atol=1e-4)
        np.testing.assert_array_equal(out.groups[i, :k].numpy(), g[key + "groups"])
