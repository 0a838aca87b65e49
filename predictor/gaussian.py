"""Bivariate Gaussian output head: parameters, negative log-likelihood, mean and covariance."""

from __future__ import annotations

import math

import torch
from torch import Tensor

RHO_EPS = 1e-6


def params(raw: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """(mu_x, mu_y, sigma_x, sigma_y, rho) from raw outputs (..., 5)."""
    return raw[..., 0], raw[..., 1], raw[..., 2].exp(), raw[..., 3].exp(), raw[..., 4].tanh()


def nll(raw: Tensor, target: Tensor) -> Tensor:
    """Negative log-density (...,) of displacements ``target`` (..., 2) under raw Gaussians (..., 5)."""
    mx, my, sx, sy, rho = params(raw)
    dx, dy = (target[..., 0] - mx) / sx, (target[..., 1] - my) / sy
    one_m = (1.0 - rho * rho).clamp_min(RHO_EPS)
    z = dx * dx + dy * dy - 2.0 * rho * dx * dy
    return z / (2.0 * one_m) + torch.log(sx * sy) + 0.5 * torch.log(one_m) + math.log(2.0 * math.pi)


def masked_nll(raw: Tensor, target: Tensor, node_mask: Tensor) -> Tensor:
    """Mean NLL per window (mean over steps and real pedestrians), then mean over windows.

    raw (B, 12, N, 5), target (B, 12, N, 2) m/step, node_mask (B, N) -> scalar.
    """
    per = nll(raw, target) * node_mask[:, None, :]
    per_window = per.sum(dim=(1, 2)) / (node_mask.sum(dim=1) * raw.shape[1]).clamp_min(1)
    return per_window.mean()


def mean_cov(raw: Tensor) -> tuple[Tensor, Tensor]:
    """Mean (..., 2) and covariance (..., 2, 2) of each per-step displacement."""
    mx, my, sx, sy, rho = params(raw)
    c = rho * sx * sy
    cov = torch.stack([torch.stack([sx * sx, c], -1), torch.stack([c, sy * sy], -1)], -2)
    return torch.stack([mx, my], -1), cov
