"""Ctrl-C in a crowdsim command: one line on stderr, exit 130, no traceback; what is on disk is complete."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

import crowdsim.generate as generate_module
from crowdsim.cli import main

SMALL = ["--pedestrians", "5", "--duration", "2", "--warmup", "0"]


def test_dataset_interrupted_keeps_the_finished_recordings(tmp_path, monkeypatch, capsys):
    real = generate_module.render_job

    def render_then_ctrl_c(job):
        if job.spec.seed == 1:
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(generate_module, "render_job", render_then_ctrl_c)
    out = tmp_path / "ds"
    code = main(["dataset", "--scenarios", "corridor", "--seeds-per-scenario", "3", *SMALL, "--out", str(out)])
    assert code == 130
    err = [ln for ln in capsys.readouterr().err.replace("\r", "\n").splitlines() if ln.startswith("crowdsim")]
    assert err == [f"crowdsim: interrupted: 1 of 3 recordings written to {out} (each complete, the others absent); "
                   "rerun the command to make them all"]
    assert sorted(p.name for p in out.rglob("*") if p.is_file()) == [
        "corridor_n5_s0.groups.txt", "corridor_n5_s0.json", "corridor_n5_s0.labels.tsv", "corridor_n5_s0.txt"]


def test_generate_interrupted_leaves_no_partial_rerun_recording(tmp_path, monkeypatch, capsys):
    from crowdsim.recording import RrdRecorder

    frames = []

    def log_then_ctrl_c(self, state):
        frames.append(state.frame)
        if len(frames) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(RrdRecorder, "log_frame", log_then_ctrl_c)
    assert main(["generate", "--scenario", "plaza", *SMALL, "--rrd", "--out", str(tmp_path / "g")]) == 130
    assert capsys.readouterr().err.replace("\r", "\n").splitlines()[-1] == "crowdsim: interrupted: generate stopped"
    assert len(frames) == 3 and not [p for p in (tmp_path / "g").rglob("*") if p.is_file()]


@pytest.mark.slow
def test_a_real_ctrl_c_stops_a_worker_pool_with_one_line(tmp_path):
    """SIGINT to the whole process group (what a terminal's Ctrl-C does) while 2 workers simulate."""
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "crowdsim.cli", "dataset", "--scenarios", "corridor,plaza", "--seeds-per-scenario",
           "4", "--pedestrians", "40", "--duration", "900", "--workers", "2", "--out", str(out)]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(4)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and not ln.startswith("dataset:")]
    assert proc.returncode == 130, err[-2000:]
    assert len(lines) == 1 and lines[0].startswith("crowdsim: interrupted: ") and "Traceback" not in err
    written = int(lines[0].split()[2])
    assert len(list(out.rglob("*.json"))) == written and not list(out.rglob("*.tmp"))


def test_write_files_is_whole_or_nothing(tmp_path, monkeypatch):
    """A Ctrl-C between a recording's files removes the ones already written (and the temporary file)."""
    import crowdsim.export as export
    import crowdsim.files as files_module  # where the atomic rename lives

    real, calls = files_module.os.replace, []

    def replace_then_ctrl_c(src, dst):
        calls.append(dst)
        if len(calls) == 3:
            raise KeyboardInterrupt
        real(src, dst)

    monkeypatch.setattr(files_module.os, "replace", replace_then_ctrl_c)
    files = {k: (f"r.{k}", f"{k}\n") for k in ("trajectories", "groups", "labels", "metadata")}
    with pytest.raises(KeyboardInterrupt):
        export.write_files(tmp_path, files)
    assert len(calls) == 3 and list(tmp_path.iterdir()) == []
    monkeypatch.setattr(files_module.os, "replace", real)
    assert sorted(p.name for p in export.write_files(tmp_path, files).values()) == sorted(
        f"r.{k}" for k in files)
