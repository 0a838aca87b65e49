"""Batched training: micro-batching keeps the gradient of the full batch; batching keeps the loss."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from predictor.batch import collate
from predictor.model import GPGraph, GPGraphConfig
from predictor.train import TrainConfig, batch_loss, eval_batches, make_batches, split_by_size, validation_loss
from predictor.windows import Window


def _windows(sizes: list[int], seed: int = 0) -> list[Window]:
    rng = np.random.default_rng(seed)
    out = []
    for n in sizes:
        traj = np.cumsum(rng.normal(scale=0.3, size=(20, n, 2)), axis=0)
        out.append(Window(traj[:8], traj[8:], np.arange(n), None))
    return out


def _grads(model: GPGraph) -> torch.Tensor:
    return torch.cat([p.grad.flatten() for p in model.parameters() if p.grad is not None])


def test_split_by_size_respects_budget() -> None:
    parts = split_by_size(_windows([2, 9, 3, 2, 8]), max_pairs=27)
    assert [[w.n_peds for w in p] for p in parts] == [[2, 2, 3], [8], [9]]
    assert len(split_by_size(_windows([2, 9]), 0)) == 1


def test_micro_batches_give_the_full_batch_gradient() -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="stgcnn"))
    windows = _windows([2, 5, 3, 7, 4])
    batch_loss(model, collate(windows)).backward()
    full = _grads(model).clone()
    model.zero_grad()
    parts = split_by_size(windows, max_pairs=30)
    assert len(parts) > 1
    for p in parts:
        (batch_loss(model, collate(p)) * (len(p) / len(windows))).backward()
    torch.testing.assert_close(_grads(model), full, atol=1e-5, rtol=1e-4)


def test_batched_loss_is_mean_of_window_losses() -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="stgcnn")).eval()
    windows = _windows([3, 6])
    with torch.no_grad():
        joint = batch_loss(model, collate(windows))
        alone = [batch_loss(model, collate([w])) for w in windows]
    assert joint.item() == pytest.approx(float(np.mean([a.item() for a in alone])), rel=1e-5)


def test_make_batches_covers_every_window_once() -> None:
    windows = _windows([2, 3, 4, 5, 6, 7, 8])
    steps = make_batches(windows, batch_size=3, bucket=2, rng=np.random.default_rng(0), max_pairs=40)
    sizes = sorted(int(n) for step in steps for b in step for n in b.node_mask.sum(dim=1))
    assert sizes == [2, 3, 4, 5, 6, 7, 8]
    assert all(sum(b.node_mask.shape[0] for b in step) <= 3 for step in steps)


def test_train_config_validation() -> None:
    with pytest.raises(ValueError):
        TrainConfig(lr=0.0)
    with pytest.raises(ValueError):
        TrainConfig(max_pairs=-1)


def test_validation_loss_does_not_depend_on_batching() -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="sgcn"))
    windows = _windows([2, 9, 3, 2, 8, 5, 4], seed=2)
    sized = eval_batches(windows, batch_size=3, max_pairs=40)
    assert sum(b.node_mask.shape[0] for b in sized) == len(windows)
    assert all(b.node_mask.shape[0] <= 3 and b.node_mask.shape[0] * b.node_mask.shape[1] ** 2 <= 81 for b in sized)
    one = validation_loss(model, [collate(windows)])
    assert validation_loss(model, sized) == pytest.approx(one, rel=1e-5)
    assert validation_loss(model, eval_batches(windows, batch_size=2, max_pairs=0)) == pytest.approx(one, rel=1e-5)


def test_init_loads_a_checkpoints_weights_and_refuses_another_architecture() -> None:
    from predictor.checkpoint import load_model
    from predictor.train import initial_weights

    source, _ = load_model("gpgraph-stgcnn-synthetic")  # GP-Graph+S: bce_weight 2 (a loss weight only)
    torch.manual_seed(123)
    model = GPGraph(GPGraphConfig(backbone="stgcnn", bce_weight=0.0, assigner="pairwise"))
    pairs = zip(model.state_dict().values(), source.state_dict().values(), strict=True)
    assert any(not torch.equal(a, b) for a, b in pairs)
    initial_weights(model, "gpgraph-stgcnn-synthetic")
    for (k, a), b in zip(model.state_dict().items(), source.state_dict().values(), strict=True):
        assert torch.equal(a, b), k
    with pytest.raises(ValueError, match="backbone 'stgcnn' \\(init\\) vs 'sgcn'"):
        initial_weights(GPGraph(GPGraphConfig(backbone="sgcn", assigner="pairwise")), "gpgraph-stgcnn-synthetic")
    with pytest.raises(ValueError, match="assigner 'pairwise' \\(init\\) vs 'conv'"):
        initial_weights(GPGraph(GPGraphConfig(backbone="stgcnn")), "gpgraph-stgcnn-synthetic")
