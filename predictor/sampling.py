"""Latent draws and trajectory samples from the per-step bivariate Gaussians.

A latent z (K, T, N, 2) maps to a displacement mu + L z with L the Cholesky factor of the step's
covariance; positions are the cumulative sum from the last observed position. How z is drawn:
  - ``kind``: 'normal' (N(0, I)) or 'kmeans' (the K centroids of 1000 standard normal 2-D draws, scaled
    by 0.8, as the GP-Graph authors' test script does; drawn from a pool of precomputed centroid sets);
  - ``level``: shared by a 'group', the whole 'scene', or drawn per 'pedestrian';
  - ``per_step``: a fresh draw per future step, or one held constant over the 12 steps.

The 'paper' protocol gives every predicted group its own centroid set. (The authors' script indexes the
per-group draws twice by the group labels, so two groups can end up with the same set; members of one
group share theirs either way. We keep the stated scheme, which reproduces their published ADE/FDE.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PROTOCOLS = ("iid", "paper")
KMEANS_SCALE = 0.8
KMEANS_POINTS = 1000


@dataclass(frozen=True)
class LatentSpec:
    """How latents are drawn (see the module docstring)."""

    kind: str = "normal"
    level: str = "group"
    per_step: bool = True

    def __post_init__(self) -> None:
        if self.kind not in ("normal", "kmeans"):
            raise ValueError(f"kind must be 'normal' or 'kmeans', got {self.kind!r}")
        if self.level not in ("group", "scene", "pedestrian"):
            raise ValueError(f"level must be 'group', 'scene' or 'pedestrian', got {self.level!r}")


def protocol_spec(protocol: str) -> LatentSpec:
    """'iid': fresh N(0, I) per pedestrian and step. 'paper': KMeans centroids, constant, per group."""
    if protocol == "iid":
        return LatentSpec("normal", "pedestrian", True)
    if protocol == "paper":
        return LatentSpec("kmeans", "group", False)
    raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")


def kmeans_centroids(points: np.ndarray, k: int, rng: np.random.Generator, iters: int = 100) -> np.ndarray:
    """Lloyd's k-means with k-means++ seeding; returns (k, D) centroids of ``points`` (P, D)."""
    centres = [points[rng.integers(len(points))]]
    d2 = ((points - centres[0]) ** 2).sum(-1)
    for _ in range(1, k):
        centres.append(points[rng.choice(len(points), p=d2 / d2.sum())])
        d2 = np.minimum(d2, ((points - centres[-1]) ** 2).sum(-1))
    c = np.array(centres)
    sq = (points**2).sum(-1)
    for _ in range(iters):
        assign = (sq[:, None] - 2.0 * points @ c.T + (c**2).sum(-1)[None]).argmin(1)
        count = np.bincount(assign, minlength=k)
        sums = np.stack([np.bincount(assign, points[:, d], minlength=k) for d in range(points.shape[1])], -1)
        new = np.where(count[:, None] > 0, sums / np.maximum(count, 1)[:, None], c)
        if np.allclose(new, c):
            break
        c = new
    return c


def kmeans_pool(k: int, size: int, rng: np.random.Generator) -> np.ndarray:
    """(size, k, 2) sets of scaled KMeans centroids of 1000 standard normal draws."""
    return np.stack(
        [kmeans_centroids(rng.standard_normal((KMEANS_POINTS, 2)), k, rng) * KMEANS_SCALE for _ in range(size)]
    )


def _units(level: str, groups: np.ndarray) -> np.ndarray:
    """Index (N,) of the latent unit each pedestrian uses."""
    if level == "scene":
        return np.zeros(len(groups), dtype=np.int64)
    if level == "pedestrian":
        return np.arange(len(groups))
    return np.unique(groups, return_inverse=True)[1].reshape(-1)


def draw_latents(
    spec: LatentSpec,
    k: int,
    t: int,
    groups: np.ndarray,
    rng: np.random.Generator,
    pool: np.ndarray | None = None,
) -> np.ndarray:
    """Latents (K, T, N, 2) for one window with group labels ``groups`` (N,).

    For ``kind='kmeans'`` a ``pool`` from ``kmeans_pool(k, ...)`` is required; each unit takes one set.
    """
    unit = _units(spec.level, groups)
    n_units = int(unit.max()) + 1
    steps = t if spec.per_step else 1
    if spec.kind == "normal":
        z = rng.standard_normal((k, steps, n_units, 2))
    else:
        if pool is None or pool.shape[1] != k:
            raise ValueError(f"kind='kmeans' needs a pool of {k}-centroid sets")
        sets = pool[rng.integers(len(pool), size=(steps, n_units))]  # (steps, units, K, 2)
        z = np.transpose(sets, (2, 0, 1, 3))
    z = np.take(z, unit, axis=2)  # a new array
    return z if z.shape[1] == t else np.broadcast_to(z, (k, t, len(groups), 2)).copy()


def cholesky_2x2(cov: np.ndarray) -> np.ndarray:
    """Lower Cholesky factors (..., 2, 2) of 2x2 covariances (..., 2, 2)."""
    a = np.sqrt(np.maximum(cov[..., 0, 0], 0.0))
    b = cov[..., 1, 0] / np.where(a > 0, a, 1.0)
    c = np.sqrt(np.maximum(cov[..., 1, 1] - b * b, 0.0))
    out = np.zeros(cov.shape)
    out[..., 0, 0], out[..., 1, 0], out[..., 1, 1] = a, b, c
    return out


def sample_positions(mu: np.ndarray, chol: np.ndarray, z: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Absolute samples (K, T, N, 2) from step means ``mu`` (T, N, 2), factors (T, N, 2, 2), latents, last (N, 2)."""
    steps = z[..., :1] * chol[..., 0]  # (K, T, N, 2): z_0 * L[:, 0]
    steps += mu  # in this order: mu + L_00 z_0 + L_01 z_1, as written out per coordinate
    steps += z[..., 1:] * chol[..., 1]
    np.cumsum(steps, axis=1, out=steps)
    steps += last
    return steps
