"""GP-Graph (Bae, Park, Jeon, ECCV 2022): learned pedestrian groups around a weight-shared backbone.

Three branches run one backbone: the pedestrian graph, the inter-group graph (members mean-pooled into
one node per group, outputs copied back) and the intra-group graph (interactions masked to the same
group). An integration module mixes the branch outputs into one bivariate Gaussian per pedestrian and
future step.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from functools import partial
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor, nn

from predictor import grouping
from predictor.backbones import Backbone, check_backbone, make_backbone
from predictor.group_rules import apply_rule, get_rule
from predictor.pair_assigner import PairwiseAssigner

INTEGRATIONS = ("mlp", "mean")
ASSIGNERS = ("conv", "pairwise")  # GPGraphConfig.assigner: GP-Graph's F_phi, or predictor.pair_assigner
Tuple3 = tuple[Tensor, Tensor, "Tensor | None"]
SAMPLE_LEVELS = ("group", "scene", "pedestrian")


@dataclass(frozen=True)
class GPGraphConfig:
    """GP-Graph model settings; the defaults are the published GP-Graph-SGCN.

    Attributes:
        backbone: registry name ('sgcn' or 'stgcnn').
        grouping: 'exact' (connected components), 'official' (the reference code's relabelling) or
            'ratio' (fixed-ratio grouping ablation).
        group_ratio: pedestrians per group for 'ratio' grouping (>= 2).
        threshold_init: initial learnable distance threshold pi, embedding units.
        tau: temperature of the soft assignment sigmoid, embedding units.
        embed_channels: channels of the group embedding F_phi.
        assigner: how the pair distance D is learned: 'conv' (GP-Graph's F_phi, a linear convolution of each
            pedestrian's positions) or 'pairwise' (an MLP on rotation-invariant features of each pair's relative
            motion, ``predictor.pair_assigner``).
        pedestrian_branch, inter_branch, intra_branch: which branches run.
        weight_share: one backbone for all branches (False: one per branch).
        integration: 'mlp' (mean + residual PReLU/linear over the concatenation) or 'mean'.
        bce_weight: weight of the GP-Graph+S pairwise BCE loss (0 disables it).
        sample_level: default latent sharing at prediction: 'group', 'scene' or 'pedestrian'.
    """

    backbone: str = "sgcn"
    grouping: str = "exact"
    group_ratio: int = 2
    threshold_init: float = 1.0
    tau: float = 0.1
    embed_channels: int = 8
    assigner: str = "conv"
    pedestrian_branch: bool = True
    inter_branch: bool = True
    intra_branch: bool = True
    weight_share: bool = True
    integration: str = "mlp"
    bce_weight: float = 0.0
    sample_level: str = "group"

    def __post_init__(self) -> None:
        check_backbone(self.backbone)
        if self.grouping not in grouping.GROUPING_MODES:
            raise ValueError(f"grouping must be one of {grouping.GROUPING_MODES}, got {self.grouping!r}")
        if self.assigner not in ASSIGNERS:
            raise ValueError(f"assigner must be one of {ASSIGNERS}, got {self.assigner!r}")
        if self.integration not in INTEGRATIONS:
            raise ValueError(f"integration must be one of {INTEGRATIONS}, got {self.integration!r}")
        if self.sample_level not in SAMPLE_LEVELS:
            raise ValueError(f"sample_level must be one of {SAMPLE_LEVELS}, got {self.sample_level!r}")
        if not (self.pedestrian_branch or self.inter_branch or self.intra_branch):
            raise ValueError("at least one branch must be on")
        if self.tau <= 0 or self.group_ratio < 2 or self.embed_channels < 1 or self.bce_weight < 0:
            raise ValueError("need tau > 0, group_ratio >= 2, embed_channels >= 1 and bce_weight >= 0")

    @property
    def branches(self) -> tuple[bool, bool, bool]:
        return (self.pedestrian_branch, self.inter_branch, self.intra_branch)

    @property
    def uses_groups(self) -> bool:
        return self.inter_branch or self.intra_branch

    @classmethod
    def backbone_only(cls, backbone: str) -> GPGraphConfig:
        """The backbone alone: pedestrian branch only, no integration weights."""
        return cls(backbone=backbone, inter_branch=False, intra_branch=False, integration="mean")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> GPGraphConfig:
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown GPGraphConfig fields {sorted(unknown)}")
        return cls(**d)


class Output(NamedTuple):
    """Model output for B padded windows.

    raw: (B, 12, N, 5) Gaussian parameters of each per-step displacement.
    groups: (B, N) group labels. dist: (B, N, N) learned pair distance D. pi: threshold (scalar tensor).
    """

    raw: Tensor
    groups: Tensor
    dist: Tensor
    pi: Tensor


def check_group_threshold_scale(value: object) -> float:
    """``value`` as a float if it is a finite number > 0 (a valid ``group_threshold_scale``); ValueError otherwise."""
    try:
        scale = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"group_threshold_scale must be a finite number > 0, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(scale) or scale <= 0:
        raise ValueError(f"group_threshold_scale must be a finite number > 0, got {value!r}")
    return scale


def check_group_mode(value: object) -> str | None:
    """``value`` if it is None (the config's grouping) or one of ``grouping.THRESHOLD_MODES``; ValueError otherwise."""
    if value is None or (isinstance(value, str) and value in grouping.THRESHOLD_MODES):
        return value
    raise ValueError(f"group_mode must be one of {', '.join(grouping.THRESHOLD_MODES)} (or None), got {value!r}")


class GroupAssigner(nn.Module):
    """F_phi (Conv2d 2 -> C, kernel (3, 1) over time) and the learnable threshold pi."""

    def __init__(self, channels: int = 8, threshold_init: float = 1.0) -> None:
        super().__init__()
        self.embed = nn.Conv2d(2, channels, (3, 1), padding=(1, 0))
        self.threshold = nn.Parameter(torch.tensor([threshold_init]))

    def forward(self, obs_abs: Tensor) -> Tensor:
        """Pair distance D (B, N, N) from absolute observed positions (B, T, N, 2), m."""
        return grouping.pairwise_distance(self.embed(obs_abs.permute(0, 3, 1, 2)))


class Integrator(nn.Module):
    """Mean of the branch outputs plus a residual PReLU -> linear over their concatenation."""

    def __init__(self, n_branches: int, pred_len: int = 12, out_dims: int = 5) -> None:
        super().__init__()
        self.act = nn.PReLU()
        self.linear = nn.Linear(n_branches * out_dims * pred_len, out_dims * pred_len)

    def forward(self, outs: list[Tensor]) -> Tensor:
        """outs: branch outputs (B, 12, N, 5) in the order pedestrian, inter, intra -> (B, 12, N, 5)."""
        mean = torch.stack(outs).mean(dim=0)
        b, t, n, c = mean.shape
        cat = torch.cat([o.permute(0, 3, 1, 2) for o in outs], dim=1)  # (B, branches*5, 12, N)
        mix = self.linear(self.act(cat.reshape(b, -1, n).transpose(1, 2)))  # (B, N, 60)
        return mean + mix.reshape(b, n, c, t).permute(0, 3, 1, 2)


class GPGraph(nn.Module):
    """GP-Graph around a registered backbone. ``forward`` takes padded batches; see ``Output``.

    ``group_threshold_scale`` (default 1.0, finite and > 0) is an inference-time calibration of the hard group
    assignment: pedestrians i, j are linked when D_ij <= pi * group_threshold_scale, so with 'exact' grouping
    (connected components of the links) a scale below 1 only ever splits groups (the partition refines) and
    one above 1 only merges them ('official' relabelling is order-dependent and need not refine). It is not a
    parameter and not part of ``config``: the learned pi, the soft assignment (which only shapes gradients)
    and the training losses are unchanged, and 1.0 is exactly the uncalibrated model. Checkpoints may carry a
    calibrated value in their meta (``predictor.checkpoint.load_model``). It has no effect with 'ratio'
    grouping or without the group branches.

    ``group_mode`` (default None: ``config.grouping``, exactly as trained) overrides how the hard assignment
    turns D and pi * group_threshold_scale into groups, one of ``grouping.THRESHOLD_MODES``; 'average'
    (average-linkage clustering of D cut at the threshold, which does not chain people through intermediate
    neighbours) exists only as this override. Like the scale it is an inference-time setting outside
    ``config`` (training builds its model with the default None), and checkpoints may carry it in their meta.

    ``group_rule`` (default None: the learned assignment) replaces the hard assignment at inference by a
    registered rule of ``predictor.group_rules`` on the observed positions (e.g. "coherent-motion"); the scale
    and the mode then do not apply. Without the group branches it has no effect.
    """

    def __init__(self, config: GPGraphConfig | None = None, group_threshold_scale: float = 1.0,
                 group_mode: str | None = None, group_rule: str | None = None) -> None:
        super().__init__()
        self.config = config or GPGraphConfig()
        self.group_threshold_scale = group_threshold_scale
        self.group_mode = group_mode
        self.group_rule = group_rule
        n_branches = sum(self.config.branches)
        n_backbones = 1 if self.config.weight_share else n_branches
        self.backbones = nn.ModuleList(make_backbone(self.config.backbone) for _ in range(n_backbones))
        self.assigner = GroupAssigner(self.config.embed_channels, self.config.threshold_init) \
            if self.config.assigner == "conv" else PairwiseAssigner(threshold_init=self.config.threshold_init)
        self.integrator = Integrator(n_branches) if self.config.integration == "mlp" else None

    @property
    def group_threshold_scale(self) -> float:
        """Multiplier of the learned threshold pi in the hard group assignment (validated on assignment)."""
        return self._group_threshold_scale

    @group_threshold_scale.setter
    def group_threshold_scale(self, value: float) -> None:
        self._group_threshold_scale = check_group_threshold_scale(value)

    @property
    def group_mode(self) -> str | None:
        """Inference override of ``config.grouping`` (None: the config's; validated on assignment)."""
        return self._group_mode

    @group_mode.setter
    def group_mode(self, value: str | None) -> None:
        self._group_mode = check_group_mode(value)

    @property
    def group_rule(self) -> str | None:
        """Inference override of the hard assignment by a rule (``predictor.group_rules.GROUP_RULES``), or None."""
        return self._group_rule

    @group_rule.setter
    def group_rule(self, value: str | None) -> None:
        if value is not None:
            get_rule(value)  # an unknown name raises, listing the valid ones
        self._group_rule = value

    @property
    def effective_group_mode(self) -> str:
        """The grouping the hard assignment uses: ``group_mode``, else ``config.grouping``."""
        return self.config.grouping if self._group_mode is None else self._group_mode

    def assign(self, obs_abs: Tensor, node_mask: Tensor, rule_obs: np.ndarray | None = None) -> tuple[Tensor, Tensor]:
        """Pair distances D (B, N, N) and group labels (B, N) (``group_rule``, else ``effective_group_mode`` at
        pi * scale). ``rule_obs`` (B, H, N, 2) m: what the group rule reads instead of ``obs_abs`` (a longer
        track, NaN before a pedestrian was first seen); only with a ``group_rule``."""
        if rule_obs is not None and (self._group_rule is None or not self.config.uses_groups):
            raise ValueError("rule_obs is read by a group rule only; this model has none (group_rule=None)")
        dist = self.assigner(obs_abs)
        pi = self.assigner.threshold
        mode = self.effective_group_mode
        with torch.no_grad():
            if not self.config.uses_groups:  # backbone alone: every pedestrian is its own group
                labels = torch.arange(dist.shape[1], device=dist.device).expand(dist.shape[0], -1).clone()
            elif self._group_rule is not None:
                rule = get_rule(self._group_rule)
                seen = obs_abs.detach().double().cpu().numpy() if rule_obs is None else rule_obs
                labels = torch.from_numpy(apply_rule(rule, seen, node_mask.detach().cpu().numpy())).to(dist.device)
            elif mode == "ratio":
                labels = grouping.ratio_groups(dist, node_mask, self.config.group_ratio)
            else:
                pi_eff = pi * self.group_threshold_scale  # exact for 1.0: the uncalibrated model
                labels = grouping.threshold_groups(dist, pi_eff, node_mask, mode)
        return dist, labels

    def _branches(self, x: Tensor, xg: Tensor, labels: Tensor, node_mask: Tensor) -> list[Tuple3]:
        """(features, node mask, edge mask or None) per active branch: pedestrian, inter, intra."""
        cfg = self.config
        items: list[Tuple3] = []
        if cfg.pedestrian_branch:
            items.append((x, node_mask, None))
        if cfg.inter_branch:
            pooled, gmask = grouping.pool(xg, labels, node_mask)
            items.append((pooled, gmask, None))
        if cfg.intra_branch:
            items.append((xg, node_mask, grouping.same_group_mask(labels, node_mask)))
        return items

    def _run_stacked(self, items: list[Tuple3]) -> list[Tensor]:
        """One backbone call over all branches stacked along the batch (exact: padding is masked).

        Without gradients the intra-group branch's features equal the pedestrian branch's (the
        straight-through estimator only changes gradients), so the two share one batch slice and the
        backbone's edge-independent work (``Backbone.forward_variants``).
        """
        n = max(f.shape[2] for f, _, _ in items)
        share = not torch.is_grad_enabled() and self.config.pedestrian_branch and self.config.intra_branch
        feats: list[Tensor] = []
        masks: list[Tensor] = []
        variants = []
        for k, (f, m, e) in enumerate(items):
            if share and k == len(items) - 1:  # intra: reuse the pedestrian slice (items[0])
                variants.append((variants[0][0], e))
                continue
            pad = n - f.shape[2]
            b0 = sum(x.shape[0] for x in feats)
            feats.append(nn.functional.pad(f, (0, 0, 0, pad)))
            masks.append(nn.functional.pad(m, (0, pad)))
            edge = None if e is None else nn.functional.pad(e, (0, pad, 0, pad))
            variants.append((slice(b0, b0 + f.shape[0]), edge))
        backbone = self.backbones[0]
        run = backbone.forward_variants if share else partial(Backbone.forward_variants, backbone)
        outs = run(torch.cat(feats), torch.cat(masks), variants)
        return [o[:, :, : f.shape[2]] for o, (f, _, _) in zip(outs, items, strict=True)]

    def forward(self, obs_abs: Tensor, obs_rel: Tensor, node_mask: Tensor,
                rule_obs: np.ndarray | None = None) -> Output:
        """obs_abs, obs_rel: (B, 8, N, 2) positions (m) and displacements (m/step); node_mask (B, N); rule_obs: see
        ``assign``."""
        cfg = self.config
        x = self.backbones[0].features(obs_rel)
        dist, labels = self.assign(obs_abs, node_mask, rule_obs)
        pi = self.assigner.threshold
        xg = grouping.straight_through(x, grouping.soft_assignment(dist, pi, cfg.tau, node_mask))
        items = self._branches(x, xg, labels, node_mask)
        if cfg.weight_share:
            outs = self._run_stacked(items)
        else:
            outs = [bb(f, m, e) for bb, (f, m, e) in zip(self.backbones, items, strict=True)]
        if cfg.inter_branch:
            k = int(cfg.pedestrian_branch)
            outs[k] = grouping.unpool(outs[k], labels)
        raw = self.integrator(outs) if self.integrator is not None else torch.stack(outs).mean(dim=0)
        return Output(raw, labels, dist, pi)
