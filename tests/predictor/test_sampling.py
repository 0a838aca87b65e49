"""Latent draws for the two evaluation protocols and the sampling levels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predictor.sampling import (
    LatentSpec,
    cholesky_2x2,
    draw_latents,
    kmeans_centroids,
    kmeans_pool,
    protocol_spec,
    sample_positions,
)


def test_paper_protocol_latents_are_group_shared_constant_kmeans() -> None:
    rng = np.random.default_rng(0)
    pool = kmeans_pool(20, 8, rng)
    groups = np.array([0, 1, 0, 2])
    z = draw_latents(protocol_spec("paper"), 20, 12, groups, rng, pool)
    assert z.shape == (20, 12, 4, 2)
    np.testing.assert_array_equal(z[:, 0], z[:, 11])  # constant over the horizon
    np.testing.assert_array_equal(z[:, :, 0], z[:, :, 2])  # shared by group members
    assert not np.allclose(z[:, :, 0], z[:, :, 1])
    # each pedestrian's 20 latents are one centroid set of the pool
    assert any(np.allclose(z[:, 0, 1], s) for s in pool)
    with pytest.raises(ValueError, match="pool"):
        draw_latents(protocol_spec("paper"), 20, 12, groups, rng, None)


def test_iid_protocol_latents_are_fresh_per_step_and_pedestrian() -> None:
    z = draw_latents(protocol_spec("iid"), 500, 12, np.zeros(3, dtype=int), np.random.default_rng(0))
    assert not np.allclose(z[:, 0], z[:, 1]) and not np.allclose(z[:, :, 0], z[:, :, 1])
    assert abs(z.std() - 1.0) < 0.02 and abs(z.mean()) < 0.02


def test_scene_level_shares_everything() -> None:
    z = draw_latents(LatentSpec("normal", "scene", False), 5, 12, np.array([0, 1, 2]), np.random.default_rng(0))
    np.testing.assert_array_equal(z[:, :, 0], z[:, :, 2])
    with pytest.raises(ValueError):
        protocol_spec("bogus")


def test_kmeans_centroids_are_spread_and_scaled() -> None:
    rng = np.random.default_rng(0)
    pts = np.concatenate([rng.normal(size=(50, 2)) * 0.01 + c for c in ([0, 0], [5, 5], [-5, 5])])
    c = kmeans_centroids(pts, 3, rng)
    np.testing.assert_allclose(sorted(c[:, 0].round()), [-5, 0, 5])
    pool = kmeans_pool(20, 2, rng)
    assert pool.shape == (2, 20, 2) and 0.3 < np.abs(pool).mean() < 1.0  # 0.8 x centroids of N(0, I)


def test_sampling_reproduces_the_step_covariance() -> None:
    cov = np.array([[[[0.04, 0.012], [0.012, 0.09]]]])  # (T=1, N=1, 2, 2)
    chol = cholesky_2x2(cov)
    np.testing.assert_allclose(chol @ np.swapaxes(chol, -1, -2), cov)
    z = np.random.default_rng(0).standard_normal((20000, 1, 1, 2))
    s = sample_positions(np.zeros((1, 1, 2)), chol, z, np.array([[1.0, 2.0]]))
    np.testing.assert_allclose(np.cov(s[:, 0, 0].T), cov[0, 0], atol=3e-3)
    np.testing.assert_allclose(s.mean(axis=0)[0, 0], [1.0, 2.0], atol=0.01)


def test_paper_protocol_reproduces_published_hotel_numbers(reference: Path, eth_ucy: Path) -> None:
    from predictor.checkpoint import load_model
    from predictor.evaluate import EvalConfig, evaluate
    from predictor.windows import load_windows

    model, _ = load_model(reference / "hotel" / "val_best.pth")
    res = evaluate(model, load_windows(eth_ucy / "hotel" / "test"),
                   EvalConfig(protocol="paper", trials=1, pool_size=50))
    assert res["ade"] == pytest.approx(0.18, abs=0.02) and res["fde"] == pytest.approx(0.30, abs=0.03)
