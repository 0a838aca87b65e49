"""Inference API and bad-input handling."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from predictor import (
    ConstantVelocityConfig,
    ConstantVelocityPredictor,
    GPGraph,
    GPGraphConfig,
    GPGraphPredictor,
    Prediction,
    load_predictor,
)
from predictor.checkpoint import CheckpointError, export_packaged, load_model, save_model


def _history(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    start = rng.uniform(-4, 4, size=(n, 2))
    vel = rng.normal(scale=0.4, size=(n, 2))
    return start[None] + vel[None] * np.arange(8)[:, None, None]


@pytest.fixture(scope="module")
def predictor() -> GPGraphPredictor:
    torch.manual_seed(0)
    return GPGraphPredictor(GPGraph(GPGraphConfig(backbone="stgcnn")))


def test_prediction_shapes_and_consistency(predictor: GPGraphPredictor) -> None:
    h = _history(5)
    p = predictor.predict(h, n_samples=7, rng=np.random.default_rng(0))
    assert isinstance(p, Prediction)
    assert p.samples.shape == (7, 12, 5, 2) and p.mean.shape == (12, 5, 2) and p.cov.shape == (12, 5, 2, 2)
    assert p.group_id.shape == (5,) and p.group_id.min() == 0
    assert set(p.group_id.tolist()) == set(range(p.group_id.max() + 1))
    assert p.samples.dtype == np.float64 and np.isfinite(p.samples).all()
    # covariances are symmetric positive definite and grow along the horizon
    np.testing.assert_allclose(p.cov, np.swapaxes(p.cov, -1, -2))
    assert (np.linalg.eigvalsh(p.cov) > 0).all()
    assert (np.trace(p.cov[-1], axis1=-2, axis2=-1) > np.trace(p.cov[0], axis1=-2, axis2=-1)).all()


def test_same_rng_state_same_samples(predictor: GPGraphPredictor) -> None:
    h = _history(4)
    a = predictor.predict(h, rng=np.random.default_rng(3)).samples
    b = predictor.predict(h, rng=np.random.default_rng(3)).samples
    c = predictor.predict(h, rng=np.random.default_rng(4)).samples
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_an_int_rng_is_a_seed_and_other_rngs_are_refused(predictor: GPGraphPredictor) -> None:
    h = _history(4)
    np.testing.assert_array_equal(predictor.predict(h, rng=3).samples,
                                  predictor.predict(h, rng=np.random.default_rng(3)).samples)
    for bad in (-1, 0.5, "0", np.random.RandomState(0)):
        with pytest.raises(ValueError, match="rng"):
            predictor.predict(h, rng=bad)
    cv = ConstantVelocityPredictor(ConstantVelocityConfig(step_noise_m=0.1))
    np.testing.assert_array_equal(cv.predict(h, rng=5).samples, cv.predict(h, rng=np.random.default_rng(5)).samples)


def test_group_level_latents_shared_by_members(predictor: GPGraphPredictor) -> None:
    h = _history(3)
    h[:, 1] = h[:, 0] + [0.0, 0.5]  # ped 1 walks beside ped 0
    model = predictor.model
    with torch.no_grad():
        model.assigner.threshold.fill_(1e6)  # everyone in one group
    try:
        p = predictor.predict(h, n_samples=50, rng=np.random.default_rng(0))
    finally:
        with torch.no_grad():
            model.assigner.threshold.fill_(1.0)
    assert p.group_id.tolist() == [0, 0, 0]
    # normalised residuals of co-members are identical latent draws
    dev = p.samples - p.mean[None]
    r0 = dev[:, 0, 0, 0] / np.sqrt(p.cov[0, 0, 0, 0])
    r1 = dev[:, 0, 1, 0] / np.sqrt(p.cov[0, 1, 0, 0])
    np.testing.assert_allclose(r0, r1, atol=1e-6)


def test_single_pedestrian_is_supported(predictor: GPGraphPredictor) -> None:
    p = predictor.predict(_history(1), n_samples=3, rng=np.random.default_rng(0))
    assert p.samples.shape == (3, 12, 1, 2) and p.group_id.tolist() == [0]


@pytest.mark.parametrize(
    ("history", "match"),
    [(np.zeros((7, 3, 2)), r"shape \(8, N, 2\)"), (np.zeros((8, 3)), r"shape \(8, N, 2\)"),
     (np.zeros((8, 0, 2)), "no pedestrians")],
)
def test_bad_history_shapes(predictor: GPGraphPredictor, history: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        predictor.predict(history)


def test_nan_history_is_rejected(predictor: GPGraphPredictor) -> None:
    h = _history(3)
    h[5, 2, 1] = np.nan
    with pytest.raises(ValueError, match="step 5, pedestrian 2"):
        predictor.predict(h)
    with pytest.raises(ValueError, match="n_samples"):
        predictor.predict(_history(3), n_samples=0)


def test_constant_velocity_predictor() -> None:
    h = _history(3)
    p = load_predictor("constant-velocity").predict(h, n_samples=4, rng=np.random.default_rng(0))
    vel = h[-1] - h[-2]
    np.testing.assert_allclose(p.mean[-1], h[-1] + 12 * vel)
    assert p.samples.shape == (4, 12, 3, 2) and p.group_id.tolist() == [0, 1, 2]
    exact = ConstantVelocityPredictor().predict(h, rng=np.random.default_rng(0))
    np.testing.assert_allclose(exact.samples.mean(axis=0)[-1], p.mean[-1], atol=1.0)


def test_checkpoint_roundtrip_and_errors(tmp_path: Path, predictor: GPGraphPredictor) -> None:
    path = tmp_path / "m.pt"
    save_model(predictor.model, path)
    h = _history(4)
    loaded = load_predictor(path)
    np.testing.assert_allclose(
        loaded.predict(h, rng=np.random.default_rng(1)).samples,
        predictor.predict(h, rng=np.random.default_rng(1)).samples, atol=1e-6,
    )
    packaged = tmp_path / "m.safetensors"
    export_packaged(predictor.model, packaged, meta={"scene": "test"})
    model, meta = load_model(packaged)
    assert meta == {"scene": "test"} and model.config == predictor.model.config
    truncated = tmp_path / "cut.pt"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="truncated"):
        load_predictor(truncated)
    with pytest.raises(CheckpointError, match="is a stgcnn model, not sgcn"):
        load_model(path, backbone="sgcn")
    with pytest.raises(CheckpointError, match="packaged"):
        load_predictor("gpgraph-nonexistent-scene")


def test_other_architecture_checkpoint(tmp_path: Path) -> None:
    path = tmp_path / "foreign.pt"
    torch.save({"format": "predictor.gpgraph/1", "config": GPGraphConfig(backbone="stgcnn").to_dict(),
                "state_dict": torch.nn.Linear(3, 3).state_dict()}, path)
    with pytest.raises(CheckpointError, match="does not fit"):
        load_predictor(path)
    torch.save(torch.nn.Linear(3, 3).state_dict(), path)
    with pytest.raises(CheckpointError, match="neither"):
        load_predictor(path)
    torch.save([1, 2, 3], path)
    with pytest.raises(CheckpointError, match="expected a dict"):
        load_predictor(path)


def test_reference_checkpoint_through_api(reference: Path) -> None:
    p = load_predictor(reference / "zara1" / "val_best.pth")
    assert p.model.config.grouping == "official" and p.model.config.backbone == "sgcn"
    out = p.predict(_history(6), n_samples=5, rng=np.random.default_rng(0))
    assert out.samples.shape == (5, 12, 6, 2)


def test_reference_checkpoint_with_wrong_backbone(reference: Path) -> None:
    with pytest.raises(CheckpointError, match="does not fit a stgcnn"):
        load_predictor(reference / "hotel" / "val_best.pth", backbone="stgcnn")
    with pytest.raises(ValueError, match="valid backbones"):
        load_predictor(reference / "hotel" / "val_best.pth", backbone="transformer")


@pytest.mark.parametrize("name", ["gpgraph-stgcnn-hotel", "stgcnn-zara1", "gpgraph-sgcn-univ", "sgcn-hotel"])
def test_packaged_checkpoints_load_by_name(name: str) -> None:
    from predictor.checkpoint import PACKAGE_CHECKPOINTS

    if not (PACKAGE_CHECKPOINTS / f"{name}.safetensors").is_file():
        pytest.skip(f"packaged checkpoint {name} not present")
    pred = load_predictor(name)
    assert pred.model.config.backbone == ("sgcn" if "sgcn" in name else "stgcnn")
    assert pred.model.config.uses_groups == name.startswith("gpgraph")
    out = pred.predict(_history(6), n_samples=4, rng=np.random.default_rng(0))
    assert out.samples.shape == (4, 12, 6, 2) and np.isfinite(out.samples).all()
    # a trained model predicts continuing motion: the mean moves on from the last observed position
    assert np.linalg.norm(out.mean[-1] - _history(6)[-1], axis=-1).mean() > 0.5


def test_packaged_eth_ucy_checkpoints_match_their_names() -> None:
    """Every packaged `[gpgraph-]<backbone>-<scene>` file holds that backbone, grouping and scene."""
    import re

    from predictor.checkpoint import PACKAGE_CHECKPOINTS, load_model

    pattern = re.compile(r"(gpgraph-)?(sgcn|stgcnn)-(eth|hotel|univ|zara1|zara2)")
    names = [p.stem for p in sorted(PACKAGE_CHECKPOINTS.glob("*.safetensors")) if pattern.fullmatch(p.stem)]
    if not names:
        pytest.skip("no packaged ETH/UCY checkpoints")
    for name in names:
        grouped, backbone, scene = pattern.fullmatch(name).groups()
        model, meta = load_model(name)
        assert meta["scene"] == scene, name
        assert model.config.backbone == backbone, name
        assert model.config.uses_groups == bool(grouped), name
        assert meta["train"]["seed"] == 0 and meta["epoch"] < meta["train"]["epochs"], name


def test_a_history_far_outside_the_training_scale_is_an_error_not_silent_nan() -> None:
    """Centimetres instead of metres (x100): the packaged model's output overflows; that must be an error."""
    pred = load_predictor("gpgraph-sgcn-hotel")
    h = _history(6)
    assert np.isfinite(pred.predict(h, rng=0).samples).all()
    with pytest.raises(ValueError, match=r"metres at 0\.4 s steps"):
        pred.predict(h * 1000.0, rng=0)
