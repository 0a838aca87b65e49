"""The small interface every backbone implements.

A backbone maps node features (B, T_obs, N, C) of B padded windows, a node mask (B, N) and an optional
edge mask (B, N, N) to raw bivariate Gaussian parameters (B, T_pred, N, 5) of each future per-step
displacement: (mu_x, mu_y, log sigma_x, log sigma_y, rho before tanh), metres per step.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from predictor.grouping import pair_mask

Variant = tuple[slice, "Tensor | None"]


def displacement_features(rel: Tensor, with_time: bool) -> Tensor:
    """Node features from displacements ``rel`` (B, T, N, 2), m/step; optionally prepend t = 1..T."""
    if not with_time:
        return rel
    b, t, n, _ = rel.shape
    time = torch.arange(1, t + 1, dtype=rel.dtype, device=rel.device)
    return torch.cat([time[None, :, None, None].expand(b, t, n, 1), rel], dim=-1)


class Backbone(nn.Module):
    """Base class: set ``in_features``, implement ``features`` and ``forward``."""

    in_features: int = 2
    pair_budget: int = 16384  # default training micro-batch size, padded pair slots B * N_max^2

    def features(self, rel: Tensor) -> Tensor:
        """Node features (B, T, N, in_features) from observed displacements ``rel`` (B, T, N, 2)."""
        raise NotImplementedError

    def forward(self, x: Tensor, node_mask: Tensor, edge_mask: Tensor | None = None) -> Tensor:
        """x (B, T, N, C), node_mask (B, N) bool, edge_mask (B, N, N) bool or None -> (B, 12, N, 5)."""
        raise NotImplementedError

    def forward_variants(self, x: Tensor, node_mask: Tensor, variants: list[Variant]) -> list[Tensor]:
        """Outputs for several views of one batch: each variant is (batch slice, edge mask or None).

        x (B, T, N, C), node_mask (B, N); an edge mask is (b, N, N) for the b windows of its slice. Returns
        one (b, 12, N, 5) output per variant. This default stacks the views and runs ``forward`` once; a
        backbone whose edge-independent work is costly overrides it to do that work once per window.
        """
        feats = torch.cat([x[sl] for sl, _ in variants])
        masks = torch.cat([node_mask[sl] for sl, _ in variants])
        edges = torch.cat([pair_mask(node_mask[sl]) if e is None else e for sl, e in variants])
        out = self(feats, masks, edges)
        return list(out.split([x[sl].shape[0] for sl, _ in variants]))

    @staticmethod
    def reference_renames() -> list[tuple[str, str]]:
        """Regex renames from a published checkpoint's names; empty when there is none."""
        return []
