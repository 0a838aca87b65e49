"""Ctrl-C in every command of the three CLIs: one line on stderr, exit 130, no traceback. Here the command's work
is replaced by a KeyboardInterrupt (what Ctrl-C raises); real interrupted processes, and what each keeps, are in
tests/predictor/test_train_validation.py, tests/envs/test_train_interrupt.py, tests/envs/test_interrupt.py and
tests/crowdsim/test_interrupt.py."""

from __future__ import annotations

import pytest

import crowdsim.cli
import envs.cli
import predictor.cli

# (cli, argv, module, the function that does the command's work there)
COMMANDS = [
    ("gpgraph", "train --data d --out o", predictor.cli, "cmd_train"),
    ("gpgraph", "evaluate --checkpoint c --data d", predictor.cli, "cmd_evaluate"),
    ("gpgraph", "predict --checkpoint c --history h.npy --out p.npz", predictor.cli, "cmd_predict"),
    ("gpgraph", "interpolate --start a --end b --alpha 0.5 --out w.pt", predictor.cli, "cmd_interpolate"),
    ("gpgraph", "groups --groups g --predictor constant-velocity", predictor.cli, "cmd_groups"),
    ("gpgraph", "list", predictor.cli, "cmd_list"),
    ("crowdnav", "evaluate --policy random", envs.cli, "_evaluate"),
    ("crowdnav", "benchmark --suite smoke --out o", envs.cli, "_benchmark"),
    ("crowdnav", "bounds --suite smoke --out o", envs.cli, "_bounds"),
    ("crowdnav", "demo", envs.cli, "_demo"),
    ("crowdnav", "train", envs.cli, "_train"),
    ("crowdnav", "policies", envs.cli, "_list"),
    ("crowdnav", "suites", envs.cli, "_list"),
    ("crowdsim", "generate --scenario corridor --out o", crowdsim.cli, "generate"),
    ("crowdsim", "dataset --out o", crowdsim.cli, "_dataset"),
    ("crowdsim", "demo --out o", crowdsim.cli, "generate"),
    ("crowdsim", "scenarios", crowdsim.cli, "_run"),  # the dispatcher: listing has no function of its own
    ("crowdsim", "presets", crowdsim.cli, "_run"),
]
MAINS = {"gpgraph": predictor.cli.main, "crowdnav": envs.cli.main, "crowdsim": crowdsim.cli.main}


def _ctrl_c(*args, **kwargs):
    raise KeyboardInterrupt


@pytest.mark.parametrize("cli, argv, module, name", COMMANDS, ids=[f"{c} {a.split()[0]}" for c, a, _, _ in COMMANDS])
def test_ctrl_c_in_every_command_is_one_line_and_exit_130(cli, argv, module, name, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(module, name, _ctrl_c)
    assert MAINS[cli](argv.split()) == 130
    out, err = capsys.readouterr()
    assert len(err.splitlines()) == 1 and err.startswith(f"{cli}: interrupted"), err
    assert "Traceback" not in out + err
