"""SGCN's inference fast paths equal the reference computations (conv2d layers, torch.softmax, the
per-coordinate sampling formula) up to float rounding."""

from __future__ import annotations

import copy
import pickle
import threading

import numpy as np
import pytest
import torch
from torch import nn
from torch.nn import functional as F

from predictor.backbones.cross_conv import CrossStack
from predictor.backbones.sgcn import SGCN, AsymmetricConv, MultiHeadScores
from predictor.sampling import cholesky_2x2, sample_positions


def _layers(seed: int = 0, n: int = 7) -> nn.ModuleList:
    torch.manual_seed(seed)
    layers = nn.ModuleList(AsymmetricConv(4) for _ in range(n))
    with torch.no_grad():
        for k, layer in enumerate(layers):
            layer.act.weight.fill_(0.1 + 0.05 * k)  # distinct slopes
    return layers


def _reference(layers: nn.ModuleList, x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Layer by layer with the modules' own forward (the cross-shaped conv2d): x (C, *batch, H, W)."""
    c, batch, (h, w) = x.shape[0], x.shape[1:-2], x.shape[-2:]
    y = x.movedim(0, -3).reshape(-1, c, h, w)
    m = None if mask is None else mask.expand(*batch, h, w).reshape(-1, 1, h, w)
    if m is not None:
        y = y * m
    for layer in layers:
        y = layer(y) if m is None else layer(y) * m
    return y.reshape(*batch, c, h, w).movedim(-3, 0)


@pytest.mark.parametrize("shape", [(16, 20, 20), (2, 8, 5, 5), (40, 8, 8), (3, 1, 1), (2, 3, 7, 4)])
@pytest.mark.parametrize("masked", [False, True])
def test_cross_stack_matches_the_layers(shape: tuple[int, ...], masked: bool) -> None:
    layers = _layers()
    stack = CrossStack(layers)
    gen = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for _ in range(2):  # the second call reuses the buffers
            x = torch.rand(4, *shape, generator=gen) * 2 - 0.5
            mask = (torch.rand(*shape[:-2], 1, *shape[-2:], generator=gen) > 0.3).float()[..., 0, :, :]
            mask = mask if masked else None
            ref = _reference(layers, x, mask)
            torch.testing.assert_close(stack(x, mask), ref, atol=1e-5, rtol=1e-5)
            gated = stack(x.transpose(-1, -2).contiguous().transpose(-1, -2), mask, 0.5)  # strided input
            assert gated.is_contiguous() and gated.shape == (*shape[:-2], 4, *shape[-2:])
            sig = torch.sigmoid(ref.movedim(0, -3))
            near = (sig - 0.5).abs() < 1e-5  # a rounding difference may flip the threshold there
            torch.testing.assert_close(gated[~near], F.threshold(sig, 0.5, 0.0)[~near], atol=1e-5, rtol=1e-5)


def test_cross_stack_buffers_for_changing_shapes() -> None:
    """More shapes than kept buffer sets, visited twice: every call equals the layers."""
    layers = _layers(2)
    stack = CrossStack(layers)
    with torch.no_grad():
        for n in [5, 6, 7, 8, 9, 10] * 2:
            x = torch.rand(4, 2, 3, n, n)
            torch.testing.assert_close(stack(x), _reference(layers, x, None), atol=1e-5, rtol=1e-5)


def test_cross_stack_follows_weight_changes() -> None:
    layers = _layers(0)
    stack = CrossStack(layers)
    x = torch.rand(4, 3, 6, 6)
    with torch.no_grad():
        stack(x)
        layers.load_state_dict(_layers(1).state_dict())  # in place
        torch.testing.assert_close(stack(x), _reference(layers, x, None), atol=1e-5, rtol=1e-5)
        layers[2].conv_w.bias.add_(0.5)  # in place
        torch.testing.assert_close(stack(x), _reference(layers, x, None), atol=1e-5, rtol=1e-5)
        layers[3].conv_h.weight = nn.Parameter(torch.randn(4, 4, 3, 1))  # replaced
        torch.testing.assert_close(stack(x), _reference(layers, x, None), atol=1e-5, rtol=1e-5)
        layers[4].act.weight.data = torch.tensor([0.7])  # new storage
        torch.testing.assert_close(stack(x), _reference(layers, x, None), atol=1e-5, rtol=1e-5)
        layers.double()
        torch.testing.assert_close(stack(x.double()), _reference(layers, x.double(), None))


def test_cross_stack_copies_pickles_and_runs_in_threads_and_inference_mode() -> None:
    model = SGCN().eval()
    x = torch.rand(4, 2, 8, 9, 9)
    with torch.no_grad():
        ref = _reference(model.spatial_asym, x, None).clone()
        model._spatial_stack(x)
        clone = copy.deepcopy(model)
        torch.testing.assert_close(clone._spatial_stack(x), ref, atol=1e-5, rtol=1e-5)
        loaded = pickle.loads(pickle.dumps(model))
        torch.testing.assert_close(loaded._spatial_stack(x), ref, atol=1e-5, rtol=1e-5)
    with torch.inference_mode():
        torch.testing.assert_close(model._spatial_stack(x), ref, atol=1e-5, rtol=1e-5)
    with torch.no_grad():  # buffers made in inference mode are not reused outside it
        torch.testing.assert_close(model._spatial_stack(x), ref, atol=1e-5, rtol=1e-5)

    inputs = [torch.rand(4, 2, 8, 9, 9, generator=torch.Generator().manual_seed(k)) for k in range(4)]
    expected = [_reference(model.spatial_asym, a, None) for a in inputs]
    errors: list[float] = []

    def work(k: int) -> None:
        with torch.no_grad():
            for _ in range(20):
                errors.append(float((model._spatial_stack(inputs[k]) - expected[k]).abs().max()))

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(errors) == 80 and max(errors) < 1e-5


def test_sgcn_masks_fast_path_matches_the_layers() -> None:
    """The no-grad interaction masks (CrossStack) equal the training path's (einsum layers)."""
    torch.manual_seed(3)
    model = SGCN()
    b, t, h, n = 3, 8, 4, 11
    s = torch.rand(b, t, h, n, n) * 2 - 1
    tmp = torch.rand(b, n, h, t, t) * 2 - 1
    node_mask = torch.arange(n)[None] < torch.tensor([[11], [7], [1]])
    valid = node_mask[:, :, None] & node_mask[:, None, :]
    ref_s, ref_t = (m.detach() for m in model._masks(s, tmp, valid))
    with torch.no_grad():
        fast_s, fast_t = model._masks(s, tmp, valid)
    assert fast_s.shape == ref_s.shape and fast_t.shape == ref_t.shape
    torch.testing.assert_close(fast_s, ref_s, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(fast_t, ref_t, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("length", [3, 8, 12, 20])
def test_short_row_softmax_matches_torch(length: int) -> None:
    torch.manual_seed(0)
    scores = MultiHeadScores(3, 64, 4)
    x = torch.randn(2, 5, length, 3)
    key_mask = torch.arange(length)[None, None] < torch.tensor([[[length]], [[max(1, length - 2)]]])
    key_mask = key_mask.expand(2, 5, length)
    ref = scores(x, key_mask).detach()
    with torch.no_grad():
        fast = scores(x, key_mask)
    torch.testing.assert_close(fast, ref, atol=1e-6, rtol=1e-5)


def test_sample_positions_equals_the_per_coordinate_formula() -> None:
    rng = np.random.default_rng(0)
    mu = rng.normal(size=(12, 7, 2))
    a = rng.normal(size=(12, 7, 2, 2))
    chol = cholesky_2x2(a @ np.swapaxes(a, -1, -2))
    z, last = rng.normal(size=(20, 12, 7, 2)), rng.normal(size=(7, 2))
    steps = np.empty(z.shape)
    steps[..., 0] = mu[None, ..., 0] + chol[None, ..., 0, 0] * z[..., 0] + chol[None, ..., 0, 1] * z[..., 1]
    steps[..., 1] = mu[None, ..., 1] + chol[None, ..., 1, 0] * z[..., 0] + chol[None, ..., 1, 1] * z[..., 1]
    np.testing.assert_array_equal(sample_positions(mu, chol, z, last), last + np.cumsum(steps, axis=1))
