"""A pairwise group assigner: the learned pair distance D from rotation-invariant features of each pair's motion.

GP-Graph's F_phi (``model.GroupAssigner``) embeds each pedestrian's absolute positions with one linear
convolution over time, so D_ij is a fixed norm of the pair's relative displacement over 3-step windows, measured
in the scene's axes: it cannot tell a pair walking abreast from one walking in file unless the scene happens to
be aligned, and it sees a stranger keeping pace beside a group (crowdsim's `stranger_follow_gain_per_s`) as it
sees a member. This assigner (``GPGraphConfig.assigner = "pairwise"``) scores every pair instead from
features that depend only on the pair's relative motion, not on the scene's position or rotation:

per observed step t (velocities from consecutive positions, the first step taking the second's):
    distance |p_i - p_j| (m); relative speed |v_i - v_j| (m/s); mean speed (|v_i| + |v_j|) / 2 and speed
    difference ||v_i| - |v_j|| (m/s); heading agreement cos(v_i, v_j) (0 when either stands); and the pair's
    offset along and across their mean velocity |(p_i - p_j) . u|, |(p_i - p_j) x u| (m; both = distance / sqrt 2
    when the mean velocity vanishes, so standing pairs are scored by distance alone);

and D_ij = softplus(MLP([mean over t, std over t, last step] of these 7 features)). Every feature is symmetric in
i and j, so D is symmetric; its diagonal is 0. The learnable threshold ``threshold`` (pi) plays the role it has
in GP-Graph (D_ij <= pi links a pair), and the GP-Graph+S BCE loss trains D and pi as before.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

N_FEATURES = 7
EPS = 1e-6
STANDING_MPS = 0.05  # below this a speed counts as standing (heading undefined), m/s


def pair_features(obs_abs: Tensor) -> Tensor:
    """(B, T, N, N, 7) per-step pair features (see the module doc) from positions (B, T, N, 2), m."""
    vel = obs_abs[:, 1:] - obs_abs[:, :-1]
    vel = torch.cat([vel[:, :1], vel], dim=1) if vel.shape[1] else torch.zeros_like(obs_abs)  # (B, T, N, 2) m/step
    rel = obs_abs[:, :, :, None] - obs_abs[:, :, None, :]  # (B, T, N, N, 2)
    dvel = vel[:, :, :, None] - vel[:, :, None, :]
    dist = torch.sqrt((rel * rel).sum(-1) + EPS)
    rel_speed = torch.sqrt((dvel * dvel).sum(-1) + EPS)
    speed = torch.sqrt((vel * vel).sum(-1) + EPS)  # (B, T, N)
    s_i, s_j = speed[:, :, :, None], speed[:, :, None, :]
    moving = (s_i > STANDING_MPS) & (s_j > STANDING_MPS)
    cos = ((vel[:, :, :, None] * vel[:, :, None, :]).sum(-1) / (s_i * s_j)).where(moving, torch.zeros_like(dist))
    mean_vel = (vel[:, :, :, None] + vel[:, :, None, :]) / 2
    mean_speed = torch.sqrt((mean_vel * mean_vel).sum(-1) + EPS)
    unit = mean_vel / mean_speed[..., None]
    along = (rel * unit).sum(-1).abs()
    across = (rel[..., 0] * unit[..., 1] - rel[..., 1] * unit[..., 0]).abs()
    heading_known = mean_speed > STANDING_MPS
    along = along.where(heading_known, dist / math.sqrt(2.0))
    across = across.where(heading_known, dist / math.sqrt(2.0))
    return torch.stack([dist, rel_speed, (s_i + s_j) / 2, (s_i - s_j).abs(), cos, along, across], dim=-1)


class PairwiseAssigner(nn.Module):
    """D (B, N, N) from pair features: an MLP (21 -> hidden -> hidden -> 1) with a softplus, and the threshold pi."""

    def __init__(self, hidden: int = 32, threshold_init: float = 1.0, step_s: float = 0.4) -> None:
        super().__init__()
        self.step_s = step_s  # positions per observed step -> velocities in m/s
        self.mlp = nn.Sequential(nn.Linear(3 * N_FEATURES, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(),
                                 nn.Linear(hidden, 1))
        self.threshold = nn.Parameter(torch.tensor([threshold_init]))

    def forward(self, obs_abs: Tensor) -> Tensor:
        """Pair distance D (B, N, N), symmetric with a zero diagonal, from absolute positions (B, T, N, 2), m."""
        feats = pair_features(obs_abs)
        scale = torch.tensor([1.0, 1 / self.step_s, 1 / self.step_s, 1 / self.step_s, 1.0, 1.0, 1.0],
                             dtype=feats.dtype, device=feats.device)
        feats = feats * scale  # speeds in m/s
        summary = torch.cat([feats.mean(dim=1), feats.std(dim=1, unbiased=False), feats[:, -1]], dim=-1)
        dist = nn.functional.softplus(self.mlp(summary).squeeze(-1))  # (B, N, N)
        dist = (dist + dist.transpose(1, 2)) / 2  # exact symmetry (the features are symmetric up to rounding)
        eye = torch.eye(dist.shape[-1], dtype=torch.bool, device=dist.device)
        return dist.masked_fill(eye, 0.0)
