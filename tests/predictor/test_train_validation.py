"""What `gpgraph train` validates on (never its training windows) and what Ctrl-C leaves (one line, exit 130, a
resumable last.pt), as a user meets them: on the command line and in a real interrupted process."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from predictor.checkpoint import read_file
from predictor.cli import main
from predictor.data import read_recording
from predictor.train_split import holdout_windows, split_recording
from predictor.windows import recording_windows
from tests.cli_helpers import terminal_sigint
from tests.predictor.conftest import write_synthetic_split

ROOT = Path(__file__).resolve().parents[2]


def _train(data: Path, out: Path, *extra: str) -> int:
    return main(["train", "--data", str(data), "--out", str(out), "--epochs", "1", "--batch-size", "8", "--quiet",
                 *extra])


def _frames(windows: list) -> set[float]:
    """Every frame id a window covers (stride 1 in the synthetic recording's 10-frame steps)."""
    return {w.start_frame + 10 * k for w in windows for k in range(20)}


def test_a_folder_without_val_is_an_error_that_names_the_fix_and_writes_nothing(tmp_path: Path, capsys) -> None:
    write_synthetic_split(tmp_path / "flat", n_frames=60)
    assert _train(tmp_path / "flat", tmp_path / "run") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has no val/ folder" in err and "--val-fraction" in err
    assert not (tmp_path / "run").exists()
    assert _train(tmp_path / "flat", tmp_path / "run", "--val-fraction", "0.9") == 2  # most of the data: refused
    assert "must be in (0, 0.5]" in capsys.readouterr().err and not (tmp_path / "run").exists()
    (tmp_path / "split" / "val").mkdir(parents=True)  # ... and the same with train/ but no val/ files
    write_synthetic_split(tmp_path / "split" / "train", n_frames=60)
    (tmp_path / "split" / "val").rmdir()
    assert _train(tmp_path / "split", tmp_path / "run") == 2
    assert "has no val/ folder" in capsys.readouterr().err and not (tmp_path / "run").exists()


def test_val_fraction_holds_out_the_end_of_each_recording_without_shared_frames(tmp_path: Path) -> None:
    write_synthetic_split(tmp_path / "flat", n_frames=100)
    rec = read_recording(tmp_path / "flat" / "sim.txt")
    early, late = split_recording(rec, 0.2)
    assert early.rows[:, 0].max() < late.rows[:, 0].min()  # one cut in time
    assert len(np.unique(late.rows[:, 0])) == 20 and len(early.rows) + len(late.rows) == len(rec.rows)
    train, val = holdout_windows(tmp_path / "flat", 0.2)
    assert len(train) == 80 - 19 and len(val) == 1  # each part cut alone: 81 - 20 + 1 frames lost to the cut
    assert not _frames(train) & _frames(val)  # no position is both trained on and validated on
    assert len(recording_windows(rec)) == 81 > len(train) + len(val)
    with pytest.raises(ValueError, match=r"must be in \(0, 0\.5\]"):
        holdout_windows(tmp_path / "flat", 0.9)


def test_val_fraction_trains_and_says_where_it_validates(tmp_path: Path, capsys) -> None:
    write_synthetic_split(tmp_path / "flat", n_frames=100)
    assert _train(tmp_path / "flat", tmp_path / "run", "--val-fraction", "0.25") == 0
    out = capsys.readouterr().out  # 75 frames give 75 - 19 windows, 25 give 6
    assert "56 training / 6 validation windows (validation: the last 0.25 of each recording's frames" in out
    meta = read_file(tmp_path / "run" / "best.pt")["meta"]
    assert meta["epoch"] == 0 and meta["train"]["val_fraction"] == 0.25  # the checkpoint says what chose it
    write_synthetic_split(tmp_path / "split" / "train")  # a val/ folder is used, and a fraction beside it refused
    write_synthetic_split(tmp_path / "split" / "val", seed=1)
    assert _train(tmp_path / "split", tmp_path / "run2", "--val-fraction", "0.25") == 2
    assert "has its own val/ split" in capsys.readouterr().err and not (tmp_path / "run2").exists()


def _epochs(out: Path) -> list[int]:
    with (out / "log.csv").open(newline="") as f:
        return [int(r["epoch"]) for r in csv.DictReader(f)]


@pytest.mark.slow
def test_ctrl_c_in_train_is_one_line_exit_130_and_resume_continues(synthetic_data: Path, tmp_path: Path) -> None:
    """A real process, interrupted as a terminal does (SIGINT to its process group) once an epoch is saved."""
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "predictor.cli", "train", "--data", str(synthetic_data), "--out", str(out),
            "--batch-size", "8", "--quiet", "--eval-every", "0"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([*argv, "--epochs", "100000"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=terminal_sigint)
    deadline = time.monotonic() + 120
    while not (out / "last.pt").is_file() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    done = int(read_file(out / "last.pt")["epoch"])
    assert err.splitlines() == [f"gpgraph: interrupted: epochs up to {done} saved in {out / 'last.pt'} (best.pt: "
                                f"the lowest validation loss so far); rerun the command with --resume to continue "
                                f"at epoch {done + 1}"]
    assert _epochs(out)[: done + 1] == list(range(done + 1))  # (a row of an unsaved epoch may follow: dropped below)
    resumed = subprocess.run([*argv, "--epochs", str(done + 2), "--resume"], env=env, capture_output=True,
                             text=True, timeout=120)
    assert resumed.returncode == 0, resumed.stderr
    assert _epochs(out) == list(range(done + 2)) and int(read_file(out / "last.pt")["epoch"]) == done + 1
