"""The pairwise group assigner: invariances, what its features mean, and what it can learn that F_phi cannot."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from predictor.batch import collate
from predictor.model import GPGraph, GPGraphConfig, GroupAssigner
from predictor.pair_assigner import PairwiseAssigner, pair_features
from predictor.windows import Window

torch.set_num_threads(1)


def _rotation(theta: float) -> torch.Tensor:
    return torch.tensor([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])


def _walk(b: int, n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(b, 8, n, 2, generator=g) * 0.3).cumsum(1) + torch.randn(b, 1, n, 2, generator=g) * 3


def test_distance_is_symmetric_zero_on_the_diagonal_and_invariant_to_the_scene_frame() -> None:
    torch.manual_seed(0)
    assigner = PairwiseAssigner()
    x = _walk(3, 6, 0)
    d = assigner(x)
    torch.testing.assert_close(d, d.transpose(1, 2))
    assert torch.all(d.diagonal(dim1=1, dim2=2) == 0) and torch.all(d >= 0)
    moved = x @ _rotation(2.1).T + torch.tensor([40.0, -7.0])
    torch.testing.assert_close(assigner(moved), d, atol=1e-5, rtol=1e-5)
    perm = torch.tensor([3, 0, 5, 1, 4, 2])
    torch.testing.assert_close(assigner(x[:, :, perm]), d[:, perm][:, :, perm], atol=1e-6, rtol=1e-6)


def _pair(kind: str, spacing: float, heading: float, speed: float = 1.2, step_s: float = 0.4) -> torch.Tensor:
    """(8, 2, 2): two people walking at `speed` m/s in direction `heading`, abreast or in file `spacing` m apart."""
    u = torch.tensor([math.cos(heading), math.sin(heading)])
    normal = torch.tensor([-u[1], u[0]])
    offset = (normal if kind == "abreast" else u) * spacing
    lead = torch.arange(8.0)[:, None] * speed * step_s * u
    return torch.stack([lead, lead + offset], dim=1)


def test_features_tell_abreast_from_in_file_in_any_orientation() -> None:
    for heading in (0.0, 0.7, 2.5, -1.9):
        abreast = pair_features(_pair("abreast", 0.8, heading)[None])[0, :, 0, 1]  # (8, 7)
        file_ = pair_features(_pair("file", 0.8, heading)[None])[0, :, 0, 1]
        dist, rel_speed, mean_speed, speed_diff, cos, along, across = abreast.T
        torch.testing.assert_close(dist, torch.full((8,), 0.8), atol=1e-3, rtol=0)
        torch.testing.assert_close(mean_speed, torch.full((8,), 0.48), atol=1e-3, rtol=0)  # m per 0.4 s step
        assert rel_speed.max() < 1e-2 and speed_diff.max() < 1e-3 and cos.min() > 0.999
        assert along.max() < 1e-3 and across.min() > 0.79
        assert file_[:, 5].min() > 0.79 and file_[:, 6].max() < 1e-3  # along / across swap roles


def test_standing_pairs_are_scored_by_distance_alone() -> None:
    still = torch.zeros(1, 8, 2, 2)
    still[:, :, 1, 0] = 1.0
    f = pair_features(still)[0, :, 0, 1]
    assert torch.all(f[:, 4] == 0)  # no heading agreement without headings
    torch.testing.assert_close(f[:, 5], f[:, 6])


def _train_bce(assigner: torch.nn.Module, steps: int = 150) -> float:
    """BCE-train `assigner` to link abreast pairs and not in-file pairs 0.8 m apart, headings random; return the
    accuracy of D <= pi on fresh headings."""
    def data(seed: int) -> tuple[torch.Tensor, torch.Tensor]:
        rng = np.random.default_rng(seed)
        kinds = rng.integers(0, 2, 64)
        x = torch.stack([_pair("abreast" if k else "file", 0.8, float(rng.uniform(-np.pi, np.pi))) for k in kinds])
        return x, torch.tensor(kinds, dtype=torch.float32)

    opt = torch.optim.Adam(assigner.parameters(), lr=0.02)
    x, y = data(0)
    for _ in range(steps):
        opt.zero_grad()
        d = assigner(x)[:, 0, 1]
        loss = torch.nn.functional.binary_cross_entropy_with_logits((assigner.threshold - d) / 0.1, y)
        loss.backward()
        opt.step()
    x, y = data(1)
    with torch.no_grad():
        linked = (assigner(x)[:, 0, 1] <= assigner.threshold).float()
    return float((linked == y).float().mean())


def test_pairwise_assigner_learns_formation_that_the_linear_embedding_cannot_see() -> None:
    torch.manual_seed(0)
    assert _train_bce(PairwiseAssigner()) > 0.95
    torch.manual_seed(0)
    assert _train_bce(GroupAssigner()) < 0.75  # F_phi: a fixed norm of the offset in scene axes, near chance


def test_config_names_the_assigner_and_old_configs_load_as_gp_graph() -> None:
    with pytest.raises(ValueError, match=r"assigner must be one of \('conv', 'pairwise'\)"):
        GPGraphConfig(assigner="knn")
    old = {k: v for k, v in GPGraphConfig(backbone="stgcnn").to_dict().items() if k != "assigner"}
    assert GPGraphConfig.from_dict(old).assigner == "conv"
    assert isinstance(GPGraph(GPGraphConfig(assigner="pairwise")).assigner, PairwiseAssigner)


def test_pairwise_model_round_trips_through_a_checkpoint(tmp_path) -> None:
    from predictor.checkpoint import load_model, save_model

    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    traj = np.cumsum(rng.normal(scale=0.3, size=(20, 5, 2)), axis=0)
    b = collate([Window(traj[:8], traj[8:], np.arange(5), None)])
    model = GPGraph(GPGraphConfig(backbone="stgcnn", assigner="pairwise")).eval()
    path = tmp_path / "m.pt"
    save_model(model, path)
    loaded, _ = load_model(str(path))
    assert loaded.config.assigner == "pairwise"
    with torch.no_grad():
        torch.testing.assert_close(loaded(b.obs_abs, b.obs_rel, b.node_mask).raw,
                                   model(b.obs_abs, b.obs_rel, b.node_mask).raw)
