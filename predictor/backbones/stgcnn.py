"""Social-STGCNN backbone (Mohamed et al., CVPR 2020), batched over padded windows.

Input features (B, 8, N, 2) are per-step displacements (m/step). The graph at each observed step uses
the inverse distance between displacements as edge weight, self loops, symmetric normalisation and the
Laplacian form I - D^-1/2 A D^-1/2, as the reference implementations do. One spatio-temporal graph
convolution (graph conv + temporal conv, residual) is followed by a time-extrapolator CNN that maps the
8 observed steps to 12 future steps; like the original, its 3x3 kernels also span neighbouring
pedestrian indices (padded nodes are zeroed after every layer so padding stays exact).
Output (B, 12, N, 5) raw bivariate Gaussian parameters.

The adjacency carries no gradient (Social-STGCNN precomputes it; the GP-Graph authors' STGCNN wrapper
detaches it), so the group assignment learns through the branch features only.

Deviations from the original: batch normalisation is left out (padded nodes would bias its statistics)
and the features are permuted, not reshaped, between the two stages.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from predictor.backbones.base import Backbone
from predictor.grouping import pair_mask


def laplacian_adjacency(rel: Tensor, node_mask: Tensor, edge_mask: Tensor | None) -> Tensor:
    """(B, T, N, N) normalised graph I - D^-1/2 (A + I) D^-1/2 from displacements ``rel`` (B, T, N, 2)."""
    n = rel.shape[2]
    dist = torch.cdist(rel, rel, compute_mode="donot_use_mm_for_euclid_dist")
    keep = pair_mask(node_mask) if edge_mask is None else pair_mask(node_mask) & edge_mask
    keep = keep[:, None] & (dist > 0)
    eye = torch.eye(n, dtype=rel.dtype, device=rel.device)
    a_hat = torch.where(keep, dist.clamp_min(1e-12).reciprocal(), torch.zeros_like(dist)) + eye
    d = a_hat.sum(dim=-1).rsqrt()
    return eye - d[..., :, None] * a_hat * d[..., None, :]  # rows/columns of padded nodes are zero


class STGCNN(Backbone):
    """Social-STGCNN: 1 ST-GCN layer (2 -> 5 channels) and a 5-layer time-extrapolator CNN."""

    in_features = 2
    pair_budget = 65536

    def __init__(self, obs_len: int = 8, pred_len: int = 12, channels: int = 5, n_txp: int = 5) -> None:
        super().__init__()
        self.gcn_conv = nn.Conv2d(2, channels, 1)
        self.tcn_act = nn.PReLU()
        self.tcn_conv = nn.Conv2d(channels, channels, (3, 1), padding=(1, 0))
        self.residual = nn.Conv2d(2, channels, 1)
        self.st_act = nn.PReLU()
        self.txp_convs = nn.ModuleList(
            nn.Conv2d(obs_len if k == 0 else pred_len, pred_len, 3, padding=1) for k in range(n_txp)
        )
        self.txp_acts = nn.ModuleList(nn.PReLU() for _ in range(n_txp))
        self.output = nn.Conv2d(pred_len, pred_len, 3, padding=1)

    def features(self, rel: Tensor) -> Tensor:
        return rel

    def forward(self, x: Tensor, node_mask: Tensor, edge_mask: Tensor | None = None) -> Tensor:
        with torch.no_grad():  # a fixed function of the input, as in the authors' GP-Graph-STGCNN code
            adj = laplacian_adjacency(x, node_mask, edge_mask)  # (B, T, N, N)
        v = x.permute(0, 3, 1, 2)  # (B, 2, T, N)
        g = torch.einsum("bctv,btvw->bctw", self.gcn_conv(v), adj)
        keep = node_mask[:, None, None, :].to(x.dtype)  # zero padded nodes after every layer: the
        h = self.st_act(self.tcn_conv(self.tcn_act(g)) + self.residual(v)) * keep  # 3x3 convs span nodes
        f = h.transpose(1, 2)  # (B, T, C, N): time as channels
        f = self.txp_acts[0](self.txp_convs[0](f)) * keep
        for conv, act in zip(self.txp_convs[1:], self.txp_acts[1:], strict=True):
            f = (act(conv(f)) + f) * keep
        out = self.output(f)  # (B, 12, 5, N)
        return out.transpose(2, 3) * node_mask[:, None, :, None].to(x.dtype)
