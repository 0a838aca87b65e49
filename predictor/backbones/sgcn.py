"""SGCN backbone (Shi et al., CVPR 2021): sparse graph attention with learned interaction masks.

Batched over B padded windows. Input features (B, 8, N, 3) are (t, dx, dy) with t = 1..8 and (dx, dy) the
per-step displacement in metres. Output (B, 12, N, 5): raw bivariate Gaussian parameters of the per-step
displacement (mu_x, mu_y, log sigma_x, log sigma_y, rho before tanh).

Padding is exact: attention keys of padded pedestrians are masked, and the asymmetric convolutions over
the N x N interaction maps see zeros outside the real block after every layer, which is what the
convolutions' own zero padding gives an unpadded window.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from predictor.backbones.base import Backbone, Variant, displacement_features
from predictor.backbones.cross_conv import CrossStack
from predictor.grouping import pair_mask


class AsymmetricConv(nn.Module):
    """PReLU(conv (3x1) + conv (1x3)) + identity, over (batch, channels, H, W)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv_h = nn.Conv2d(channels, channels, (3, 1), padding=(1, 0), bias=False)
        self.conv_w = nn.Conv2d(channels, channels, (1, 3), padding=(0, 1))
        self.act = nn.PReLU()

    def forward(self, x: Tensor) -> Tensor:
        """Training: both convolutions as one 5-tap contraction (its backward is several times faster than
        that of two tiny CPU convolutions). Inference: one 3x3 convolution with the cross-shaped sum of the
        two kernels (1.5x faster than the two convolutions; equal up to float rounding)."""
        if not torch.is_grad_enabled():
            cross = F.pad(self.conv_h.weight, (1, 1)) + F.pad(self.conv_w.weight, (0, 0, 1, 1))
            return self.act(F.conv2d(x, cross, self.conv_w.bias, padding=1)) + x
        h, w = x.shape[-2:]
        wh, ww = self.conv_h.weight[..., 0], self.conv_w.weight[:, :, 0]  # (out, in, 3)
        taps = torch.stack([wh[..., 0], wh[..., 2], ww[..., 0], ww[..., 2], wh[..., 1] + ww[..., 1]], -1)
        xp = F.pad(x, (1, 1, 1, 1))
        shifted = torch.stack(
            [xp[..., :h, 1 : w + 1], xp[..., 2:, 1 : w + 1], xp[..., 1 : h + 1, :w], xp[..., 1 : h + 1, 2:], x], 1
        )
        y = torch.einsum("oik,bkihw->bohw", taps, shifted) + self.conv_w.bias[:, None, None]
        return self.act(y) + x


class MultiHeadScores(nn.Module):
    """Scaled dot-product attention scores (..., heads, L, L) over a length-L sequence of features."""

    def __init__(self, in_dims: int, d_model: int = 64, heads: int = 4) -> None:
        super().__init__()
        self.embedding = nn.Linear(in_dims, d_model)
        self.query = nn.Linear(d_model, d_model)
        self.key = nn.Linear(d_model, d_model)
        self.heads = heads
        self.scale = math.sqrt(d_model)

    def _split(self, x: Tensor) -> Tensor:
        return x.reshape(*x.shape[:-1], self.heads, x.shape[-1] // self.heads).transpose(-3, -2)

    def forward(self, x: Tensor, key_mask: Tensor | None = None) -> Tensor:
        """x (..., L, in_dims); key_mask (..., L) bool -> softmax scores (..., heads, L, L)."""
        emb = self.embedding(x)
        scores = self._split(self.query(emb)) @ self._split(self.key(emb)).transpose(-1, -2) / self.scale
        if key_mask is not None and torch.is_grad_enabled():
            scores = scores.masked_fill(~key_mask[..., None, None, :], float("-inf"))
        elif key_mask is not None:  # the same in place, faster: add 0 or -inf
            bias = torch.zeros(key_mask.shape, dtype=scores.dtype, device=scores.device)
            scores += bias.masked_fill_(~key_mask, float("-inf"))[..., None, None, :]
        if torch.is_grad_enabled() or scores.shape[-1] >= 16:
            return torch.softmax(scores, dim=-1)
        # torch's CPU softmax is several times slower than this over rows shorter than one vector register
        e = (scores - scores.amax(dim=-1, keepdim=True)).exp_()
        return e.div_(e.sum(dim=-1, keepdim=True))


def zero_softmax(x: Tensor, eps: float = 1e-5) -> Tensor:
    """Row normalisation of (exp(x) - 1)^2 over the last axis: exact zeros stay zero."""
    if not torch.is_grad_enabled():  # the same operations in place
        e = torch.exp(x).sub_(1.0).pow_(2)
        return e.div_(e.sum(dim=-1, keepdim=True).add_(eps))
    e = torch.pow(torch.exp(x) - 1.0, 2)
    return e / (e.sum(dim=-1, keepdim=True) + eps)


class GraphConv(nn.Module):
    """PReLU(Linear(A @ X)), no bias."""

    def __init__(self, in_dims: int, out_dims: int) -> None:
        super().__init__()
        self.linear = nn.Linear(in_dims, out_dims, bias=False)
        self.act = nn.PReLU()

    def forward(self, x: Tensor, adj: Tensor) -> Tensor:
        return self.act(self.linear(adj @ x))


class SGCN(Backbone):
    """Sparse graph convolution network. Shapes in the class docstring of the module."""

    in_features = 3
    pair_budget = 4096  # its N x N interaction maps are memory bound: small micro-batches train fastest

    def __init__(
        self,
        obs_len: int = 8,
        pred_len: int = 12,
        d_model: int = 64,
        heads: int = 4,
        n_asym: int = 7,
        n_tcn: int = 5,
        mask_threshold: float = 0.5,
    ) -> None:
        super().__init__()
        hid = d_model // heads
        self.heads, self.mask_threshold = heads, mask_threshold
        self.spatial_att = MultiHeadScores(2, d_model, heads)
        self.temporal_att = MultiHeadScores(3, d_model, heads)
        self.fusion_conv = nn.Conv2d(obs_len, obs_len, 1)
        self.fusion_act = nn.PReLU()
        self.spatial_asym = nn.ModuleList(AsymmetricConv(heads) for _ in range(n_asym))
        self.temporal_asym = nn.ModuleList(AsymmetricConv(heads) for _ in range(n_asym))
        self.gcn_st = nn.ModuleList([GraphConv(2, hid), GraphConv(hid, hid)])
        self.gcn_ts = nn.ModuleList([GraphConv(2, hid), GraphConv(hid, hid)])
        self.head_fusion = nn.Conv2d(heads, heads, 1, bias=False)
        self.tcn_convs = nn.ModuleList(
            nn.Conv2d(obs_len if k == 0 else pred_len, pred_len, 3, padding=1) for k in range(n_tcn)
        )
        self.tcn_acts = nn.ModuleList(nn.PReLU() for _ in range(n_tcn))
        self.output = nn.Linear(hid, 5)
        self._spatial_stack = CrossStack(self.spatial_asym)  # the stacks' inference path
        self._temporal_stack = CrossStack(self.temporal_asym)

    def features(self, rel: Tensor) -> Tensor:
        return displacement_features(rel, with_time=True)

    def _masks(self, s: Tensor, t: Tensor, valid: Tensor) -> tuple[Tensor, Tensor]:
        """Sparse interaction masks from fused spatial scores s (B, T, H, N, N) and temporal t (B, N, H, T, T)."""
        b, tt, h, n, _ = s.shape
        v = valid[:, None, None].to(s.dtype)  # (B, 1, 1, N, N)
        if not torch.is_grad_enabled():  # both stacks as small matmuls (equal up to float rounding)
            gate = self.mask_threshold
            return (self._spatial_stack(s.movedim(2, 0), v[:, :, 0], gate),  # masks s on entry
                    self._temporal_stack(t.movedim(2, 0), None, gate))
        x = (s * v).reshape(b * tt, h, n, n)
        vf = v.expand(b, tt, 1, n, n).reshape(b * tt, 1, n, n)
        for layer in self.spatial_asym:
            x = layer(x) * vf
        y = t.reshape(-1, h, tt, tt)
        for layer in self.temporal_asym:
            y = layer(y)
        x, y = torch.sigmoid(x), torch.sigmoid(y)
        x = torch.where(x > self.mask_threshold, x, torch.zeros_like(x)).reshape(s.shape)
        y = torch.where(y > self.mask_threshold, y, torch.zeros_like(y)).reshape(t.shape)
        return x, y

    def _edge_free(self, x: Tensor, node_mask: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """The work that no edge mask changes: masked spatial scores (B, T, H, N, N), the valid-pair mask
        (B, N, N) and the normalised temporal adjacency (B, N, H, T, T)."""
        b, t, n, _ = x.shape
        valid = pair_mask(node_mask)
        att_s = self.spatial_att(x[..., 1:], node_mask[:, None, :].expand(b, t, n))
        att_s = att_s * valid[:, None, None].to(x.dtype)
        att_t = self.temporal_att(x.transpose(1, 2))
        f = att_s.transpose(1, 2).reshape(b * self.heads, t, n, n)
        fused = (self.fusion_act(self.fusion_conv(f)) + f).reshape(b, self.heads, t, n, n).transpose(1, 2)
        mask_s, mask_t = self._masks(fused, att_t, valid)
        eye_s, eye_t = (torch.eye(k, dtype=x.dtype, device=x.device) for k in (n, t))
        if not torch.is_grad_enabled():  # the same products, in place
            return mask_s.add_(eye_s).mul_(att_s), valid, zero_softmax(mask_t.add_(eye_t).mul_(att_t))
        return att_s * (mask_s + eye_s), valid, zero_softmax(att_t * (mask_t + eye_t))

    @staticmethod
    def _spatial(scores: Tensor, valid: Tensor, edge_mask: Tensor | None) -> Tensor:
        """Normalised sparse spatial adjacency (B, T, H, N, N) keeping the valid pairs of ``edge_mask``."""
        keep = valid if edge_mask is None else valid & edge_mask
        return zero_softmax(scores * keep[:, None, None].to(scores.dtype))

    def adjacency(self, x: Tensor, node_mask: Tensor, edge_mask: Tensor | None) -> tuple[Tensor, Tensor]:
        """Normalised sparse spatial (B, T, H, N, N) and temporal (B, N, H, T, T) adjacencies."""
        scores, valid, adj_t = self._edge_free(x, node_mask)
        return self._spatial(scores, valid, edge_mask), adj_t

    def _decode(self, x: Tensor, adj_s: Tensor, adj_t: Tensor) -> Tensor:
        """Sparse GCNs, head fusion and the TCN: (B, T, N, 3) features -> (B, 12, N, 5)."""
        b, t, n, _ = x.shape
        pos = x[..., 1:]  # (B, T, N, 2)
        st = self.gcn_st[0](pos[:, :, None], adj_s).permute(0, 3, 2, 1, 4)  # (B, N, H, T, d)
        st = self.gcn_st[1](st, adj_t)
        ts = self.gcn_ts[0](pos.transpose(1, 2)[:, :, None], adj_t).permute(0, 3, 2, 1, 4)  # (B, T, H, N, d)
        ts = self.gcn_ts[1](ts, adj_s).permute(0, 3, 2, 1, 4)  # (B, N, H, T, d)
        h, d = st.shape[2], st.shape[-1]
        fuse = self.head_fusion.weight[:, :, 0, 0].expand(b * n, h, h)  # the 1x1 convolution as a matmul
        rep = torch.baddbmm(ts.reshape(b * n, h, t * d), fuse, st.reshape(b * n, h, t * d))
        feat = rep.view(b * n, h, t, d).transpose(1, 2)  # (B*N, T, H, d)
        feat = self.tcn_acts[0](self.tcn_convs[0](feat))
        for conv, act in zip(self.tcn_convs[1:], self.tcn_acts[1:], strict=True):
            feat = act(conv(feat)).add_(feat)
        out = self.output(feat).mean(dim=-2)  # (B*N, 12, 5)
        return out.reshape(b, n, -1, 5).transpose(1, 2)

    def forward(self, x: Tensor, node_mask: Tensor, edge_mask: Tensor | None = None) -> Tensor:
        return self._decode(x, *self.adjacency(x, node_mask, edge_mask))

    def forward_variants(self, x: Tensor, node_mask: Tensor, variants: list[Variant]) -> list[Tensor]:
        """The attention, interaction masks and temporal adjacency once per window; then the variants'
        spatial adjacencies and one stacked decoder pass (see ``Backbone.forward_variants``)."""
        scores, valid, adj_t = self._edge_free(x, node_mask)
        keep = torch.cat([valid[sl] if e is None else valid[sl] & e for sl, e in variants])
        adj_s = self._spatial(torch.cat([scores[sl] for sl, _ in variants]), keep, None)
        cat = [torch.cat([a[sl] for sl, _ in variants]) for a in (x, adj_t)]
        out = self._decode(cat[0], adj_s, cat[1])
        return list(out.split([x[sl].shape[0] for sl, _ in variants]))

    @staticmethod
    def reference_renames() -> list[tuple[str, str]]:
        """(pattern, replacement) regexes from the authors' parameter names to this module's."""
        return [
            (r"^sparse_weighted_adjacency_matrices\.spatial_attention\.", "spatial_att."),
            (r"^sparse_weighted_adjacency_matrices\.temporal_attention\.", "temporal_att."),
            (r"^sparse_weighted_adjacency_matrices\.spa_fusion\.conv\.0\.", "fusion_conv."),
            (r"^sparse_weighted_adjacency_matrices\.spa_fusion\.conv\.1\.", "fusion_act."),
            (r"^sparse_weighted_adjacency_matrices\.interaction_mask\.spatial_asymmetric_convolutions\.",
             "spatial_asym."),
            (r"^sparse_weighted_adjacency_matrices\.interaction_mask\.temporal_asymmetric_convolutions\.",
             "temporal_asym."),
            (r"asym\.(\d+)\.conv1\.", r"asym.\1.conv_h."),
            (r"asym\.(\d+)\.conv2\.", r"asym.\1.conv_w."),
            (r"asym\.(\d+)\.activation\.", r"asym.\1.act."),
            (r"^stsgcn\.spatial_temporal_sparse_gcn\.(\d+)\.embedding\.", r"gcn_st.\1.linear."),
            (r"^stsgcn\.spatial_temporal_sparse_gcn\.(\d+)\.activation\.", r"gcn_st.\1.act."),
            (r"^stsgcn\.temporal_spatial_sparse_gcn\.(\d+)\.embedding\.", r"gcn_ts.\1.linear."),
            (r"^stsgcn\.temporal_spatial_sparse_gcn\.(\d+)\.activation\.", r"gcn_ts.\1.act."),
            (r"^fusion_\.", "head_fusion."),
            (r"^tcns\.(\d+)\.0\.", r"tcn_convs.\1."),
            (r"^tcns\.(\d+)\.1\.", r"tcn_acts.\1."),
        ]
