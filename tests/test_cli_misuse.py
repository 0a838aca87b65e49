"""Every CLI misuse gets one line on stderr and exit 2, no traceback, and nothing is written (all three CLIs).
Also: every option's default shows in `--help`."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from crowdsim.cli import build_parser as crowdsim_parser
from crowdsim.cli import main as crowdsim_main
from envs.cli import build_parser as crowdnav_parser
from envs.cli import main as crowdnav_main
from predictor.cli import build_parser as gpgraph_parser
from predictor.cli import main as gpgraph_main

MAINS = {"crowdnav": crowdnav_main, "gpgraph": gpgraph_main, "crowdsim": crowdsim_main}

# (cli, argv with {tmp} for the case's folder); fixtures there: afile (a file), h.npy (a valid history),
# notes.txt (text), empty/ (a folder), bad.txt (a malformed ETH/UCY file).
CASES = [
    ("crowdnav", "evaluate --policy nope --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --episodes 0 --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --scenario mall --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --mpc safety_margin_m=0.4 --out {tmp}/o"),
    ("crowdnav", "evaluate --policy mpc-cv --mpc bogus_field=1 --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --out {tmp}/afile/o"),
    ("crowdnav", "evaluate --policy random --json {tmp}/empty --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --scenario replay --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --scenario replay --replay-file {tmp}/bad.txt --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --scenario replay --replay-file {tmp}/notes.txt --pedestrians 5 "
                 "--out {tmp}/o"),
    ("crowdnav", "evaluate --policy mpc-cv --predictor gpgraph-stgcnn-hotel --out {tmp}/o"),
    ("crowdnav", "evaluate --polcy random --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --epi 3 --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --replay-file {tmp}/notes.txt --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --workers 0 --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --address auto --out {tmp}/o"),
    ("crowdnav", "evaluate --policy social-force --samples 5 --out {tmp}/o"),
    ("crowdnav", "evaluate --policy random --wall-rays 8 --out {tmp}/o"),
    ("crowdnav", "benchmark --suite smoke --policy mpc-cv --samples 5 --out {tmp}/b"),
    ("crowdnav", "benchmark --suite smoke --policy mpc-cv social-force --threads 2 --out {tmp}/b"),
    ("crowdnav", "benchmark --suite nope --out {tmp}/b"),
    ("crowdnav", "benchmark --suite smoke --cells real-mars --out {tmp}/b"),
    ("crowdnav", "demo --episodes 0 --out {tmp}/d"),
    ("gpgraph", "predict --checkpoint gpgraph-stgcnn-hotel --history {tmp}/empty --out {tmp}/p.npz"),
    ("gpgraph", "predict --checkpoint gpgraph-stgcnn-hotel --history {tmp}/notes.txt --out {tmp}/p.npz"),
    ("gpgraph", "predict --checkpoint gpgraph-stgcnn-hotel --history {tmp}/h.npy --out {tmp}/p"),
    ("gpgraph", "predict --checkpoint gpgraph-stgcnn-hotel --history {tmp}/h.npy --out {tmp}/afile/p.npz"),
    ("gpgraph", "predict --checkpoint no-such-model --history {tmp}/h.npy --out {tmp}/p.npz"),
    ("gpgraph", "predict --checkpoint {tmp}/notes.txt --history {tmp}/h.npy --out {tmp}/p.npz"),
    ("gpgraph", "evaluate --checkpoint no-such-model --data {tmp}/empty"),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/empty"),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/empty --protocol bogus"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --threads 0"),
    ("gpgraph", "groups --groups {tmp}/empty --predictor constant-velocity"),
    ("gpgraph", "groups --groups {tmp}/empty --predictor constant-velocity+nearest"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --epoch 3"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/afile/t"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --resume"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --device cuda"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --device gpu"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --init no-such-checkpoint"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --backbone sgcn --init gpgraph-stgcnn-synthetic"),
    ("gpgraph", "train --data {tmp}/empty --out {tmp}/t --eval-every -1"),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/empty --device cuda --json {tmp}/r.json"),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/empty --json {tmp}/afile/r.json"),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/empty --json {tmp}/new/r.txt"),
    ("crowdnav", "benchmark --suite smoke --out {tmp}/afile/b"),
    ("crowdsim", "generate --scenario mall --out {tmp}/g"),
    ("crowdsim", "generate --duration -5 --out {tmp}/g"),
    ("crowdsim", "generate --duration 0 --out {tmp}/g"),
    ("crowdsim", "generate --pedestrians 0 --out {tmp}/g"),
    ("crowdsim", "generate --scenario corridor --option widht_m=8 --out {tmp}/g"),
    ("crowdsim", "generate --scenario corridor --option width_m=-4 --out {tmp}/g"),
    ("crowdsim", "generate --scenario corridor --option width_m --out {tmp}/g"),
    ("crowdsim", "generate --out {tmp}/afile/g"),
    ("crowdsim", "generate --duration abc --out {tmp}/g"),
    ("crowdsim", "dataset --scenarios , --out {tmp}/ds"),
    ("crowdsim", "dataset --seeds-per-scenario 1 --out {tmp}/ds"),
    ("crowdsim", "dataset --address auto --out {tmp}/ds"),
    ("crowdsim", "dataset --workers 0 --out {tmp}/ds"),
    ("crowdsim", "dataset --preset realistic-v1 --pedestrians 30 --out {tmp}/ds"),
    ("crowdsim", "dataset --preset realistic-v1 --option width_m=5 --out {tmp}/ds"),
    ("crowdsim", "dataset --preset realistic-v1 --scenarios open --out {tmp}/ds"),
    ("crowdsim", "dataset --preset realistic --out {tmp}/ds"),
]


def _fixtures(tmp):
    (tmp / "afile").write_text("x")
    np.save(tmp / "h.npy", np.cumsum(np.full((8, 3, 2), 0.4), axis=0))
    (tmp / "notes.txt").write_text("these are notes\n")
    (tmp / "empty").mkdir()
    (tmp / "bad.txt").write_text("0 1 0.0 0.0\n0 1 1.0 1.0\n")  # pedestrian 1 twice in frame 0


def _snapshot(tmp):
    return sorted((str(p.relative_to(tmp)), p.stat().st_size if p.is_file() else -1) for p in tmp.rglob("*"))


def test_there_are_at_least_30_cases():
    assert len(CASES) >= 30 and {cli for cli, _ in CASES} == set(MAINS)


def _misuse(tmp_path, capsys, cli: str, argv: str) -> str:
    """The one error line of a misuse, after checking: exit 2, one line on stderr, no traceback, nothing written."""
    _fixtures(tmp_path)
    before = _snapshot(tmp_path)
    try:
        code = MAINS[cli](argv.format(tmp=tmp_path).split())
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (out, err)
    assert len(lines) == 1 and lines[0].startswith(cli) and "error" in lines[0], err
    assert "Traceback" not in err + out
    assert _snapshot(tmp_path) == before
    return lines[0]


@pytest.mark.parametrize("cli, argv", CASES, ids=[f"{c}: {a.split(' --out')[0]}" for c, a in CASES])
def test_misuse_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, cli, argv):
    _misuse(tmp_path, capsys, cli, argv)


# (cli, argv, what the line must say): the flag as the user typed it (not a config field's name), the path of an OS
# error next to its flag, and for a misspelt name the closest valid one
SPOKEN = [
    ("crowdnav", "evaluate --policy random --pedestrians -3 --out {tmp}/o", "--pedestrians must be >= 1, got -3"),
    ("crowdnav", "evaluate --policy random --time-limit -3 --out {tmp}/o", "--time-limit must be"),
    ("crowdnav", "evaluate --policy ppo-crowdnav --wall-rays -1 --out {tmp}/o", "--wall-rays must be >= 0, got -1"),
    ("crowdnav", "evaluate --policy random --fov-deg 0 --out {tmp}/o", "--fov-deg must be in (0, 360] degrees"),
    ("crowdnav", "evaluate --policy random --fov-deg 400 --out {tmp}/o", "--fov-deg must be in (0, 360] degrees"),
    ("crowdnav", "evaluate --policy random --fov-deg nan --out {tmp}/o", "--fov-deg must be in (0, 360] degrees"),
    ("crowdnav", "evaluate --policy mpc-gpgraph --samples 0 --out {tmp}/o", "--samples must be >= 1, got 0"),
    ("crowdnav", "evaluate --policy mpc-gpgraph --threads 0 --out {tmp}/o", "--threads must be >= 1, got 0"),
    ("crowdnav", "evaluate --policy random --scenario replay --replay-file {tmp}/nope.txt --out {tmp}/o",
     "--replay-file {tmp}/nope.txt: no such file"),
    ("crowdnav", "evaluate --policy random --scenario replay --replay-file {tmp}/bad.txt --groups-file {tmp}/no.txt "
                 "--out {tmp}/o", "--groups-file {tmp}/no.txt: no such file"),
    ("crowdnav", "evaluate --policy mpc-cvv --out {tmp}/o", "unknown policy 'mpc-cvv'; did you mean 'mpc-cv'? valid"),
    ("crowdnav", "evaluate --policy random --scenario plazza --out {tmp}/o", "did you mean 'plaza'? valid names"),
    ("crowdnav", "evaluate --policy random --crowd-model orcaa --out {tmp}/o", "did you mean 'orca'?"),
    ("crowdnav", "evaluate --policy mpc-gpgraph --predictor gpgraph-stgcnn-hotell --out {tmp}/o",
     "did you mean 'gpgraph-stgcnn-hotel'?"),
    ("crowdnav", "evaluate --policy mpc-gpgraph --predictor gpgraph-stgcnn-hotel+coherent-motin --out {tmp}/o",
     "did you mean 'coherent-motion'?"),
    ("crowdnav", "evaluate --policy mpc-cv --mpc safety_margn_m=0.3 --out {tmp}/o", "did you mean 'safety_margin_m'?"),
    ("crowdnav", "evaluate --policy random --epi 3 --out {tmp}/o", "did you mean '--episodes'?"),
    ("crowdnav", "evaluate --policy random --group-overlaps merg --out {tmp}/o", "did you mean 'merge'?"),
    ("crowdnav", "benchmark --suite smok --out {tmp}/b", "unknown suite 'smok'; did you mean 'smoke'? valid names"),
    ("crowdnav", "benchmark --suite smoke --cells corridor-low-visibl --out {tmp}/b",
     "did you mean 'corridor-low-visible'?"),
    ("crowdnav", "bounds --suite smoke --cells-per-step 0 --out {tmp}/b", "--cells-per-step must"),
    ("crowdnav", "demo --predictor gpgraph-stgcnn-synthtic --out {tmp}/d", "did you mean 'gpgraph-stgcnn-synthetic'?"),
    ("gpgraph", "predict --checkpoint gpgraph-stgcnn-hotell --history {tmp}/h.npy --out {tmp}/p.npz",
     "did you mean 'gpgraph-stgcnn-hotel'?"),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/nope",
     "--data: no such data folder: {tmp}/nope"),
    ("gpgraph", "groups --groups {tmp}/nope --predictor constant-velocity", "--groups: "),
    ("gpgraph", "evaluate --checkpoint gpgraph-stgcnn-hotel --data {tmp}/empty --protocol papr",
     "did you mean 'paper'?"),
    ("gpgraph", "predict --checkpont gpgraph-stgcnn-hotel --history {tmp}/h.npy --out {tmp}/p.npz",
     "did you mean '--checkpoint'?"),
    ("crowdsim", "generate --pedestrians -3 --out {tmp}/g", "--pedestrians must be >= 1, got -3"),
    ("crowdsim", "generate --scenario plazza --out {tmp}/g", "unknown scenario 'plazza'; did you mean 'plaza'? valid"),
    ("crowdsim", "generate --scenario corridor --option widht_m=8 --out {tmp}/g", "did you mean 'width_m'?"),
    ("crowdsim", "dataset --preset realistc --out {tmp}/ds", "did you mean 'realistic-v1'?"),
    ("crowdsim", "generate --scenaro plaza --out {tmp}/g", "did you mean '--scenario'?"),
    ("crowdnav", "evaluate --polcy random --out {tmp}/o", "required: --policy; did you mean '--policy'?"),
]


@pytest.mark.parametrize("cli, argv, says", SPOKEN, ids=[f"{c}: {a.split(' --out')[0]}" for c, a, _ in SPOKEN])
def test_misuse_speaks_in_flags_and_suggests_the_name_meant(tmp_path, capsys, cli, argv, says):
    line = _misuse(tmp_path, capsys, cli, argv)
    assert says.format(tmp=tmp_path) in line, line
    assert "Errno" not in line and "n_pedestrians" not in line and "Config." not in line


def test_the_registries_suggest_the_name_meant():
    """Not only the CLIs: each registry's own error names the closest valid name and lists them all."""
    from crowdsim.presets import get_preset
    from crowdsim.scenarios import check_options
    from envs.crowds.models import check_crowd_model
    from envs.evaluation.suite import load_suite
    from envs.policies import PolicyConfig
    from predictor.checkpoint import resolve
    from predictor.group_rules import get_rule

    for call, says in ((lambda: PolicyConfig("socal-force"), "did you mean 'social-force'? valid names: mpc-gpgraph"),
                       (lambda: PolicyConfig("MPC-CV+shield"), "did you mean 'mpc-cv'?"),
                       (lambda: load_suite("crowdnav-v2"), "did you mean 'crowdnav-v1'? valid names: "),
                       (lambda: load_suite("smoke").cell("real-hotl"), "did you mean 'real-hotel'?"),
                       (lambda: get_preset("realistic-v2"), "did you mean 'realistic-v1'?"),
                       (lambda: check_options("cooridor", {}), "did you mean 'corridor'?"),
                       (lambda: check_crowd_model("social_force", "plaza"), "did you mean 'social-force'?"),
                       (lambda: get_rule("proximity-lst"), "did you mean 'proximity-last'?"),
                       (lambda: resolve("stgcnn-zra1"), "did you mean 'stgcnn-zara1'?")):
        with pytest.raises(ValueError) as info:
            call()
        assert says in str(info.value), str(info.value)
    with pytest.raises(ValueError) as info:
        load_suite("qwerty")
    assert "did you mean" not in str(info.value) and "valid names: crowdnav-classic" in str(info.value)


def _options(parser: argparse.ArgumentParser):
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        yield name, command, [a for a in command._actions if a.option_strings and a.dest != "help"
                              and not a.required and a.default is not argparse.SUPPRESS]


@pytest.mark.parametrize("build", [crowdnav_parser, gpgraph_parser, crowdsim_parser])
def test_help_shows_every_default(build):
    for name, command, options in _options(build()):
        # ArgumentDefaultsHelpFormatter appends "(default: ...)" to every option that has help text
        assert issubclass(command.formatter_class, argparse.ArgumentDefaultsHelpFormatter), name
        assert all(a.help and a.help.strip() for a in options), name
        text = " ".join(command.format_help().split())  # undo line wrapping
        for a in options:
            assert f"{a.option_strings[-1]}" in text and "(default: " in text.split(a.option_strings[-1], 1)[1], \
                (name, a.option_strings)


def test_os_errors_name_their_flag_and_both_copies_of_the_helpers_agree():
    """crowdsim.names and predictor.names (the packages do not import each other) say the same things."""
    from pathlib import Path

    import crowdsim.names as a
    import predictor.names as b

    missing = FileNotFoundError(2, "No such file or directory", "data/x.txt")
    flags = {"--out": Path("o"), "--merge": [Path("m.jsonl"), Path("data/x.txt")], "--episodes": 3}
    for names in (a, b):
        assert names.os_error_line(missing, flags) == "--merge data/x.txt: no such file or directory"
        assert names.os_error_line(missing, {}) == "data/x.txt: no such file or directory"
        assert names.os_error_line(FileNotFoundError("no such data folder: o"), flags) == \
            "--out: no such data folder: o"
        assert names.unknown_name("policy", "rndom", ["random", "orca"]) == \
            "unknown policy 'rndom'; did you mean 'random'? valid names: random, orca"
        assert names.did_you_mean("zzz", ["random"]) == "" and names.closest("--epi", ["--help", "--episodes"]) == \
            "--episodes"
