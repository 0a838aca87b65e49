"""Group assignment, straight-through estimator, pooling and masks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from predictor import grouping


def _adj(n: int, edges: list[tuple[int, int]]) -> np.ndarray:
    a = np.zeros((n, n), dtype=bool)
    for i, j in edges:
        a[i, j] = a[j, i] = True
    return a


def test_official_relabel_splits_a_chain_that_exact_components_join() -> None:
    adj = _adj(3, [(1, 0), (2, 1)])
    # (1,0): ped 1 takes raw label 0; (2,1): ped 2 takes raw 1 (ped 1's *index*), so 2 is split off.
    np.testing.assert_array_equal(grouping.official_relabel(adj), [0, 0, 1])
    exact = grouping.connected_components(torch.from_numpy(adj)[None])
    np.testing.assert_array_equal(exact[0].numpy(), [0, 0, 0])


def test_connected_components_numbers_by_first_member() -> None:
    adj = torch.from_numpy(_adj(6, [(4, 2), (5, 0), (1, 3)]))[None]
    np.testing.assert_array_equal(grouping.connected_components(adj)[0].numpy(), [0, 1, 2, 1, 2, 0])


def test_connected_components_match_scipy_on_random_graphs() -> None:
    from scipy.sparse import csgraph

    rng = np.random.default_rng(0)
    for n, density in [(1, 0.0), (7, 0.1), (20, 0.08), (40, 0.03), (57, 0.3)]:
        upper = np.triu(rng.random((6, n, n)) < density, k=1)
        adj = upper | upper.transpose(0, 2, 1)
        ours = grouping.connected_components(torch.from_numpy(adj)).numpy()
        for b in range(6):
            ref = csgraph.connected_components(adj[b], directed=False)[1]
            # same partition, numbered by first member
            first = {c: i for i, c in reversed(list(enumerate(ref)))}
            order = {c: r for r, c in enumerate(sorted(first, key=first.get))}
            np.testing.assert_array_equal(ours[b], [order[c] for c in ref])


def test_threshold_groups_ignore_padding_and_pad_with_own_groups() -> None:
    dist = torch.full((1, 4, 4), 5.0)
    dist[0, 0, 1] = dist[0, 1, 0] = 0.5
    dist[0, 2, 3] = dist[0, 3, 2] = 0.1  # ped 3 is padding: must not join ped 2
    mask = torch.tensor([[True, True, True, False]])
    for mode in ("exact", "official"):
        labels = grouping.threshold_groups(dist, torch.tensor([1.0]), mask, mode)
        np.testing.assert_array_equal(labels[0].numpy(), [0, 0, 1, 2])
    with pytest.raises(ValueError, match="valid"):
        grouping.threshold_groups(dist, torch.tensor([1.0]), mask, "bogus")


def test_ratio_groups_merge_closest_pairs() -> None:
    pts = torch.tensor([0.0, 0.1, 5.0, 5.2, 10.0])
    dist = (pts[:, None] - pts[None]).abs()[None]
    labels = grouping.ratio_groups(dist, torch.ones(1, 5, dtype=torch.bool), ratio=2)
    np.testing.assert_array_equal(labels[0].numpy(), [0, 0, 1, 1, 2])  # 5 - ceil(5/2) = 2 merges


def test_straight_through_keeps_value_and_passes_gradient() -> None:
    torch.manual_seed(0)
    x = torch.randn(1, 8, 3, 2)
    dist = torch.tensor([[[0.0, 0.5, 3.0], [0.5, 0.0, 3.0], [3.0, 3.0, 0.0]]], requires_grad=True)
    pi = torch.tensor([1.0], requires_grad=True)
    mask = torch.ones(1, 3, dtype=torch.bool)
    a = grouping.soft_assignment(dist, pi, 0.1, mask)
    torch.testing.assert_close(a.sum(dim=1), torch.ones(1, 3))
    y = grouping.straight_through(x, a)
    torch.testing.assert_close(y, x)
    (y * torch.randn_like(y)).sum().backward()
    assert pi.grad is not None and pi.grad.abs().item() > 0
    assert dist.grad is not None and dist.grad.abs().sum().item() > 0


def test_pool_unpool_and_same_group_mask() -> None:
    x = torch.arange(2 * 1 * 4 * 1, dtype=torch.float32).reshape(2, 1, 4, 1)  # (B=2, T=1, N=4, C=1)
    labels = torch.tensor([[0, 1, 0, 2], [0, 0, 1, 2]])  # window 1: ped 3 is padding (its own group 2)
    mask = torch.tensor([[True, True, True, True], [True, True, True, False]])
    pooled, gmask = grouping.pool(x, labels, mask)
    torch.testing.assert_close(pooled[0, 0, :, 0], torch.tensor([1.0, 1.0, 3.0]))  # mean(0, 2), 1, 3
    torch.testing.assert_close(pooled[1, 0, :2, 0], torch.tensor([4.5, 6.0]))
    np.testing.assert_array_equal(gmask.numpy(), [[True, True, True], [True, True, False]])
    back = grouping.unpool(pooled, labels)
    torch.testing.assert_close(back[0, 0, :, 0], torch.tensor([1.0, 1.0, 1.0, 3.0]))
    same = grouping.same_group_mask(labels, mask)
    assert same[0, 0, 2] and not same[0, 0, 1] and same[1, 1, 1] and not same[1, 3, 3]
