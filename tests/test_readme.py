"""The README and the reference pages in docs/ as tested documents: every Python block runs as written, prints
what it made, and does what its comments say; every `crowdsim` / `gpgraph` / `crowdnav` command parses and runs."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
# The README, then the per-package reference moved out of it (each block and command is tested the same way).
DOCS = [README, *(ROOT / "docs" / f"{name}.md" for name in ("crowdsim", "predictor", "planner", "envs", "rl", "data"))]


def python_blocks() -> list[tuple[str, str]]:
    """(file name, code) of every ```python block of the documents, in order."""
    return [(doc.name if doc == README else f"docs/{doc.name}", code) for doc in DOCS
            for code in re.findall(r"^```python\n(.*?)^```", doc.read_text(), flags=re.S | re.M)]


def _block(first_line: str) -> tuple[str, str]:
    found = [b for b in python_blocks() if first_line in b[1]]
    assert len(found) == 1, f"no single documented block containing {first_line!r}"
    return found[0]


def _run(block: tuple[str, str], tmp_path: Path, monkeypatch) -> dict:
    monkeypatch.chdir(tmp_path)  # blocks that write files write here
    namespace: dict = {"__name__": "readme_block"}
    exec(compile(block[1], block[0], "exec"), namespace)
    return namespace


def test_every_python_block_is_covered_here():
    where = [name for name, _ in python_blocks()]
    # README: one episode, the plug-in (tests/envs/test_plugins.py); docs: crowdsim, predictor, planner, env
    assert where == ["README.md", "README.md", "docs/crowdsim.md", "docs/predictor.md", "docs/planner.md",
                     "docs/envs.md"]


def test_the_readme_is_short_and_its_links_resolve():
    assert len(README.read_text().splitlines()) <= 200
    for doc in [*DOCS, *sorted((ROOT / "docs").rglob("*.md")), ROOT / "RESULTS.md", ROOT / "BENCHMARKS.md"]:
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", doc.read_text()):
            if "://" not in target:
                assert (doc.parent / target).exists(), f"{doc.relative_to(ROOT)} links to missing {target}"


def test_episode_block(tmp_path, monkeypatch, capsys):
    ns = _run(_block("from envs.evaluation.evaluate import evaluate"), tmp_path, monkeypatch)
    assert ns["result"]["episodes"] == 1 and ns["episode"]["outcome"] in ("success", "collision", "timeout")
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert re.fullmatch(r"mpc-cv, plaza, seed 0: (success|collision|timeout) after \d+\.\d s, "
                        r"closest person -?\d+\.\d\d m, \d+ plans", line), line


def test_crowdsim_block(tmp_path, monkeypatch, capsys):
    ns = _run(_block("from crowdsim import CrowdSimulator"), tmp_path, monkeypatch)
    state = ns["state"]
    assert state.pos.shape[1] == 2 and state.active.sum() == 40 and np.isfinite(state.pos[state.active]).all()
    groups = int(state.group_id[state.active].max()) + 1
    assert capsys.readouterr().out == f"40 pedestrians in {groups} groups after 40 s\n" and 1 < groups < 40


def test_planner_block(tmp_path, monkeypatch, capsys):
    ns = _run(_block("from planner import MPCConfig"), tmp_path, monkeypatch)
    assert ns["result"].status == "solved" and ns["result"].control.shape == (2,)
    assert ns["state"][0] > 0.0  # the robot moved towards the goal at +x
    assert "solved" in capsys.readouterr().out
    assert callable(ns["baseline"].plan)


def test_predictor_block_feeds_the_planner(tmp_path, monkeypatch, capsys):
    ns = _run(_block("from predictor import load_predictor"), tmp_path, monkeypatch)
    assert ns["out"].samples.shape == (20, 12, 3, 2) and ns["result"].status == "solved"
    groups = int(ns["out"].group_id.max()) + 1
    assert capsys.readouterr().out == f"20 futures of 3 pedestrians in {groups} predicted groups; plan solved\n"
    np.testing.assert_array_equal(np.load(tmp_path / "out" / "hist.npy"), ns["history"])
    # ... and the documented `gpgraph predict` line runs as written on that file
    from predictor.cli import main

    (argv,) = [c for c in cli_commands() if c[:2] == ["gpgraph", "predict"]]
    assert main(argv[1:]) == 0
    with np.load(tmp_path / "out" / "pred.npz") as z:
        assert z["samples"].shape == (20, 12, 3, 2)


def test_env_block(tmp_path, monkeypatch, capsys):
    ns = _run(_block("import gymnasium as gym"), tmp_path, monkeypatch)
    assert ns["reward"] == pytest.approx(sum(ns["info"]["reward_terms"].values()))
    assert ns["frame"].shape == (480, 480, 3) and ns["frame"].dtype == np.uint8
    seen, terms = int(ns["obs"]["pedestrian_mask"].sum()), len(ns["info"]["reward_terms"])
    assert capsys.readouterr().out == (f"{seen} pedestrians in view; reward {ns['reward']:+.3f} from {terms} terms; "
                                       f"frame (480, 480, 3)\n") and 0 < seen <= 20


def cli_commands() -> list[list[str]]:
    """Every `crowdsim` / `gpgraph` / `crowdnav` command in the bash blocks of the README and docs/, as argv
    lists, each once, in order; optional parts shown in [brackets] are included (without the brackets),
    comments dropped."""
    import shlex

    commands = []
    for doc in DOCS:
        for block in re.findall(r"^```bash\n(.*?)^```", doc.read_text(), flags=re.S | re.M):
            for line in block.replace("\\\n", " ").splitlines():
                tokens = shlex.split(line.split(" #")[0].replace("[", " ").replace("]", " "))
                if tokens and tokens[0] in ("crowdsim", "gpgraph", "crowdnav") and tokens not in commands:
                    commands.append(tokens)
    return commands


def test_every_readme_command_line_is_a_valid_invocation():
    """Each documented command parses with its CLI as written (options exist, values have the right types)."""
    from crowdsim.cli import build_parser as crowdsim_parser
    from envs.cli import build_parser as crowdnav_parser
    from predictor.cli import build_parser as gpgraph_parser

    parsers = {"crowdsim": crowdsim_parser, "gpgraph": gpgraph_parser, "crowdnav": crowdnav_parser}
    commands = cli_commands()
    assert {c[0] for c in commands} == set(parsers) and len(commands) >= 15
    for argv in commands:
        parsers[argv[0]]().parse_args(argv[1:])  # SystemExit (exit 2) on any unknown or malformed option


def test_training_docs_show_the_smallest_run_first():
    """A new user meets a one-minute training run before the full-size recipe (hours), in each training page; the
    run-with-small-sizes test below runs both."""
    for doc, command, small in (("predictor", ["gpgraph", "train"], "--max-windows"),
                                ("rl", ["crowdnav", "train"], "--quick")):
        runs = [c for c in cli_commands() if c[:2] == command]  # in the order of README, then docs/ pages
        assert small in runs[0] and small not in runs[1], (doc, runs[:2])  # the smallest, then the full-size one


# Shortened only through documented options (README: "Every command of this README and of docs/ runs in the test
# suite with small sizes").
SMALL = {"--duration": "6", "--pedestrians": "8", "--seeds-per-scenario": "3", "--episodes": "1", "--workers": "1",
         "--epochs": "1", "--trials": "1", "--record": "0", "--time-limit": "4"}
ADD = {("gpgraph", "train"): ["--max-windows", "16", "--quiet"], ("crowdnav", "benchmark"): ["--no-progress"],
       ("crowdnav", "evaluate"): ["--no-progress"], ("crowdnav", "demo"): ["--episodes", "1", "--workers", "1",
                                                                          "--no-progress"]}


def _small(argv: list[str], shared: Path, tmp_path: Path) -> list[str] | None:
    """The documented command with small sizes, the shared data's real path, and a real recording for `rec.txt`;
    None for what cannot run here (a Ray cluster address). `--backend ray` runs on the default local pool here
    (Ray itself is tested in tests/envs/test_benchmark.py and tests/crowdsim/test_distributed.py)."""
    if "--address" in argv:
        return None
    if "--backend" in argv:
        k = argv.index("--backend")
        argv = argv[:k] + argv[k + 2:]
    out = []
    for i, tok in enumerate(argv):
        prev = argv[i - 1] if i else ""
        if prev in SMALL:
            tok = SMALL[prev]
        tok = tok.replace("../shared", str(shared))
        if tok in ("rec.txt", "groups.txt"):
            tok = str(tmp_path / tok)
        out.append(tok)
    if argv[:2] == ["crowdnav", "train"]:  # a few hundred steps; a cheap expert for the warm start
        steps = "512" if "--resume" in argv else "256"
        out = [steps if prev == "--steps" else tok for prev, tok in zip(["", *out[:-1]], out, strict=True)]
        if "--resume" not in argv:
            out += [] if "--steps" in argv else ["--steps", "256"]  # --quick's 4096 steps are a minute
            out += ["--envs", "2", "--n-steps", "128", "--batch-size", "64", "--n-epochs", "1", "--eval-episodes", "1",
                    "--eval-every-steps", "256", "--demo-episodes", "1", "--dagger-rounds", "1", "--dagger-episodes",
                    "1", "--bc-epochs", "1", "--demo-policy", "mpc-cv"]
    if argv[:2] == ["crowdnav", "bounds"]:  # the smoke suite's invisible-robot cell (16 s episodes)
        out[out.index("--suite") + 1] = "smoke"
        out = [*out[:out.index("--cells")], *out[out.index("--cells") + 2:]] if "--cells" in out else out
        out += ["--cells", "circle-low-invisible", "--no-progress"]
    if argv[:2] == ["crowdnav", "benchmark"]:  # the smallest cell of the suite (or the smoke suite) and cheap policies
        if "--cells" in out:
            out[out.index("--cells") + 1] = "corridor-low-visible"
        start = out.index("--policy") + 1
        stop = next((i for i in range(start, len(out)) if out[i].startswith("--")), len(out))
        out[start:stop] = ["mpc-cv", "social-force"]
    return out + ADD.get(tuple(argv[:2]), [])


@pytest.mark.slow
@pytest.mark.timeout(900)  # ~210 s alone on the 2-core machine; the suite's 300 s guard killed it under load
def test_every_readme_command_runs_with_small_sizes(tmp_path, monkeypatch, capsys):
    from crowdsim.cli import main as crowdsim_main
    from envs.cli import main as crowdnav_main
    from predictor.cli import main as gpgraph_main

    shared = Path(__file__).resolve().parents[1].parent / "shared"
    hotel = shared / "datasets/eth_ucy/hotel/test/biwi_hotel.txt"
    if not hotel.is_file():
        pytest.skip("../shared/datasets is not here")
    (tmp_path / "rec.txt").write_text(hotel.read_text())
    (tmp_path / "groups.txt").write_text("")
    (tmp_path / "my_room.toml").write_text(toml_block())  # the scenario file docs/crowdsim.md shows, as shown
    monkeypatch.chdir(tmp_path)
    np.save("out_hist.npy", np.cumsum(np.full((8, 3, 2), 0.4), axis=0))
    Path("out").mkdir()
    Path("out_hist.npy").rename("out/hist.npy")
    mains = {"crowdsim": crowdsim_main, "gpgraph": gpgraph_main, "crowdnav": crowdnav_main}
    ran, tour = 0, [shlex.split(line.split(" #")[0]) for line in tour_block().splitlines()]
    for argv in cli_commands():
        small = _small(argv, shared, tmp_path)
        if small is None or argv in tour:  # the tour runs in a shell, as a user runs it (test below)
            continue
        if small[:2] == ["gpgraph", "evaluate"] and small[3] == "runs/hotel/best.pt":
            assert Path("runs/hotel/best.pt").is_file()  # made by the documented train line just before
        assert mains[small[0]](small[1:]) == 0, (small, capsys.readouterr().err)
        ran += 1
    assert ran >= 10


def toml_block() -> str:
    """The scenario file of docs/crowdsim.md (its one ```toml block), as written there."""
    (block,) = re.findall(r"^```toml\n(.*?)^```", (ROOT / "docs" / "crowdsim.md").read_text(), flags=re.S | re.M)
    return block


def tour_block() -> str:
    """The README's tour: its bash block that ends with the smoke benchmark."""
    (block,) = [b for b in re.findall(r"^```bash\n(.*?)^```", README.read_text(), flags=re.S | re.M)
                if "crowdnav benchmark --suite smoke" in b]
    return block


def _plain_shell_env() -> dict[str, str]:
    """This process's environment as a new user's shell has it: no virtual environment active, its bin/ off PATH;
    PYTHONPATH is this checkout (a fresh clone's editable install points at the clone itself)."""
    venv_bin = (Path(sys.prefix) / "bin").resolve()
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONHOME")}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep)
                                  if p and Path(p).resolve() != venv_bin)
    env["PYTHONPATH"] = str(ROOT)
    return env


@pytest.mark.slow
def test_the_tour_runs_as_written_in_a_plain_shell(tmp_path):
    """After `make demo` on a fresh clone (`.venv` in its root, `../shared` beside it), the tour's lines run as
    written in bash with nothing activated, only the sizes shrunk as above; the console scripts are not on that
    shell's PATH, so the block must say how to reach them (the README once did not: `crowdsim: command not found`)."""
    shared = ROOT.parent / "shared"
    if sys.prefix == sys.base_prefix or not (shared / "datasets/eth_ucy").is_dir():
        pytest.skip("needs the tests to run in a virtual environment and ../shared/datasets")
    clone = tmp_path / "clone"
    clone.mkdir()
    (clone / ".venv").symlink_to(sys.prefix)  # what make demo made
    (clone / "crowdsim").symlink_to(ROOT / "crowdsim")  # the tour reads a shipped scenario file by its path
    (tmp_path / "shared").symlink_to(shared.resolve())
    env = _plain_shell_env()
    plain = subprocess.run(["bash", "-c", "command -v crowdsim crowdnav gpgraph"], env=env, cwd=clone,
                           capture_output=True, text=True)
    assert plain.stdout == "", f"console scripts on the plain PATH, the test cannot tell: {plain.stdout}"
    lines = []
    for line in tour_block().splitlines():
        argv = shlex.split(line.split(" #")[0])
        small = _small(argv, Path("../shared"), clone) if argv and argv[0] in ("crowdsim", "gpgraph", "crowdnav") \
            else None
        lines.append(line if small is None else shlex.join(small))
    run = subprocess.run(["bash", "-e", "-c", "\n".join(lines)], env=env, cwd=clone, capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    for made in ("out/data/plaza", "out/tour/comparison.md", "out/bench-smoke/leaderboard.md"):
        assert (clone / made).exists(), made
