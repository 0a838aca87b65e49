"""Every crowdsim command that writes checks its output folder before any work: one line on stderr, exit 2,
nothing written, nothing simulated."""

from __future__ import annotations

from pathlib import Path

import pytest

import crowdsim.cli as cli

SMALL = ["--pedestrians", "4", "--duration", "1", "--warmup", "0"]
COMMANDS = {
    "generate": ["generate", *SMALL],
    "dataset": ["dataset", "--scenarios", "corridor", "--seeds-per-scenario", "3", *SMALL],
    "demo": ["demo"],
}


@pytest.fixture
def no_work(monkeypatch):
    """Simulating or writing a dataset fails the test."""
    def forbidden(*args, **kwargs):
        raise AssertionError("work started before the output path was checked")

    monkeypatch.setattr(cli, "generate", forbidden)
    monkeypatch.setattr(cli, "make_dataset", forbidden)


def _tree(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*"))


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_unwritable_out_is_one_line_exit_2(command, capsys, no_work):
    assert cli.main([*COMMANDS[command], "--out", "/proc/crowdsim-test/x"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1  # the reason (errno text) may vary by kernel
    assert err.startswith("crowdsim: error: --out /proc/crowdsim-test/x: cannot create folders in /proc (")
    assert not Path("/proc/crowdsim-test").exists()


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_out_under_a_file_is_one_line_exit_2(command, tmp_path, capsys, no_work):
    (tmp_path / "a_file").write_text("x")
    assert cli.main([*COMMANDS[command], "--out", str(tmp_path / "a_file" / "out")]) == 2
    out, bad = tmp_path / "a_file" / "out", tmp_path / "a_file"
    assert capsys.readouterr().err == f"crowdsim: error: --out {out}: {bad} is a file, not a folder\n"
    assert _tree(tmp_path) == ["a_file"]


def test_dataset_split_folder_that_is_a_file(tmp_path, capsys, no_work):
    (tmp_path / "val").write_text("x")
    assert cli.main([*COMMANDS["dataset"], "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"crowdsim: error: --out {tmp_path}: {tmp_path / 'val'} is a file, not a folder\n"
    assert _tree(tmp_path) == ["val"]


def test_a_writable_out_passes_and_the_probe_leaves_nothing(tmp_path):
    cli._check_out_dir(tmp_path / "new" / "deeper", cli.SPLITS)
    assert _tree(tmp_path) == []


def test_console_script_names_the_venv_path_when_the_venv_is_not_activated(tmp_path, monkeypatch):
    """`crowdnav demo` / `crowdsim demo` say how to view the recording: `rerun` on PATH, else the script's path
    beside this Python (a user who ran `make demo` and has not activated .venv)."""
    import sys

    from crowdsim.cli import console_script

    bindir = tmp_path / "venv" / "bin"
    bindir.mkdir(parents=True)
    (bindir / "rerun").write_text("#!/bin/sh\n")
    (bindir / "rerun").chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(bindir / "python"))
    monkeypatch.setenv("PATH", str(tmp_path / "nothing-here"))
    assert console_script("rerun") == str(bindir / "rerun")
    assert console_script("no-such-script") == "no-such-script"
    monkeypatch.setenv("PATH", str(bindir))
    assert console_script("rerun") == "rerun"
