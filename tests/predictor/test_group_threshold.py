"""Inference-time calibration of the group threshold: ``GPGraph.group_threshold_scale`` and where it is set."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from predictor import GPGraph, GPGraphConfig, grouping, load_predictor
from predictor.batch import collate
from predictor.checkpoint import CheckpointError, export_packaged, load_model, read_file, save_model
from predictor.cli import main
from predictor.evaluate import EvalConfig, evaluate
from predictor.windows import load_windows

SCALES_DOWN = (4.0, 2.0, 1.25, 1.0, 0.8, 0.5, 0.3, 0.1, 1e-6)


def _model(seed: int = 0, **cfg: object) -> GPGraph:
    torch.manual_seed(seed)
    return GPGraph(GPGraphConfig(backbone="stgcnn", **cfg)).eval()


def _scene(seed: int, b: int = 3, n: int = 9) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Random padded batch: clustered positions (so that some pairs fall under the threshold), node mask."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-3, 3, size=(1, n // 3 + 1, 2)).repeat(3, axis=1)[:, :n]
    pos = centres + rng.normal(scale=0.4, size=(b, n, 2))
    obs_abs = pos[:, None] + rng.normal(scale=0.3, size=(b, 1, n, 2)) * np.arange(8)[None, :, None, None]
    obs_abs = torch.as_tensor(obs_abs, dtype=torch.float32)
    obs_rel = torch.cat([torch.zeros_like(obs_abs[:, :1]), obs_abs.diff(dim=1)], dim=1)
    counts = rng.integers(1, n + 1, size=b)
    counts[0] = n
    mask = torch.arange(n)[None] < torch.as_tensor(counts)[:, None]
    return obs_abs, obs_rel, mask


def misuse_command(tmp_path: Path, command: str) -> list[str]:
    """A valid `gpgraph evaluate` or `predict` command line (with a history file in tmp_path) for misuse tests
    to append one bad option to."""
    hist = tmp_path / "h.npy"
    np.save(hist, np.zeros((8, 3, 2)))
    if command == "evaluate":
        return ["evaluate", "--checkpoint", "gpgraph-stgcnn-synthetic", "--data", str(tmp_path),
                "--json", str(tmp_path / "r.json")]
    return ["predict", "--checkpoint", "gpgraph-stgcnn-synthetic", "--history", str(hist),
            "--out", str(tmp_path / "p.npz")]


def _assert_refining(label_sequence, mask: torch.Tensor) -> torch.Tensor:
    """Each labelling (B, N) of the sequence refines the previous one (never merges more); the last counts."""
    prev, prev_count = None, None
    for labels in label_sequence:
        count = grouping.group_count(labels, mask)
        if prev is not None:
            assert (count >= prev_count).all()
            for i, m in enumerate(mask.sum(dim=1).tolist()):
                assert _refines(labels[i, :m].numpy(), prev[i, :m].numpy())
        prev, prev_count = labels, count
    return prev_count


def _refines(fine: np.ndarray, coarse: np.ndarray) -> bool:
    """Every group of ``fine`` lies inside one group of ``coarse``."""
    return all(len(np.unique(coarse[fine == g])) == 1 for g in np.unique(fine))


def test_scale_one_is_the_uncalibrated_model_exactly() -> None:
    """Scale 1.0 (the default) gives bit-identical groups and outputs to thresholding at the learned pi."""
    model = _model()
    with torch.no_grad():
        model.assigner.threshold.fill_(0.6)  # a threshold that links some pairs of this scene
    obs_abs, obs_rel, mask = _scene(0)
    assert model.group_threshold_scale == 1.0
    with torch.no_grad():
        out = model(obs_abs, obs_rel, mask)
        dist = model.assigner(obs_abs)
    # today's rule, written out: components of D <= pi
    np.testing.assert_array_equal(out.groups, grouping.threshold_groups(dist, model.assigner.threshold, mask))
    assert (grouping.group_count(out.groups, mask) < mask.sum(dim=1)).any()  # some pedestrians were merged
    explicit = GPGraph(model.config, group_threshold_scale=1.0).eval()
    explicit.load_state_dict(model.state_dict())
    with torch.no_grad():
        again = explicit(obs_abs, obs_rel, mask)
    assert torch.equal(out.raw, again.raw) and torch.equal(out.groups, again.groups)
    assert torch.equal(out.pi, model.assigner.threshold)  # Output.pi stays the learned threshold


def test_scale_one_reproduces_the_packaged_synthetic_predictor(synthetic_data: Path) -> None:
    """The packaged file without its calibration (exact grouping, scale 1.0 given explicitly) groups exactly by
    connected components at the learned threshold, as it was trained; the shipped meta says 1.1."""
    windows = load_windows(synthetic_data / "test")
    assert load_model("gpgraph-stgcnn-synthetic")[0].group_threshold_scale == 1.1
    default, _ = load_model("gpgraph-stgcnn-synthetic", group_threshold_scale=1.0, group_mode="exact")
    explicit, _ = load_model("gpgraph-stgcnn-synthetic", group_threshold_scale=1.0, group_mode="exact")
    assert default.group_threshold_scale == 1.0
    cfg = EvalConfig(trials=2)
    np.testing.assert_equal(evaluate(default, windows, cfg), evaluate(explicit, windows, cfg))  # NaN == NaN here
    batch = collate(windows)
    with torch.no_grad():
        out = default(batch.obs_abs, batch.obs_rel, batch.node_mask)
        dist = default.assigner(batch.obs_abs)
    np.testing.assert_array_equal(
        out.groups, grouping.threshold_groups(dist, default.assigner.threshold, batch.node_mask))


@pytest.mark.parametrize("seed", range(6))
def test_smaller_scale_never_merges_more_on_random_distances(seed: int) -> None:
    """threshold_groups at pi * s: as s decreases, each partition refines the previous one."""
    rng = np.random.default_rng(seed)
    b, n = 4, 12
    d = rng.gamma(2.0, 0.5, size=(b, n, n))
    dist = torch.as_tensor((d + d.transpose(0, 2, 1)) / 2 * (1 - np.eye(n)), dtype=torch.float32)
    mask = torch.arange(n)[None] < torch.as_tensor(rng.integers(1, n + 1, size=b))[:, None]
    pi = torch.tensor([float(rng.uniform(0.2, 1.5))])
    last = _assert_refining((grouping.threshold_groups(dist, pi * s, mask) for s in SCALES_DOWN), mask)
    assert (last == mask.sum(dim=1)).all()  # a tiny scale leaves everybody alone


@pytest.mark.parametrize("seed", range(4))
def test_smaller_scale_never_merges_more_in_the_model(seed: int) -> None:
    model = _model(seed)
    with torch.no_grad():
        model.assigner.threshold.fill_(float(np.random.default_rng(seed).uniform(0.3, 1.5)))
    obs_abs, obs_rel, mask = _scene(100 + seed)

    def labels_at(scale: float) -> torch.Tensor:
        model.group_threshold_scale = scale
        with torch.no_grad():
            return model(obs_abs, obs_rel, mask).groups

    _assert_refining((labels_at(s) for s in SCALES_DOWN), mask)


@pytest.mark.parametrize("bad", [0, -0.5, math.nan, math.inf, -math.inf, "x", None, True])
def test_invalid_scales_are_refused(bad: object) -> None:
    model = _model()
    with pytest.raises(ValueError, match="finite number > 0"):
        model.group_threshold_scale = bad  # type: ignore[assignment]
    with pytest.raises(ValueError, match="finite number > 0"):
        GPGraph(GPGraphConfig(backbone="stgcnn"), group_threshold_scale=bad)  # type: ignore[arg-type]
    if bad is not None:  # None means "the checkpoint's value" in the loaders
        with pytest.raises(ValueError, match="finite number > 0"):
            load_predictor("gpgraph-stgcnn-synthetic", group_threshold_scale=bad)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="finite number > 0"):
            load_predictor("constant-velocity", group_threshold_scale=bad)  # type: ignore[arg-type]
    assert model.group_threshold_scale == 1.0


def test_checkpoint_meta_stores_the_calibration(tmp_path: Path) -> None:
    model = _model()
    plain = tmp_path / "plain.pt"
    save_model(model, plain, meta={"epoch": 3})
    assert read_file(plain)["meta"] == {"epoch": 3}  # uncalibrated files are unchanged
    assert load_model(plain)[0].group_threshold_scale == 1.0
    model.group_threshold_scale = 0.7
    for path in (tmp_path / "cal.pt", tmp_path / "cal.safetensors"):
        (save_model if path.suffix == ".pt" else export_packaged)(model, path, meta={"epoch": 3})
        loaded, meta = load_model(path)
        assert meta == {"epoch": 3, "group_threshold_scale": 0.7} and loaded.group_threshold_scale == 0.7
        assert load_model(path, group_threshold_scale=1.0)[0].group_threshold_scale == 1.0  # the override wins
        assert load_predictor(path).model.group_threshold_scale == 0.7
        assert load_predictor(path, group_threshold_scale=0.5).model.group_threshold_scale == 0.5
    model.group_threshold_scale = 1.0  # saving an uncalibrated model drops a stale key
    save_model(model, tmp_path / "back.pt", meta={"epoch": 3, "group_threshold_scale": 0.7})
    assert read_file(tmp_path / "back.pt")["meta"] == {"epoch": 3}
    bad = tmp_path / "bad.pt"
    obj = read_file(plain)
    obj["meta"]["group_threshold_scale"] = -1
    torch.save(obj, bad)
    with pytest.raises(CheckpointError, match="group_threshold_scale"):
        load_model(bad)
    assert load_model(bad, group_threshold_scale=0.9)[0].group_threshold_scale == 0.9


def test_predictor_api_groups_follow_the_scale() -> None:
    rng = np.random.default_rng(0)
    base = rng.uniform(-4, 4, size=(1, 5, 2)) + np.arange(8)[:, None, None] * np.array([0.4, 0.0])
    history = np.concatenate([base, base + np.array([0.0, 0.6])], axis=1)  # five side-by-side pairs
    counts = []
    for s in (1.0, 0.5, 1e-6):
        pred = load_predictor("gpgraph-stgcnn-synthetic", group_threshold_scale=s).predict(history, rng=0)
        counts.append(len(np.unique(pred.group_id)))
    assert counts == sorted(counts) and counts[-1] == 10


def test_cli_evaluate_scale_and_split(synthetic_data: Path, tmp_path: Path) -> None:
    ckpt = tmp_path / "m.pt"
    save_model(_model(), ckpt)
    base = ["evaluate", "--checkpoint", str(ckpt), "--data", str(synthetic_data), "--trials", "2", "--quiet"]
    runs = {}
    for name, extra in {"default": [], "one": ["--group-threshold-scale", "1"],
                        "small": ["--group-threshold-scale", "1e-6"], "val": ["--split", "val"]}.items():
        out = tmp_path / f"{name}.json"
        assert main([*base, *extra, "--json", str(out)]) == 0
        runs[name] = json.loads(out.read_text())
    metrics = ("ade", "fde", "col", "tcc", "pw_precision", "pw_recall", "gmitre_precision", "gmitre_recall")
    assert all(runs["default"][k] == runs["one"][k] for k in metrics)
    assert runs["default"]["group_threshold_scale"] == 1.0 and runs["small"]["group_threshold_scale"] == 1e-6
    assert runs["small"]["pw_precision"] is None  # no pair predicted at a vanishing threshold
    assert runs["default"]["split"] == "test" and runs["val"]["split"] == "val"


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "-inf", "abc", ""])
@pytest.mark.parametrize("command", ["evaluate", "predict"])
def test_cli_bad_scale_is_one_line_exit_2(tmp_path: Path, capsys, command: str, value: str) -> None:
    args = misuse_command(tmp_path, command)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    with pytest.raises(SystemExit) as exc:
        main([*args, f"--group-threshold-scale={value}"])  # '=' so that '-inf' is read as a value
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"gpgraph {command}: error: argument --group-threshold-scale") and "> 0" in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
