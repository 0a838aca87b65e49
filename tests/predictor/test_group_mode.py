"""Inference-time hard grouping override ``GPGraph.group_mode``, and its 'average' (average-linkage) mode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from predictor import GPGraph, GPGraphConfig, grouping, load_predictor
from predictor.checkpoint import CheckpointError, export_packaged, load_model, read_file, save_model
from predictor.cli import main


def _model(seed: int = 0, **kw: object) -> GPGraph:
    torch.manual_seed(seed)
    return GPGraph(GPGraphConfig(backbone="stgcnn"), **kw).eval()  # type: ignore[arg-type]


def _random_batch(seed: int, b: int = 5, n: int = 14) -> tuple[torch.Tensor, torch.Tensor]:
    """Symmetric random distances (B, N, N) of clustered points and a padding mask (first window full)."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(b, n, 3)) + rng.integers(0, 4, size=(b, n, 1)) * 2.0
    d = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1)
    counts = rng.integers(1, n + 1, size=b)
    counts[0] = n
    return torch.as_tensor(d), torch.arange(n)[None] < torch.as_tensor(counts)[:, None]


def _same(labels: np.ndarray) -> np.ndarray:
    return labels[:, None] == labels[None]


def _refines(fine: np.ndarray, coarse: np.ndarray) -> bool:
    return all(len(np.unique(coarse[fine == g])) == 1 for g in np.unique(fine))


def _scene(seed: int = 0, b: int = 3, n: int = 9) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-3, 3, size=(b, n, 2))
    obs_abs = torch.as_tensor(pos[:, None] + 0.3 * np.arange(8)[None, :, None, None] * rng.normal(size=(b, 1, n, 2)),
                              dtype=torch.float32)
    obs_rel = torch.cat([torch.zeros_like(obs_abs[:, :1]), obs_abs.diff(dim=1)], dim=1)
    mask = torch.arange(n)[None] < torch.as_tensor([n, 5, 2])[:, None]
    return obs_abs, obs_rel, mask


def test_average_linkage_does_not_chain_what_components_join() -> None:
    # a-b and b-c close, a-c far: components of D <= 0.8 join all three; average linkage merges a-b (0.5),
    # then {a, b} to c at the mean (2.0 + 0.5) / 2 = 1.25 > 0.8, so c stays alone.
    d = torch.tensor([[[0.0, 0.5, 2.0], [0.5, 0.0, 0.5], [2.0, 0.5, 0.0]]])
    mask = torch.ones(1, 3, dtype=torch.bool)
    pi = torch.tensor(0.8)
    np.testing.assert_array_equal(grouping.threshold_groups(d, pi, mask, "exact")[0], [0, 0, 0])
    np.testing.assert_array_equal(grouping.threshold_groups(d, pi, mask, "average")[0], [0, 0, 1])
    # at a cut above 1.25 average linkage joins them too
    np.testing.assert_array_equal(grouping.threshold_groups(d, torch.tensor(1.25), mask, "average")[0], [0, 0, 0])


def test_average_linkage_uses_mean_distance_of_whole_clusters() -> None:
    # two tight pairs {0, 1} and {2, 3}; one cross pair (1, 2) is close but the mean cross distance is not
    d = np.full((4, 4), 3.0)
    d[0, 1] = d[1, 0] = d[2, 3] = d[3, 2] = 0.2
    d[1, 2] = d[2, 1] = 0.6
    np.fill_diagonal(d, 0.0)
    dist, mask = torch.as_tensor(d)[None], torch.ones(1, 4, dtype=torch.bool)
    assert grouping.average_linkage(dist, 1.0, mask)[0].tolist() == [0, 0, 1, 1]  # mean 2.4 > 1.0
    assert grouping.average_linkage(dist, 2.4, mask)[0].tolist() == [0, 0, 0, 0]
    assert grouping.threshold_groups(dist, torch.tensor(1.0), mask)[0].tolist() == [0, 0, 0, 0]


@pytest.mark.parametrize("seed", range(5))
def test_average_linkage_matches_scipy(seed: int) -> None:
    from scipy.cluster.hierarchy import fcluster, linkage
    from scipy.spatial.distance import squareform

    dist, mask = _random_batch(seed)
    for t in (0.3, 1.0, 2.0, 4.0):
        labels = grouping.average_linkage(dist, t, mask).numpy()
        for i, m in enumerate(mask.sum(dim=1).tolist()):
            if m < 2:
                assert labels[i, :m].tolist() == [0] * m
                continue
            ref = fcluster(linkage(squareform(dist[i, :m, :m].numpy(), checks=False), "average"), t,
                           criterion="distance")
            np.testing.assert_array_equal(_same(labels[i, :m]), _same(ref))


@pytest.mark.parametrize("seed", range(4))
def test_padding_never_joins_a_group(seed: int) -> None:
    dist, mask = _random_batch(seed)
    n = dist.shape[1]
    zeroed = dist.clone()
    zeroed[~grouping.pair_mask(mask)] = 0.0  # padded pairs as close as can be
    for t in (0.5, 2.0, 100.0):
        labels = grouping.average_linkage(zeroed, t, mask)
        for i, m in enumerate(mask.sum(dim=1).tolist()):
            g = int(labels[i, :m].max()) + 1 if m else 0
            assert labels[i, m:].tolist() == list(range(g, g + n - m))  # padding: one group each, after the real
            alone = grouping.average_linkage(dist[i : i + 1, :m, :m], t, torch.ones(1, m, dtype=torch.bool))
            assert labels[i, :m].tolist() == alone[0].tolist()  # the real pedestrians as without padding


@pytest.mark.parametrize("seed", range(4))
def test_average_linkage_is_permutation_equivariant(seed: int) -> None:
    dist, _ = _random_batch(seed, b=1, n=20)
    mask = torch.ones(1, 20, dtype=torch.bool)
    perm = torch.as_tensor(np.random.default_rng(seed).permutation(20))
    for t in (0.5, 1.5, 3.0):
        labels = grouping.average_linkage(dist, t, mask)[0].numpy()
        permuted = grouping.average_linkage(dist[:, perm][:, :, perm], t, mask)[0].numpy()
        np.testing.assert_array_equal(_same(permuted), _same(labels[perm.numpy()]))
        # labels are numbered by first member: 0, then each new group the next integer
        assert np.all(np.maximum.accumulate(permuted) <= np.arange(20)) and permuted[0] == 0


@pytest.mark.parametrize("seed", range(4))
def test_average_linkage_is_nested_and_refines_components(seed: int) -> None:
    dist, mask = _random_batch(seed)
    prev = None
    for t in (0.2, 0.5, 1.0, 1.5, 2.5, 4.0, 8.0):
        labels = grouping.average_linkage(dist, t, mask)
        comps = grouping.threshold_groups(dist, torch.tensor(t), mask, "exact")
        for i, m in enumerate(mask.sum(dim=1).tolist()):
            assert _refines(labels[i, :m].numpy(), comps[i, :m].numpy())
            if prev is not None:
                assert _refines(prev[i, :m].numpy(), labels[i, :m].numpy())
        prev = labels


def test_default_is_the_trained_grouping_bit_for_bit() -> None:
    """group_mode None (default) and the config's own mode give identical outputs, in eval and train mode."""
    model = _model()
    with torch.no_grad():
        model.assigner.threshold.fill_(0.8)
    obs_abs, obs_rel, mask = _scene()
    assert model.group_mode is None and model.effective_group_mode == "exact"
    explicit = _model(group_mode="exact")
    explicit.load_state_dict(model.state_dict())
    for train in (False, True):
        model.train(train)
        explicit.train(train)
        torch.manual_seed(1)
        out = model(obs_abs, obs_rel, mask)
        torch.manual_seed(1)
        again = explicit(obs_abs, obs_rel, mask)
        assert torch.equal(out.raw, again.raw) and torch.equal(out.groups, again.groups)
        np.testing.assert_array_equal(
            out.groups, grouping.threshold_groups(out.dist.detach(), model.assigner.threshold, mask, "exact"))
    with pytest.raises(ValueError, match="grouping must be one of"):
        GPGraphConfig(grouping="average")  # an inference override only: never a trained grouping


def test_average_mode_in_the_model_follows_scale() -> None:
    model = _model(group_mode="average")
    with torch.no_grad():
        model.assigner.threshold.fill_(0.8)
    obs_abs, obs_rel, mask = _scene()
    for scale in (0.5, 1.0, 1.3):
        model.group_threshold_scale = scale
        with torch.no_grad():
            out = model(obs_abs, obs_rel, mask)
        expected = grouping.average_linkage(out.dist, model.assigner.threshold * scale, mask)
        assert torch.equal(out.groups, expected)
        assert torch.isfinite(out.raw).all()


@pytest.mark.parametrize("bad", ["ratio", "avg", "", 1, True])
def test_invalid_group_modes_are_refused(bad: object) -> None:
    model = _model()
    with pytest.raises(ValueError, match="group_mode must be one of exact, official, average"):
        model.group_mode = bad  # type: ignore[assignment]
    with pytest.raises(ValueError, match="group_mode must be one of"):
        load_predictor("gpgraph-stgcnn-synthetic", group_mode=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="group_mode must be one of"):
        load_predictor("constant-velocity", group_mode=bad)  # type: ignore[arg-type]
    assert model.group_mode is None


def test_checkpoint_meta_stores_the_group_mode(tmp_path: Path) -> None:
    model = _model()
    save_model(model, tmp_path / "plain.pt", meta={"epoch": 3})
    assert read_file(tmp_path / "plain.pt")["meta"] == {"epoch": 3}  # the default writes no key
    assert load_model(tmp_path / "plain.pt")[0].group_mode is None
    shipped = load_model("gpgraph-stgcnn-synthetic")[0]  # calibrated on the validation split (RESULTS)
    assert (shipped.group_mode, shipped.group_threshold_scale) == ("average", 1.1)
    model.group_mode, model.group_threshold_scale = "average", 1.2
    for path in (tmp_path / "avg.pt", tmp_path / "avg.safetensors"):
        (save_model if path.suffix == ".pt" else export_packaged)(model, path, meta={"epoch": 3})
        loaded, meta = load_model(path)
        assert meta == {"epoch": 3, "group_threshold_scale": 1.2, "group_mode": "average"}
        assert loaded.group_mode == "average" and loaded.group_threshold_scale == 1.2
        assert load_model(path, group_mode="exact")[0].group_mode == "exact"  # the override wins
        assert load_predictor(path).model.group_mode == "average"
        assert load_predictor(path, group_mode="official").model.group_mode == "official"
    obj = read_file(tmp_path / "plain.pt")
    obj["meta"]["group_mode"] = "single"
    torch.save(obj, tmp_path / "bad.pt")
    with pytest.raises(CheckpointError, match="group_mode"):
        load_model(tmp_path / "bad.pt")
    assert load_model(tmp_path / "bad.pt", group_mode="average")[0].group_mode == "average"


def test_predictor_api_average_mode_splits_a_chain() -> None:
    """Ten walkers in a line 0.6 m apart: whatever components join, average linkage never gives fewer groups."""
    base = np.zeros((8, 10, 2))
    base[..., 0] = np.arange(10) * 0.6
    base[..., 1] = np.arange(8)[:, None] * 0.4
    counts = {}
    for mode in ("exact", "average"):
        pred = load_predictor("gpgraph-stgcnn-synthetic", group_mode=mode).predict(base, rng=0)
        counts[mode] = len(np.unique(pred.group_id))
        assert pred.samples.shape == (20, 12, 10, 2)
    assert counts["average"] >= counts["exact"]


def test_cli_group_mode(synthetic_data: Path, tmp_path: Path) -> None:
    base = ["evaluate", "--checkpoint", "gpgraph-stgcnn-synthetic", "--data", str(synthetic_data), "--trials", "2",
            "--quiet"]
    runs = {}
    modes = {"default": [], "exact": ["--group-mode", "exact"], "average": ["--group-mode", "average"]}
    for name, extra in modes.items():
        out = tmp_path / f"{name}.json"
        assert main([*base, *extra, "--json", str(out)]) == 0
        runs[name] = json.loads(out.read_text())
    keys = ("ade", "fde", "col", "tcc", "pw_precision", "pw_recall", "gmitre_precision", "gmitre_recall")
    assert all(runs["default"][k] == runs["average"][k] for k in keys)  # the shipped meta says average
    assert runs["default"]["group_mode"] == "average" and runs["exact"]["group_mode"] == "exact"
    hist = tmp_path / "h.npy"
    np.save(hist, np.cumsum(np.full((8, 3, 2), 0.3), axis=0) + np.arange(3)[None, :, None])
    out = tmp_path / "p.npz"
    assert main(["predict", "--checkpoint", "gpgraph-stgcnn-synthetic", "--history", str(hist), "--out", str(out),
                 "--group-mode", "average"]) == 0
    assert np.load(out)["samples"].shape[-2:] == (3, 2)


@pytest.mark.parametrize("value", ["single", "ratio", "", "Average"])
@pytest.mark.parametrize("command", ["evaluate", "predict"])
def test_cli_bad_group_mode_is_one_line_exit_2(tmp_path: Path, capsys, command: str, value: str) -> None:
    from test_group_threshold import misuse_command

    args = misuse_command(tmp_path, command)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    with pytest.raises(SystemExit) as exc:
        main([*args, f"--group-mode={value}"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"gpgraph {command}: error: argument --group-mode")
    assert all(name in err for name in grouping.THRESHOLD_MODES)
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
