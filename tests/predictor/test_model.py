"""GP-Graph model: configuration, registry, ablation switches, batching and gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from predictor.backbones import BACKBONES, make_backbone
from predictor.batch import collate
from predictor.gaussian import masked_nll, mean_cov, nll
from predictor.model import GPGraph, GPGraphConfig
from predictor.train import batch_loss, group_bce
from predictor.windows import Window


def _windows(sizes: list[int], seed: int = 0, labelled: bool = False) -> list[Window]:
    rng = np.random.default_rng(seed)
    out = []
    for n in sizes:
        traj = np.cumsum(rng.normal(scale=0.3, size=(20, n, 2)), axis=0) + rng.uniform(-3, 3, size=(1, n, 2))
        gid = np.arange(n) // 2 if labelled else None
        out.append(Window(traj[:8], traj[8:], np.arange(n), gid))
    return out


def test_unknown_backbone_lists_valid_names() -> None:
    with pytest.raises(ValueError, match="unknown backbone 'gru'; valid backbones: sgcn, stgcnn"):
        GPGraphConfig(backbone="gru")
    with pytest.raises(ValueError, match="valid backbones"):
        make_backbone("nope")


@pytest.mark.parametrize(
    "kwargs",
    [{"grouping": "fuzzy"}, {"integration": "max"}, {"tau": 0.0}, {"sample_level": "crowd"},
     {"pedestrian_branch": False, "inter_branch": False, "intra_branch": False}],
)
def test_config_rejects_bad_values(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        GPGraphConfig(**kwargs)


@pytest.mark.parametrize(("backbone", "assigner"), [*((b, "conv") for b in sorted(BACKBONES)), ("stgcnn", "pairwise")])
def test_padding_does_not_change_outputs(backbone: str, assigner: str) -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone=backbone, assigner=assigner)).eval()
    windows = _windows([3, 6, 2])
    with torch.no_grad():
        b = collate(windows)
        joint = model(b.obs_abs, b.obs_rel, b.node_mask)
        for i, w in enumerate(windows):
            s = collate([w])
            alone = model(s.obs_abs, s.obs_rel, s.node_mask)
            torch.testing.assert_close(joint.raw[i, :, : w.n_peds], alone.raw[0], atol=1e-5, rtol=1e-4)
            assert torch.equal(joint.groups[i, : w.n_peds], alone.groups[0])


@pytest.mark.parametrize(
    "kwargs",
    [{"weight_share": False}, {"inter_branch": False}, {"intra_branch": False}, {"pedestrian_branch": False},
     {"grouping": "ratio"}, {"integration": "mean"}, {"grouping": "official"}],
)
def test_ablation_switches_train(kwargs: dict) -> None:
    torch.manual_seed(0)
    cfg = GPGraphConfig(backbone="stgcnn", **kwargs)
    model = GPGraph(cfg)
    n_backbones = 1 if cfg.weight_share else sum(cfg.branches)
    assert len(model.backbones) == n_backbones
    batch = collate(_windows([4, 5]))
    loss = batch_loss(model, batch)
    loss.backward()
    assert torch.isfinite(loss)
    assert all(p.grad is not None for p in model.backbones.parameters())


def test_backbone_only_has_own_groups_and_matches_backbone() -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig.backbone_only("stgcnn")).eval()
    b = collate(_windows([4]))
    out = model(b.obs_abs, b.obs_rel, b.node_mask)
    np.testing.assert_array_equal(out.groups[0].numpy(), [0, 1, 2, 3])
    direct = model.backbones[0](b.obs_rel, b.node_mask)
    torch.testing.assert_close(out.raw, direct)


def test_group_assignment_receives_gradient() -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="sgcn"))
    loss = batch_loss(model, collate(_windows([4, 3])))
    loss.backward()
    assert model.assigner.threshold.grad is not None
    assert model.assigner.threshold.grad.abs().item() > 0
    assert model.assigner.embed.weight.grad.abs().sum().item() > 0


def test_supervised_bce_pulls_threshold_towards_labels() -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="stgcnn", bce_weight=1.0))
    batch = collate(_windows([4, 4], labelled=True))
    out = model(batch.obs_abs, batch.obs_rel, batch.node_mask)
    bce = group_bce(out.dist, out.pi, model.config.tau, batch)
    assert bce.item() > 0
    total = batch_loss(model, batch)
    plain = masked_nll(out.raw, batch.pred_rel, batch.node_mask)
    assert total.item() > plain.item()


def test_gaussian_nll_matches_scipy() -> None:
    from scipy.stats import multivariate_normal

    raw = torch.tensor([0.1, -0.2, np.log(0.5), np.log(0.3), 0.4], dtype=torch.float64)
    target = torch.tensor([0.3, 0.1], dtype=torch.float64)
    mu, cov = mean_cov(raw)
    expected = -multivariate_normal(mu.numpy(), cov.numpy()).logpdf(target.numpy())
    assert nll(raw, target).item() == pytest.approx(expected)


def test_sgcn_training_and_inference_paths_agree() -> None:
    from predictor.backbones.sgcn import AsymmetricConv

    torch.manual_seed(0)
    layer = AsymmetricConv(4)
    x = torch.randn(3, 4, 7, 5)
    with torch.no_grad():
        conv = layer(x)
    torch.testing.assert_close(layer(x), conv, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("backbone", sorted(BACKBONES))
def test_inference_sharing_matches_training_forward(backbone: str) -> None:
    """Without gradients the pedestrian and intra-group branches share the backbone's edge-independent
    work; the outputs must equal the stacked forward that training runs."""
    torch.manual_seed(1)
    model = GPGraph(GPGraphConfig(backbone=backbone)).eval()
    b = collate(_windows([5, 9, 2, 7], seed=3))
    with torch.no_grad():
        shared = model(b.obs_abs, b.obs_rel, b.node_mask)
    stacked = model(b.obs_abs, b.obs_rel, b.node_mask)
    assert stacked.raw.requires_grad and not shared.raw.requires_grad
    assert torch.equal(shared.groups, stacked.groups)
    real = b.node_mask[:, None, :, None].expand_as(shared.raw)
    torch.testing.assert_close(shared.raw[real], stacked.raw.detach()[real], atol=1e-5, rtol=1e-4)
