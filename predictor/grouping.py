"""Group assignment, straight-through estimator, pedestrian group pooling/unpooling and group masks.

Batched layout: B windows padded to N pedestrians; ``node_mask`` (B, N) marks real pedestrians, which are
always the first ones of each window. Group labels (B, N) are 0..G_b-1 for the real pedestrians of window
b and G_b, G_b+1, ... for its padding, so every padded node is a group of its own.

Hard assignment from the learned pair distances D and a threshold t ('exact', 'official': pairs with D <= t;
'average': average-linkage clustering of D cut at t, inference only, see ``GPGraph.group_mode``).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

GROUPING_MODES = ("exact", "official", "ratio")  # GPGraphConfig.grouping (training and inference)
THRESHOLD_MODES = ("exact", "official", "average")  # threshold_groups; GPGraph.group_mode (inference override)


def pair_mask(node_mask: Tensor) -> Tensor:
    """(B, N, N) bool: both pedestrians real."""
    return node_mask[:, :, None] & node_mask[:, None, :]


def pairwise_distance(emb: Tensor) -> Tensor:
    """D (B, N, N): mean over time of the L2 distance between embeddings ``emb`` (B, C, T, N)."""
    e = emb.permute(0, 2, 3, 1)  # (B, T, N, C)
    return torch.cdist(e, e, compute_mode="donot_use_mm_for_euclid_dist").mean(dim=1)


def connected_components(adj: Tensor) -> Tensor:
    """Exact connected components of symmetric bool graphs ``adj`` (B, N, N); labels (B, N) by first member.

    Min-label propagation in numpy: every node repeatedly takes the smallest index among itself and its
    neighbours until nothing changes (at most the graph diameter + 1 passes), so each component ends up
    labelled by its first member; components are then numbered 0, 1, ... in order of first members.
    """
    a = adj.detach().cpu().numpy()
    a = a | a.transpose(0, 2, 1)
    b, n, _ = a.shape
    lab = np.broadcast_to(np.arange(n), (b, n)).copy()
    while True:
        nxt = np.minimum(lab, np.where(a, lab[:, None, :], n).min(axis=2))
        if np.array_equal(nxt, lab):
            break
        lab = nxt
    is_root = lab == np.arange(n)
    rank = np.cumsum(is_root, axis=1) - 1
    return torch.from_numpy(np.take_along_axis(rank, lab, axis=1)).to(adj.device)


def official_relabel(adj: np.ndarray) -> np.ndarray:
    """The reference code's order-dependent merging for one window, ``adj`` (n, n) bool of D <= pi.

    Visits pairs (r, c) with r > c in row-major order; every pedestrian whose label equals r's label gets
    the raw label c. Final labels are the raw values renumbered 0..G-1 in increasing order of raw value.
    This can split chains, so it is not connected components.
    """
    n = adj.shape[0]
    raw = np.arange(n)
    for r, c in np.argwhere(np.tril(adj, k=-1)):
        raw[raw == raw[r]] = c
    return np.unique(raw, return_inverse=True)[1].reshape(-1)


def _pad_labels(labels: list[np.ndarray], n: int) -> Tensor:
    """Stack per-window labels (n_b,), padding window b with G_b, G_b+1, ...."""
    out = np.zeros((len(labels), n), dtype=np.int64)
    for i, lab in enumerate(labels):
        g = int(lab.max()) + 1 if len(lab) else 0
        out[i, : len(lab)] = lab
        out[i, len(lab) :] = g + np.arange(n - len(lab))
    return torch.from_numpy(out)


def average_linkage(dist: Tensor, threshold: Tensor | float, node_mask: Tensor) -> Tensor:
    """Average-linkage (UPGMA) clusters of ``dist`` (B, N, N) cut at ``threshold``; labels (B, N) by first member.

    Starting from singletons, the two clusters with the smallest mean pairwise distance (over all their
    cross pairs, of the symmetrised D) merge while that mean is <= ``threshold``; average linkage is monotone,
    so this is scipy's ``fcluster(linkage(D, 'average'), t=threshold, criterion='distance')``. Unlike
    connected components a cluster never grows through one close neighbour of a far member. Padded
    pedestrians are never merged. All windows merge in lock-step (numpy, float64, Lance-Williams updates;
    ties go to the lowest (i, j)): at most N - 1 vectorised steps of O(B N^2).
    """
    d = dist.detach().double().cpu().numpy()
    d = (d + d.transpose(0, 2, 1)) / 2
    b, n, _ = d.shape
    real = node_mask.detach().cpu().numpy()
    d = np.where(real[:, :, None] & real[:, None, :] & ~np.eye(n, dtype=bool), d, np.inf)
    d[np.isnan(d)] = np.inf
    size = np.ones((b, n))
    lab = np.broadcast_to(np.arange(n), (b, n)).copy()  # each node's cluster representative (its first member)
    live = np.arange(b)
    thr = float(threshold.detach()) if isinstance(threshold, Tensor) else float(threshold)
    while len(live):
        flat = d[live].reshape(len(live), -1).argmin(axis=1)
        lo, hi = np.divmod(flat, n)  # lo < hi: the first minimum of a symmetric matrix lies above the diagonal
        ok = d[live, lo, hi] <= thr
        live, lo, hi = live[ok], lo[ok], hi[ok]
        if not len(live):
            break
        s_lo, s_hi = size[live, lo][:, None], size[live, hi][:, None]
        merged = (s_lo * d[live, lo] + s_hi * d[live, hi]) / (s_lo + s_hi)  # mean distance to every cluster
        d[live, lo, :] = merged
        d[live, :, lo] = merged
        d[live, hi, :] = np.inf
        d[live, :, hi] = np.inf
        d[live, lo, lo] = np.inf
        size[live, lo] += size[live, hi]
        lab[live] = np.where(lab[live] == hi[:, None], lo[:, None], lab[live])
    is_root = lab == np.arange(n)
    rank = np.cumsum(is_root, axis=1) - 1
    return torch.from_numpy(np.take_along_axis(rank, lab, axis=1)).to(dist.device)


def threshold_groups(dist: Tensor, pi: Tensor, node_mask: Tensor, mode: str = "exact") -> Tensor:
    """Group labels (B, N) at threshold ``pi``; ``mode`` one of ``THRESHOLD_MODES``: 'exact' (components of the
    pairs with D <= pi), 'official' (the reference relabelling of those pairs) or 'average' (average linkage)."""
    if mode == "average":
        return average_linkage(dist, pi, node_mask)
    adj = (dist <= pi) & pair_mask(node_mask)
    if mode == "exact":
        return connected_components(adj)
    if mode == "official":
        counts = node_mask.sum(dim=1).tolist()
        adj_np = adj.cpu().numpy()
        labels = [official_relabel(adj_np[i, :n, :n]) for i, n in enumerate(counts)]
        return _pad_labels(labels, dist.shape[1]).to(dist.device)
    raise ValueError(f"unknown grouping mode {mode!r}; valid: {THRESHOLD_MODES}")


def ratio_groups(dist: Tensor, node_mask: Tensor, ratio: int) -> Tensor:
    """Fixed-ratio grouping (ablation): merge the n - ceil(n / ratio) closest pairs of each window."""
    adj = torch.zeros_like(dist, dtype=torch.bool)
    for i, n in enumerate(node_mask.sum(dim=1).tolist()):
        k = n - (n + ratio - 1) // ratio
        if k <= 0:
            continue
        d = dist[i, :n, :n].detach()
        rows, cols = torch.tril_indices(n, n, offset=-1, device=dist.device)
        top = torch.topk(-d[rows, cols], k=k).indices
        adj[i, rows[top], cols[top]] = True
    adj = adj | adj.transpose(1, 2)
    return connected_components(adj)


def soft_assignment(dist: Tensor, pi: Tensor, tau: float, node_mask: Tensor) -> Tensor:
    """A (B, N, N): column-normalised sigmoid(-(D - pi) / tau), zero on padded pairs."""
    sig = torch.sigmoid(-(dist - pi) / tau) * pair_mask(node_mask)
    return sig / sig.sum(dim=1, keepdim=True).clamp_min(1e-12)


def straight_through(x: Tensor, assign: Tensor) -> Tensor:
    """X' = stopgrad(X - X A) + X A for node features ``x`` (B, T, N, C): value X, gradient via X A."""
    xa = torch.einsum("btic,bij->btjc", x, assign)
    return (x - xa).detach() + xa


def group_count(labels: Tensor, node_mask: Tensor) -> Tensor:
    """Number of groups (B,) among real pedestrians."""
    return torch.where(node_mask, labels + 1, torch.zeros_like(labels)).amax(dim=1)


def pool(x: Tensor, labels: Tensor, node_mask: Tensor) -> tuple[Tensor, Tensor]:
    """Mean-pool members into group nodes.

    Args:
        x: (B, T, N, C) node features.
        labels: (B, N) group labels.
        node_mask: (B, N) real pedestrians.
    Returns:
        (B, T, G, C) group features with G = max groups per window, and the (B, G) group-node mask.
    """
    b, t, n, c = x.shape
    counts = group_count(labels, node_mask)
    g = int(counts.max().item())
    idx = labels.clamp_max(g - 1)
    keep = node_mask.to(x.dtype)
    sums = torch.zeros(b, t, g, c, dtype=x.dtype, device=x.device)
    index = idx[:, None, :, None].expand(b, t, n, c)
    sums = sums.scatter_add(2, index, x * keep[:, None, :, None])
    num = torch.zeros(b, g, dtype=x.dtype, device=x.device).scatter_add(1, idx, keep)
    gmask = torch.arange(g, device=x.device)[None, :] < counts[:, None]
    return sums / num.clamp_min(1.0)[:, None, :, None], gmask


def unpool(y: Tensor, labels: Tensor) -> Tensor:
    """Copy group outputs ``y`` (B, T, G, C) back to every member: (B, T, N, C)."""
    b, t, g, c = y.shape
    idx = labels.clamp_max(g - 1)
    return torch.gather(y, 2, idx[:, None, :, None].expand(b, t, idx.shape[1], c))


def same_group_mask(labels: Tensor, node_mask: Tensor) -> Tensor:
    """(B, N, N) bool: same group, both real (diagonal included for real pedestrians)."""
    return (labels[:, :, None] == labels[:, None, :]) & pair_mask(node_mask)
