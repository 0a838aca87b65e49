"""--device: one helper resolves it; cuda without CUDA is a one-line error; checkpoints stay CPU tensors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from predictor.batch import collate
from predictor.checkpoint import read_file, save_model, to_cpu
from predictor.cli import main
from predictor.device import model_device, resolve_device
from predictor.evaluate import EvalConfig, evaluate
from predictor.model import GPGraph, GPGraphConfig
from predictor.windows import Window, load_windows


def test_resolve_device() -> None:
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("cpu", cuda_available=lambda: 1 / 0) == torch.device("cpu")  # cpu never asks
    assert resolve_device("auto", cuda_available=lambda: False) == torch.device("cpu")
    assert resolve_device("auto", cuda_available=lambda: True) == torch.device("cuda")
    assert resolve_device("cuda", cuda_available=lambda: True) == torch.device("cuda")
    with pytest.raises(ValueError, match="no CUDA device") as exc:
        resolve_device("cuda", cuda_available=lambda: False)
    assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="one of cpu, cuda, auto"):
        resolve_device("gpu")
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert resolve_device("auto").type == expected  # the default asks torch


def test_batch_to_and_model_device() -> None:
    rng = np.random.default_rng(0)
    traj = np.cumsum(rng.normal(size=(20, 3, 2)), axis=0)
    batch = collate([Window(traj[:8], traj[8:], np.arange(3), np.array([0, 0, 1]))])
    assert batch.to("cpu") is batch  # nothing to move
    assert model_device(GPGraph(GPGraphConfig(backbone="stgcnn"))) == torch.device("cpu")
    assert model_device(torch.nn.ReLU()) == torch.device("cpu")  # no parameters


def test_to_cpu_keeps_the_structure() -> None:
    obj = {"a": torch.ones(2, requires_grad=True) * 2, "b": [torch.zeros(1), (3, torch.ones(1))], "c": "x"}
    moved = to_cpu(obj)
    assert moved["c"] == "x" and isinstance(moved["b"], list) and isinstance(moved["b"][1], tuple)
    assert moved["b"][1][0] == 3 and not moved["a"].requires_grad and moved["a"].device.type == "cpu"


@pytest.mark.parametrize("command", ["train", "evaluate", "predict"])
def test_cuda_without_cuda_is_one_line_exit_2_and_writes_nothing(tmp_path: Path, capsys, monkeypatch,
                                                                  command: str) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    np.save(tmp_path / "h.npy", np.cumsum(np.full((8, 3, 2), 0.4), axis=0))
    argv = {
        "train": ["train", "--data", str(tmp_path), "--out", str(tmp_path / "run")],
        "evaluate": ["evaluate", "--checkpoint", "gpgraph-stgcnn-hotel", "--data", str(tmp_path),
                     "--json", str(tmp_path / "r.json")],
        "predict": ["predict", "--checkpoint", "gpgraph-stgcnn-hotel", "--history", str(tmp_path / "h.npy"),
                    "--out", str(tmp_path / "p.npz")],
    }[command]
    before = sorted(tmp_path.rglob("*"))
    assert main([*argv, "--device", "cuda"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gpgraph: error: --device cuda") and err.count("\n") == 1
    assert sorted(tmp_path.rglob("*")) == before


def test_auto_falls_back_to_cpu(synthetic_data: Path, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    out = tmp_path / "run"
    assert main(["train", "--data", str(synthetic_data), "--out", str(out), "--epochs", "1", "--batch-size", "8",
                 "--eval-every", "0", "--quiet", "--device", "auto"]) == 0
    state = read_file(out / "last.pt")
    assert all(t.device.type == "cpu" for t in state["state_dict"].values())
    assert main(["evaluate", "--checkpoint", str(out / "best.pt"), "--data", str(synthetic_data), "--trials", "1",
                 "--quiet", "--device", "auto"]) == 0


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_matches_cpu(synthetic_data: Path, tmp_path: Path) -> None:  # pragma: no cover - GPU machines only
    """The same checkpoint evaluated on cuda and cpu: the same latent draws, equal metrics up to float error;
    a model trained on cuda is saved with CPU tensors."""
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="stgcnn")).eval()
    windows = load_windows(synthetic_data / "test")
    cfg = EvalConfig(protocol="iid", trials=2)
    on_cpu = evaluate(model, windows, cfg)
    on_cuda = evaluate(model.to("cuda"), windows, cfg)
    for key in ("ade", "fde", "col", "tcc"):
        assert on_cuda[key] == pytest.approx(on_cpu[key], rel=1e-4, abs=1e-6)
    save_model(model, tmp_path / "m.pt")
    assert all(t.device.type == "cpu" for t in read_file(tmp_path / "m.pt")["state_dict"].values())
    out = tmp_path / "run"
    assert main(["train", "--data", str(synthetic_data), "--out", str(out), "--epochs", "2", "--batch-size", "8",
                 "--eval-every", "1", "--quiet", "--device", "cuda"]) == 0
    last = read_file(out / "last.pt")
    assert all(t.device.type == "cpu" for t in last["state_dict"].values())
    assert main(["train", "--data", str(synthetic_data), "--out", str(out), "--epochs", "3", "--batch-size", "8",
                 "--quiet", "--device", "cuda", "--resume"]) == 0
