"""gpgraph CLI: train (CSV log, atomic checkpoint with config, resume), evaluate (JSON), predict."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from predictor.checkpoint import read_file
from predictor.cli import main
from predictor.evaluate import EvalConfig, evaluate
from predictor.model import GPGraph, GPGraphConfig
from predictor.windows import load_windows


def _train(data: Path, out: Path, epochs: int, *extra: str) -> int:
    return main(["train", "--data", str(data), "--out", str(out), "--epochs", str(epochs), "--batch-size", "8",
                 "--quiet", "--threads", "1", *extra])


def test_train_logs_checkpoints_and_resumes(synthetic_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert _train(synthetic_data, out, 2) == 0
    rows = list(csv.DictReader((out / "log.csv").open()))
    assert [r["epoch"] for r in rows] == ["0", "1"]
    assert all(np.isfinite(float(r["train_loss"])) for r in rows)
    best = read_file(out / "best.pt")
    assert best["config"]["backbone"] == "stgcnn" and "state_dict" in best
    assert not list(out.glob("*.tmp"))
    # resume continues at epoch 2 instead of starting over
    assert _train(synthetic_data, out, 3, "--resume") == 0
    rows = list(csv.DictReader((out / "log.csv").open()))
    assert [r["epoch"] for r in rows] == ["0", "1", "2"]
    assert read_file(out / "last.pt")["epoch"] == 2


def test_evaluate_writes_json_with_group_metrics(synthetic_data: Path, tmp_path: Path, capsys) -> None:
    torch.manual_seed(0)
    ckpt = tmp_path / "m.pt"
    from predictor.checkpoint import save_model

    save_model(GPGraph(GPGraphConfig(backbone="stgcnn")), ckpt)
    out = tmp_path / "res.json"
    args = ["evaluate", "--checkpoint", str(ckpt), "--data", str(synthetic_data), "--protocol", "paper",
            "--seed", "3", "--trials", "2", "--pool-size", "10", "--json", str(out)]
    assert main(args) == 0
    res = json.loads(out.read_text())
    for key in ("ade", "fde", "col", "tcc", "pw_precision", "pw_recall", "gmitre_precision", "gmitre_recall"):
        assert key in res
    assert res["protocol"] == "paper" and res["seed"] == 3
    assert "ade" in capsys.readouterr().out
    assert main(args) == 0
    assert json.loads(out.read_text())["ade"] == res["ade"]  # same seed, same numbers


def test_protocols_differ_and_are_labelled(synthetic_data: Path) -> None:
    torch.manual_seed(0)
    model = GPGraph(GPGraphConfig(backbone="stgcnn"))
    windows = load_windows(synthetic_data / "test")
    iid = evaluate(model, windows, EvalConfig(protocol="iid", trials=2))
    paper = evaluate(model, windows, EvalConfig(protocol="paper", trials=2, pool_size=20))
    assert iid["protocol"] == "iid" and paper["protocol"] == "paper"
    assert iid["ade"] != paper["ade"]
    assert iid["pedestrians"] == sum(w.n_peds for w in windows)


def test_predict_command(tmp_path: Path) -> None:
    from predictor.checkpoint import save_model

    torch.manual_seed(0)
    ckpt = tmp_path / "m.pt"
    save_model(GPGraph(GPGraphConfig(backbone="stgcnn")), ckpt)
    hist = tmp_path / "h.npy"
    np.save(hist, np.cumsum(np.full((8, 3, 2), 0.4), axis=0) + np.arange(3)[None, :, None])
    out = tmp_path / "p.npz"
    assert main(["predict", "--checkpoint", str(ckpt), "--history", str(hist), "--out", str(out),
                 "--samples", "5"]) == 0
    with np.load(out) as z:
        assert z["samples"].shape == (5, 12, 3, 2) and z["group_id"].shape == (3,)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.npy", "m.pt", "p.npz"]  # exactly --out, no temp left


@pytest.mark.parametrize("case", ["history_dir", "history_text", "history_shape", "out_suffix", "out_under_file",
                                  "out_is_dir"])
def test_predict_misuse_is_one_line_exit_2_and_writes_nothing(tmp_path: Path, capsys, case: str) -> None:
    hist = tmp_path / "h.npy"
    np.save(hist, np.zeros((8, 3, 2)))
    (tmp_path / "notes.txt").write_text("0 1 2.0 3.0\n")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir.npz").mkdir()
    history, out = str(hist), str(tmp_path / "p.npz")
    if case == "history_dir":
        history = str(tmp_path)
    elif case == "history_text":
        history = str(tmp_path / "notes.txt")
    elif case == "history_shape":
        np.save(tmp_path / "flat.npy", np.zeros((8, 3)))
        history = str(tmp_path / "flat.npy")
    elif case == "out_suffix":
        out = str(tmp_path / "p")
    elif case == "out_under_file":
        out = str(tmp_path / "afile" / "p.npz")
    else:
        out = str(tmp_path / "adir.npz")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    code = main(["predict", "--checkpoint", "gpgraph-stgcnn-hotel", "--history", history, "--out", out])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("gpgraph: error:") and err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
    if case == "history_text":
        assert "numpy .npy" in err and "pickle" not in err


def test_cli_reports_errors_cleanly(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad"
    (bad / "test").mkdir(parents=True)
    (bad / "test" / "x.txt").write_text("10 1 0 0\n10 2 oops 0\n")
    ckpt = tmp_path / "cut.pt"
    ckpt.write_bytes(b"PK\x03\x04garbage")
    assert main(["evaluate", "--checkpoint", str(ckpt), "--data", str(bad)]) == 2
    assert "cannot read checkpoint" in capsys.readouterr().err
    torch.manual_seed(0)
    from predictor.checkpoint import save_model

    good = tmp_path / "m.pt"
    save_model(GPGraph(GPGraphConfig(backbone="stgcnn")), good)
    assert main(["evaluate", "--checkpoint", str(good), "--data", str(bad)]) == 2
    assert "x.txt:2" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["evaluate", "--checkpoint", str(good), "--data", str(bad), "--protocol", "bogus"])


def test_cli_evaluates_reference_checkpoint(reference: Path, eth_ucy: Path, tmp_path: Path) -> None:
    out = tmp_path / "hotel.json"
    args = ["evaluate", "--checkpoint", str(reference / "hotel" / "val_best.pth"), "--backbone", "sgcn",
            "--grouping", "official", "--data", str(eth_ucy / "hotel"), "--protocol", "iid", "--trials", "1",
            "--json", str(out), "--threads", "1"]
    assert main(args) == 0
    res = json.loads(out.read_text())
    assert res["pedestrians"] == 1053 and res["grouping"] == "official"
    assert 0.2 < res["ade"] < 0.4 and 0.4 < res["fde"] < 0.75  # reference README: 0.30 / 0.58 (iid)


def test_train_rejects_a_scene_with_one_pedestrian(tmp_path: Path, capsys) -> None:
    for split in ("train", "val"):
        (tmp_path / split).mkdir()
        (tmp_path / split / "solo.txt").write_text("".join(f"{10 * f}\t1\t{0.1 * f}\t0.0\n" for f in range(30)))
    assert _train(tmp_path, tmp_path / "out", 1) == 2
    assert "no windows with >= 2 pedestrians" in capsys.readouterr().err


def test_bce_weight_without_group_labels_is_an_error_and_train_reports_labels(synthetic_data: Path, tmp_path: Path,
                                                                            capsys) -> None:
    """GP-Graph+S's BCE term needs labels: on data without any it is refused, not silently dropped."""
    for f in synthetic_data.rglob("*"):
        if f.name.endswith((".groups.txt", ".labels.tsv")):
            f.unlink()
    assert _train(synthetic_data, tmp_path / "run", 1, "--bce-weight", "1.0") == 2
    err = capsys.readouterr().err
    assert "needs group labels" in err and err.count("\n") == 1
    assert not (tmp_path / "run").exists()
    assert _train(synthetic_data, tmp_path / "run", 1) == 0  # without the term it trains
    assert "group labels in 0 of the training windows" in capsys.readouterr().out


def test_list_prints_every_packaged_name_and_each_loads(capsys) -> None:
    from predictor import load_predictor
    from predictor.checkpoint import PACKAGE_CHECKPOINTS

    assert main(["list"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert len(names) == len(set(names))
    assert set(names) == {p.stem for p in PACKAGE_CHECKPOINTS.glob("*.safetensors")} | {"constant-velocity"}
    assert "gpgraph-stgcnn-synthetic" in names
    load_predictor(names[0]), load_predictor(names[-1])  # the listed names are what load_predictor takes


def test_train_init_starts_from_the_checkpoint_and_records_it(synthetic_data: Path, tmp_path: Path) -> None:
    from predictor.checkpoint import load_model

    out = tmp_path / "ft"
    assert _train(synthetic_data, out, 1, "--backbone", "stgcnn", "--assigner", "pairwise",
                  "--init", "gpgraph-stgcnn-synthetic") == 0
    _, meta = load_model(out / "best.pt")
    assert meta["train"]["init"] == "gpgraph-stgcnn-synthetic"


def synthetic_run(data: Path, tmp: Path) -> Path:
    """best.pt of a one-epoch run on ``data``."""
    assert _train(data, tmp / "ok", 1) == 0
    return tmp / "ok" / "best.pt"


def test_data_and_checkpoints_of_another_step_are_refused(synthetic_data: Path, tmp_path: Path, capsys) -> None:
    """A model is trained and served on the ETH/UCY protocol's 0.4 s steps: crowdsim data recorded at 0.2 s
    is refused before training, and a checkpoint that says it was trained at 0.2 s is refused on loading."""
    import shutil

    from predictor.checkpoint import CheckpointError, load_model, save_model

    data = tmp_path / "data"
    shutil.copytree(synthetic_data, data)
    first = next(p for p in sorted((data / "val").glob("*.txt")) if not p.name.endswith(".groups.txt"))
    first.with_suffix(".json").write_text(json.dumps({"record_dt_s": 0.2}))
    out = tmp_path / "run"
    capsys.readouterr()
    assert _train(data, out, 1) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "recorded every 0.2 s" in err and not out.exists()
    assert read_file(synthetic_run(data=synthetic_data, tmp=tmp_path))["meta"]["step_s"] == 0.4  # training writes it
    ckpt = tmp_path / "m.pt"
    save_model(GPGraph(GPGraphConfig(backbone="stgcnn")), ckpt, meta={"step_s": 0.2})
    with pytest.raises(CheckpointError, match=r"0\.2 s apart"):
        load_model(ckpt)
    assert main(["evaluate", "--checkpoint", str(ckpt), "--data", str(synthetic_data), "--trials", "1"]) == 2
    assert "trained on positions 0.2 s apart" in capsys.readouterr().err
