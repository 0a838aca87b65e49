"""Training feedback: periodic validation ADE/FDE in log.csv and on the progress line; evaluate's progress bar."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
import torch

from predictor.cli import main
from predictor.evaluate import EvalConfig, evaluate
from predictor.model import GPGraph, GPGraphConfig
from predictor.train import LOG_FIELDS, VAL_EVAL_SEED, TrainConfig, validation_ade_fde
from predictor.windows import load_windows


def _train(data: Path, out: Path, epochs: int, *extra: str) -> int:
    return main(["train", "--data", str(data), "--out", str(out), "--epochs", str(epochs), "--batch-size", "8",
                 "--threads", "1", *extra])


def _log(out: Path) -> tuple[list[str], list[dict[str, str]]]:
    with (out / "log.csv").open(newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def test_eval_every_fills_val_ade_fde_on_epochs_k_n_and_the_last(synthetic_data: Path, tmp_path: Path,
                                                                  capsys) -> None:
    out = tmp_path / "run"
    assert _train(synthetic_data, out, 4, "--eval-every", "2") == 0
    header, rows = _log(out)
    assert header == list(LOG_FIELDS) and header[:5] == ["epoch", "train_loss", "val_loss", "lr", "seconds"]
    evaluated = [r["epoch"] for r in rows if r["val_ade"]]
    assert evaluated == ["0", "2", "3"]  # epochs 0, N, 2N, ... and the last
    assert all(r["val_fde"] == "" for r in rows if not r["val_ade"])
    for r in rows:
        if r["val_ade"]:
            ade, fde = float(r["val_ade"]), float(r["val_fde"])
            assert math.isfinite(ade) and math.isfinite(fde) and 0 < ade and 0 < fde
    captured = capsys.readouterr()
    assert "ade=" in captured.err and "fde=" in captured.err  # the progress line (tqdm, stderr)
    assert "validation windows" in captured.out and "last validation ADE/FDE" in captured.out


def test_eval_every_0_logs_no_ade_fde(synthetic_data: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    assert _train(synthetic_data, out, 2, "--eval-every", "0", "--quiet") == 0
    header, rows = _log(out)
    assert header == list(LOG_FIELDS) and len(rows) == 2
    assert all(r["val_ade"] == "" and r["val_fde"] == "" for r in rows)
    captured = capsys.readouterr()
    assert "ADE" not in captured.out and captured.err == ""


def test_validation_ade_fde_is_deterministic_iid_best_of_20(synthetic_data: Path) -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="stgcnn"))
    windows = load_windows(synthetic_data / "val")
    full = evaluate(model, windows, EvalConfig(protocol="iid", seed=VAL_EVAL_SEED, trials=1, n_samples=20))
    assert validation_ade_fde(model, windows) == (full["ade"], full["fde"])  # same draws as `evaluate`
    assert validation_ade_fde(model, windows) == validation_ade_fde(model, windows)


def test_resume_upgrades_an_old_log(synthetic_data: Path, tmp_path: Path) -> None:
    """A log.csv written before the val_ade/val_fde columns keeps its rows and gains the columns."""
    out = tmp_path / "run"
    assert _train(synthetic_data, out, 1, "--eval-every", "0", "--quiet") == 0
    lines = (out / "log.csv").read_text().splitlines()
    (out / "log.csv").write_text("\n".join(",".join(line.split(",")[:5]) for line in lines) + "\n")
    assert _train(synthetic_data, out, 2, "--eval-every", "1", "--quiet", "--resume") == 0
    header, rows = _log(out)
    assert header == list(LOG_FIELDS) and [r["epoch"] for r in rows] == ["0", "1"]
    assert rows[0]["val_ade"] == "" and float(rows[1]["val_ade"]) > 0


def test_eval_every_must_not_be_negative() -> None:
    with pytest.raises(ValueError, match="eval_every"):
        TrainConfig(eval_every=-1)


def test_evaluate_progress_bar_counts_windows_unless_quiet(synthetic_data: Path, tmp_path: Path, capsys) -> None:
    from predictor.checkpoint import save_model

    torch.manual_seed(0)
    ckpt = tmp_path / "m.pt"
    save_model(GPGraph(GPGraphConfig(backbone="stgcnn")), ckpt)
    n = len(load_windows(synthetic_data / "test"))
    args = ["evaluate", "--checkpoint", str(ckpt), "--data", str(synthetic_data), "--trials", "1"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert f"{n}/{n}" in err and "window" in err
    assert main([*args, "--quiet"]) == 0
    assert capsys.readouterr().err == ""
