"""WiSE-FT weight interpolation (predictor/interpolate.py, `gpgraph interpolate`): the ends reproduce their models'
forecasts exactly, the middle is the weights' average, mismatched or bad input is refused before anything is written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from predictor.api import GPGraphPredictor
from predictor.checkpoint import load_model, read_file, save_model
from predictor.cli import main
from predictor.interpolate import META_INTERPOLATION, interpolate_models
from predictor.model import GPGraph, GPGraphConfig


def _model(seed: int, **config) -> GPGraph:
    torch.manual_seed(seed)
    return GPGraph(GPGraphConfig(backbone="stgcnn", **config))


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    start, end = tmp_path / "start.pt", tmp_path / "end.pt"
    save_model(_model(0), start, meta={"scene": "crowdsim"})
    tuned = _model(1)
    tuned.group_threshold_scale = 0.8  # the end's calibration travels with the result
    save_model(tuned, end, meta={"scene": "zara1", "epoch": 7})
    return start, end


def _forecast(path: Path) -> np.ndarray:
    history = np.cumsum(np.random.default_rng(5).normal(0.0, 0.3, (8, 4, 2)), axis=0)
    model, _ = load_model(path)
    return GPGraphPredictor(model).predict(history, n_samples=5, rng=np.random.default_rng(0)).samples


@pytest.mark.parametrize("alpha, same_as", [(0.0, "start"), (1.0, "end")])
def test_the_ends_forecast_exactly_as_the_models_they_come_from(pair, tmp_path, alpha, same_as):
    start, end = pair
    out = tmp_path / "mix.pt"
    args = ["interpolate", "--start", str(start), "--end", str(end), "--alpha", str(alpha), "--out", str(out)]
    assert main(args) == 0
    if same_as == "start":  # the end's grouping calibration is kept, so compare the weights of the start
        got, want = read_file(out)["state_dict"], read_file(start)["state_dict"]
        assert all(torch.equal(got[k], want[k]) for k in want)
    else:
        np.testing.assert_array_equal(_forecast(out), _forecast(end))


def test_the_middle_is_the_average_and_the_meta_says_how_it_was_made(pair, tmp_path):
    start, end = pair
    out = tmp_path / "mix.pt"
    assert main(["interpolate", "--start", str(start), "--end", str(end), "--alpha", "0.25", "--out", str(out)]) == 0
    got, a, b = (read_file(p) for p in (out, start, end))
    for k, w in got["state_dict"].items():
        torch.testing.assert_close(w, 0.75 * a["state_dict"][k] + 0.25 * b["state_dict"][k], rtol=0, atol=1e-7)
    assert any(not torch.equal(a["state_dict"][k], w) for k, w in got["state_dict"].items())
    meta = got["meta"]
    assert meta[META_INTERPOLATION]["alpha"] == 0.25 and meta[META_INTERPOLATION]["start"] == str(start)
    assert meta["scene"] == "zara1" and meta["epoch"] == 7 and meta["group_threshold_scale"] == 0.8


def test_different_architectures_are_refused():
    with pytest.raises(ValueError, match="embed_channels"):
        interpolate_models(_model(0), _model(1, embed_channels=4), 0.5)
    with pytest.raises(ValueError, match="backbone"):
        torch.manual_seed(0)
        interpolate_models(_model(0), GPGraph(GPGraphConfig(backbone="sgcn")), 0.5)


@pytest.mark.parametrize("alpha", ["nan", "-0.1", "1.5", "inf"])
def test_an_alpha_outside_0_1_is_one_line_and_writes_nothing(pair, tmp_path, capsys, alpha):
    start, end = pair
    out = tmp_path / "mix.pt"
    assert main(["interpolate", "--start", str(start), "--end", str(end), "--alpha", alpha, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "alpha" in err and not out.exists()


def test_a_corrupt_checkpoint_or_a_wrong_suffix_is_one_line_and_writes_nothing(pair, tmp_path, capsys):
    start, end = pair
    bad = tmp_path / "bad.pt"
    bad.write_bytes(read_file.__doc__.encode())  # not a torch file
    out = tmp_path / "mix.pt"
    assert main(["interpolate", "--start", str(start), "--end", str(bad), "--alpha", "0.5", "--out", str(out)]) == 2
    assert main(["interpolate", "--start", str(start), "--end", str(end), "--alpha", "0.5",
                 "--out", str(tmp_path / "mix.safetensors")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "cannot read checkpoint" in err[0] and ".pt" in err[1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.pt", "end.pt", "start.pt"]
