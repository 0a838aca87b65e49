"""Group assignment rules: who walks together, from the observed positions alone (numpy and scipy, no weights).

A rule maps one window's observed positions ``obs`` (T, N, 2), metres at ``step_s`` apart, to group ids (N,)
0..G-1, numbered by first member. A rule reads at most its ``track_steps`` newest rows (8: the predictor's window).
One with more (``coherent-motion-track``: 48, 19.2 s) is given each pedestrian's longer past, the ``track`` of
``GPGraphPredictor.predict``: a pedestrian seen for fewer steps has NaN rows before its first position (leading rows
only), and each pair is measured over the steps both were seen (the last two rows are finite for everyone).

Rules stand beside the learned assigners of GP-Graph: ``load_predictor`` takes ``group_rule`` (or a name
``PREDICTOR+RULE``) and then replaces the model's hard group assignment by the rule's at inference
(``GPGraph.group_rule``), so the group pooling, the intra-group graph and the group-level latent sampling all follow
the rule. They are chosen on the real UCY group annotations (validation only; see RESULTS.md, "sim-to-real", and
``gpgraph groups``), because the assigner trained on crowdsim does not transfer to real people.

Rules:

* `CoherentMotionRule` ("coherent-motion"): pair cost c_ij = mean_t |p_i - p_j| / distance_m
  + mean_t |v_i - v_j| / rel_speed_mps (velocities from consecutive positions), clustered by average linkage
  (UPGMA) cut at 1: a group's members are on average close and moving alike, and one close neighbour does not
  chain two groups together as connected components would. "coherent-motion-track": the same on 48 positions.
  Motion-aware (``stand_speed_mps`` > 0): a pair whose slower member stands (its speed, displacement over the
  pair's shared steps / their duration, below ``stand_speed_mps``) is measured against ``stand_distance_m``
  instead of ``distance_m``. Two people standing still move alike trivially (relative speed ~0), so without it
  only the distance separates standing strangers, who wait close to each other (hotel, zara02's shop front).
* `ProximityRule` ("proximity-last", "proximity-max"): connected components of the pairs closer than
  ``radius_m`` at the last observed step, or at every observed step (the distance rules of the literature).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import squareform

from predictor.names import unknown_name

LINKAGES = ("average", "complete", "single")
STEPS = ("last", "max", "mean")


class GroupRule(Protocol):
    """obs (T, N, 2) m -> group ids (N,) int64, 0..G-1 numbered by first member, from its newest ``track_steps``
    rows."""

    track_steps: int

    def __call__(self, obs: np.ndarray) -> np.ndarray: ...


def check_obs(obs: np.ndarray) -> np.ndarray:
    """obs as float64 (T >= 2, N, 2); NaN allowed only as a pedestrian's leading rows (both coordinates, before it
    was first seen) with its last two rows finite; inf never."""
    o = np.asarray(obs, dtype=np.float64)
    if o.ndim != 3 or o.shape[2] != 2 or o.shape[0] < 2:
        raise ValueError(f"obs must have shape (T >= 2, N, 2) in metres, got {o.shape}")
    if np.isinf(o).any():
        raise ValueError("obs contains inf")
    missing = np.isnan(o)
    if missing.any():
        unseen = missing.any(axis=2)  # (T, N)
        leading = np.cumprod(unseen, axis=0).astype(bool)  # True while a pedestrian has not been seen yet
        if not np.array_equal(missing, np.repeat(leading[..., None], 2, axis=2)) or unseen[-2:].any():
            raise ValueError("obs contains NaN other than a pedestrian's leading rows (before it was first seen; "
                             "its last two rows must be finite)")
    return o


def _check_track_steps(steps: object) -> None:
    if not isinstance(steps, int | np.integer) or isinstance(steps, bool) or steps < 2:
        raise ValueError(f"track_steps must be an integer >= 2, got {steps!r}")


def _check_positive(name: str, v: object) -> None:
    if not (isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {v!r}")


def _mean_over_seen(x: np.ndarray) -> np.ndarray:
    """Mean over axis 0 of the finite entries (those where both of a pair were seen); the plain mean without NaN."""
    return np.nanmean(x, axis=0) if np.isnan(x).any() else x.mean(axis=0)


def first_member_order(labels: np.ndarray) -> np.ndarray:
    """Relabel (N,) cluster ids 0..G-1 in order of each cluster's first member."""
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[inverse.reshape(-1)]


def pair_distances(obs: np.ndarray) -> np.ndarray:
    """(T, N, N) distance of every pair at every observed step, m (NaN where one of the pair is NaN). The same
    floats as ``np.linalg.norm`` of the pair differences, computed per coordinate (a few times faster)."""
    dx = obs[:, :, None, 0] - obs[:, None, :, 0]
    dy = obs[:, :, None, 1] - obs[:, None, :, 1]
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(dx, out=dx)


@dataclass(frozen=True)
class CoherentMotionRule:
    """Average-linkage clusters of c_ij = mean distance / D_ij + mean relative speed / rel_speed_mps, cut at 1, where
    D_ij = stand_distance_m if the slower of the pair stands (speed < stand_speed_mps), else distance_m.

    distance_m: the mean distance (m) at which a pair moving identically stops being a group.
    rel_speed_mps: the mean relative speed (m/s) at which a pair at zero distance stops being a group.
    linkage: how cluster costs combine ("average": UPGMA; "single": connected components of c <= 1).
    step_s: time between observed positions, s (0.4: the ETH/UCY protocol).
    track_steps: the newest rows it reads (8: the predictor's window; more: a longer track, see the module).
    stand_speed_mps: a pedestrian moving slower than this (m/s; displacement over the pair's shared steps divided
        by their duration) stands; 0 (the default): nobody does, the rule is the plain coherent-motion rule.
    stand_distance_m: the distance scale (m) of a pair in which one or both stand, <= distance_m; None: distance_m.
    """

    distance_m: float = 1.5
    rel_speed_mps: float = 1.2
    linkage: str = "average"
    step_s: float = 0.4
    track_steps: int = 8
    stand_speed_mps: float = 0.0
    stand_distance_m: float | None = None

    def __post_init__(self) -> None:
        for name in ("distance_m", "rel_speed_mps", "step_s"):
            _check_positive(name, getattr(self, name))
        if self.linkage not in LINKAGES:
            raise ValueError(f"unknown linkage {self.linkage!r}; valid: {', '.join(LINKAGES)}")
        _check_track_steps(self.track_steps)
        v = self.stand_speed_mps
        if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
            raise ValueError(f"stand_speed_mps must be a finite number >= 0, got {v!r}")
        if self.stand_distance_m is not None:
            _check_positive("stand_distance_m", self.stand_distance_m)
            if self.stand_distance_m > self.distance_m:
                raise ValueError(f"stand_distance_m ({self.stand_distance_m}) must not exceed distance_m "
                                 f"({self.distance_m}): a standing pair's test is the stricter one")

    def cost(self, obs: np.ndarray) -> np.ndarray:
        """(N, N) pair cost c_ij (dimensionless, symmetric, zero diagonal) of obs (T, N, 2) m (its newest
        ``track_steps`` rows), each pair's means over the steps both were seen."""
        o = check_obs(obs)[-self.track_steps :]
        vel = np.diff(o, axis=0) / self.step_s  # (T-1, N, 2) m/s
        rel_speed = _mean_over_seen(pair_distances(vel))  # |v_i - v_j| per step, m/s
        scale = self.distance_m
        if self.stand_speed_mps > 0 and self.stand_distance_m is not None:
            standing = slower_speed(vel) < self.stand_speed_mps  # (N, N)
            scale = np.where(standing, self.stand_distance_m, self.distance_m)
        return _mean_over_seen(pair_distances(o)) / scale + rel_speed / self.rel_speed_mps

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        c = self.cost(obs)
        n = c.shape[0]
        if n == 1:
            return np.zeros(1, dtype=np.int64)
        if self.linkage == "single":
            return first_member_order(connected_components(c <= 1.0, directed=False)[1])
        tree = linkage(squareform(c, checks=False), method=self.linkage)
        return first_member_order(fcluster(tree, t=1.0, criterion="distance"))


def slower_speed(vel: np.ndarray) -> np.ndarray:
    """(N, N) speed (m/s) of the slower of each pair: each one's mean velocity over the steps both were seen
    (its displacement over them / their duration), from vel (T-1, N, 2) m/s with NaN rows before a pedestrian was
    first seen. Symmetric; the diagonal is each pedestrian's own speed."""
    shared = ~(np.isnan(vel[:, :, None, 0]) | np.isnan(vel[:, None, :, 0]))  # (T-1, N, N) both seen
    v = np.where(shared[..., None], vel[:, :, None, :], 0.0)  # (T-1, N, N, 2) i's velocity where j was seen too
    mean_v = v.sum(axis=0) / np.maximum(shared.sum(axis=0), 1)[..., None]  # (N, N, 2)
    speed = np.hypot(mean_v[..., 0], mean_v[..., 1])  # speed[i, j]: i's speed while j was seen
    return np.minimum(speed, speed.T)


@dataclass(frozen=True)
class ProximityRule:
    """Connected components of the pairs closer than radius_m at the last observed step ("last"), at every one
    ("max": the largest distance over the window), or on average ("mean").

    radius_m: link distance, m. steps: one of ``STEPS``. track_steps: the newest rows it reads (8: the window).
    """

    radius_m: float = 1.25
    steps: str = "max"
    track_steps: int = 8

    def __post_init__(self) -> None:
        if not (isinstance(self.radius_m, int | float) and np.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"radius_m must be a finite number > 0, got {self.radius_m!r}")
        if self.steps not in STEPS:
            raise ValueError(f"unknown steps {self.steps!r}; valid: {', '.join(STEPS)}")
        _check_track_steps(self.track_steps)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        d = pair_distances(check_obs(obs)[-self.track_steps :])  # NaN where one of the pair was not yet seen
        if self.steps == "last":
            d = d[-1]
        elif self.steps == "mean":
            d = _mean_over_seen(d)
        else:
            d = np.nanmax(d, axis=0) if np.isnan(d).any() else d.max(axis=0)
        return first_member_order(connected_components(d < self.radius_m, directed=False)[1])


# The registry: each rule's settings were chosen on the UCY group annotations (validation; RESULTS.md "sim-to-real",
# scripts/group_rule_selection.py: the highest mean PW F1 over students003, zara01 and zara02 in each family).
GROUP_RULES: dict[str, GroupRule] = {
    "coherent-motion": CoherentMotionRule(),
    # the same settings on each pedestrian's last 48 positions (19.2 s), the track length chosen on the same labels
    "coherent-motion-track": CoherentMotionRule(track_steps=48),
    # opt-in (issue 50): a pair with a member slower than 0.2 m/s must stand within 0.75 m (mean), walkers as above;
    # chosen by the worst of the three recordings' PW F1. Not the default: chosen on two recordings and scored on
    # the third it loses on students003 what it gains on zara02 (RESULTS.md, "sim-to-real", standing people)
    "coherent-motion-stand": CoherentMotionRule(stand_speed_mps=0.2, stand_distance_m=0.75),
    "proximity-max": ProximityRule(radius_m=1.25, steps="max"),
    "proximity-last": ProximityRule(radius_m=1.0, steps="last"),
}


def get_rule(name: str) -> GroupRule:
    """The registered rule ``name``; an unknown name raises ValueError listing the valid ones."""
    try:
        return GROUP_RULES[name]
    except (KeyError, TypeError):
        raise ValueError(unknown_name("group rule", name, GROUP_RULES)) from None


def apply_rule(rule: GroupRule, obs: np.ndarray, node_mask: np.ndarray) -> np.ndarray:
    """Batched: labels (B, N) for obs (B, T, N, 2) m with real pedestrians ``node_mask`` (B, N) first in each
    window; padding gets G_b, G_b + 1, ... (its own groups), as ``predictor.grouping`` lays batches out."""
    b, _, n, _ = obs.shape
    out = np.zeros((b, n), dtype=np.int64)
    for i in range(b):
        k = int(node_mask[i].sum())
        lab = rule(obs[i, :, :k]) if k else np.zeros(0, dtype=np.int64)
        g = int(lab.max()) + 1 if k else 0
        out[i, :k] = lab
        out[i, k:] = g + np.arange(n - k)
    return out


RULE_SEPARATOR = "+"  # "NAME+RULE": predictor NAME grouping by rule RULE (predictor.group_rules)


def split_group_rule(spec: str | Path) -> tuple[str, str | None]:
    """("NAME", "RULE") for a spec "NAME+RULE" whose RULE is checked against ``GROUP_RULES`` (an unknown one
    raises ValueError listing the valid names); (spec, None) without a "+" or for an existing file's path."""
    text = str(spec)
    base, sep, rule = text.rpartition(RULE_SEPARATOR)
    if not sep or Path(text).exists():
        return text, None
    get_rule(rule)
    return base, rule
