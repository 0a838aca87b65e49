"""The compiled MPC (planner/jit.py): the virtual machine's plans bit for bit, cached on disk, and its settings."""

from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest
from planner_helpers import PRED, drive, make_config

from planner import MPCPlanner, constant_velocity_prediction
from planner import jit as jit_mod
from planner.mpc import shared_ocp

SMALL = make_config(horizon_steps=4, max_peds=2)  # the smallest useful NLP: ~8 s to compile here


def _crossing(step: int, robot_state: np.ndarray):
    """Two walkers crossing the robot's path, one of them closing head-on: the plans have to bend."""
    t = 0.1 * step
    now = np.array([[2.5 - 0.8 * t, 0.3], [1.5, -2.0 + 1.0 * t]])
    history = np.stack([now - np.array([[-0.8, 0.0], [0.0, 1.0]]) * 0.4 * (7 - k) for k in range(8)])
    return constant_velocity_prediction(history, **PRED)


def _plans(monkeypatch, mode: str) -> list:
    monkeypatch.setenv(jit_mod.JIT_ENV, mode)
    shared_ocp.cache_clear()
    planner = MPCPlanner(SMALL)
    _, results = drive(planner, np.zeros(5), np.array([5.0, 0.0]), _crossing, steps=25)
    return [(r.states.tobytes(), r.controls.tobytes(), r.status, r.iterations) for r in results]


@pytest.mark.slow
@pytest.mark.skipif(jit_mod.compiler() is None, reason="no C compiler on PATH")
def test_the_compiled_solver_plans_as_the_virtual_machine_bit_for_bit_and_is_cached(monkeypatch, tmp_path):
    cache, cwd = tmp_path / "cache", tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    monkeypatch.setenv(jit_mod.CACHE_ENV, str(cache))
    reference = _plans(monkeypatch, "off")
    assert not cache.exists()
    compiled = _plans(monkeypatch, "on")
    assert compiled == reference  # every state, control, status and iteration count
    assert {status for _, _, status, _ in reference} == {"solved"}
    (solver_file,) = cache.glob("*.casadi")
    stem = solver_file.stem
    assert {f.name for f in cache.iterdir()} == {f"{stem}.casadi", f"{stem}.so", f"{stem}.lock"}

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled again instead of loading the cache")

    monkeypatch.setattr(jit_mod, "_compile", no_compile)
    assert _plans(monkeypatch, "on") == reference  # loaded from the files
    assert not list(cwd.iterdir()) and len(list(cache.iterdir())) == 3  # loading writes nothing
    solver_file.write_bytes(b"not a casadi file")  # a corrupt cache entry is removed and compiled again
    rebuilt, sentinel = [], object()
    monkeypatch.setattr(jit_mod, "_compile", lambda *args: rebuilt.append(args[-1]) or sentinel)
    shared_ocp.cache_clear()
    assert shared_ocp(SMALL).solver is sentinel
    assert rebuilt == [stem] and not solver_file.exists() and not (cache / f"{stem}.so").exists()
    shared_ocp.cache_clear()


def test_the_settings_are_checked_and_without_a_compiler_auto_keeps_the_virtual_machine(monkeypatch, tmp_path):
    monkeypatch.setenv(jit_mod.CACHE_ENV, str(tmp_path))
    reference = ca.Function("f", [ca.SX.sym("x")], [ca.SX.sym("x") * 0])
    monkeypatch.setenv(jit_mod.JIT_ENV, "fast")
    with pytest.raises(ValueError, match="valid: auto, on, off"):
        jit_mod.compiled_nlpsol("mpc", "fatrop", {}, {}, reference)
    monkeypatch.setattr(jit_mod, "compiler", lambda: None)
    for mode in ("auto", "off", "OFF"):
        monkeypatch.setenv(jit_mod.JIT_ENV, mode)
        assert jit_mod.compiled_nlpsol("mpc", "fatrop", {}, {}, reference) is reference
    monkeypatch.setenv(jit_mod.JIT_ENV, "on")
    with pytest.raises(RuntimeError, match="no C compiler"):
        jit_mod.compiled_nlpsol("mpc", "fatrop", {}, {}, reference)
    assert not list(tmp_path.iterdir())  # nothing compiled, nothing cached


def test_an_unwritable_cache_keeps_the_virtual_machine_under_auto_and_is_an_error_under_on(monkeypatch, tmp_path):
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache folder should be")
    monkeypatch.setenv(jit_mod.CACHE_ENV, str(blocked / "cache"))
    monkeypatch.setattr(jit_mod, "compiler", lambda: "/usr/bin/gcc")
    reference = ca.Function("f", [ca.SX.sym("x")], [ca.SX.sym("x") * 0])
    monkeypatch.setenv(jit_mod.JIT_ENV, "auto")
    assert jit_mod.compiled_nlpsol("mpc", "fatrop", {}, {}, reference) is reference
    monkeypatch.setenv(jit_mod.JIT_ENV, "on")
    with pytest.raises(RuntimeError, match="compiling the MPC's NLP failed"):
        jit_mod.compiled_nlpsol("mpc", "fatrop", {}, {}, reference)


@pytest.mark.skipif(jit_mod.compiler() is None, reason="no C compiler on PATH")
def test_a_failed_compile_keeps_the_virtual_machine_and_leaves_no_c_source_behind(monkeypatch, tmp_path):
    cwd, cache, bin_dir = tmp_path / "cwd", tmp_path / "cache", tmp_path / "bin"
    for folder in (cwd, cache, bin_dir):
        folder.mkdir()
    broken = bin_dir / "gcc"
    broken.write_text("#!/bin/sh\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:{os.environ['PATH']}")
    monkeypatch.chdir(cwd)
    monkeypatch.setenv(jit_mod.CACHE_ENV, str(cache))
    reference = _plans(monkeypatch, "off")
    assert _plans(monkeypatch, "auto") == reference  # the compile failed: the virtual machine plans
    assert not list(cwd.glob("*.c")) and not list(cache.glob("*.c")) and not list(cache.glob("*.so"))
