"""The MPC's solver with its NLP callbacks compiled to machine code (CasADi's JIT through a C compiler), cached on disk.

fatrop spends about a third of a solve in CasADi's SX virtual machine evaluating the NLP's functions (the constraints,
their Jacobian, the Lagrangian's Hessian). Compiled with ``gcc -O1`` they run the same floating-point operations in
the same order, so a solve returns the same iterates bit for bit (checked on 144 dense-corridor solves and in
tests/planner/test_jit.py), about a third faster (crowdnav-v1 corridor-high-visible, mpc-gpgraph's solver calls: p50
17.6 -> 11.8 ms, p95 56.3 -> 37.0 ms; BENCHMARKS.md "planner").

Compiling takes ~30 s per configuration, so the compiled solver is saved (CasADi serialisation with the binary
embedded) under the cache folder, named by a hash of the CasADi version, the flags and the whole serialised NLP: any
change to the problem is a new file. A later process loads it in ~0.2 s. A file that fails to load is deleted and
rebuilt. Two processes compiling the same file at once both finish; the last rename wins (same content).

Settings (environment variables, read when a problem is built; they never change a result):
- ``CROWDNAV_MPC_JIT``: ``auto`` (default: compile when a C compiler is on PATH, else keep the virtual machine),
  ``on`` (a missing compiler or a failed compile is an error), ``off``.
- ``CROWDNAV_CACHE_DIR``: the cache folder (default ``$XDG_CACHE_HOME/crowdnav`` or ``~/.cache/crowdnav``). The
  files hold native code that is loaded and run: keep the folder private, as any folder on PATH.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import casadi as ca

JIT_ENV = "CROWDNAV_MPC_JIT"
CACHE_ENV = "CROWDNAV_CACHE_DIR"
JIT_MODES = ("auto", "on", "off")
FLAGS = ("-O1",)  # the measured setting: ~30 s to build the crowd MPC here


def jit_mode() -> str:
    """The `CROWDNAV_MPC_JIT` setting; an unknown value is an error naming the valid ones."""
    mode = os.environ.get(JIT_ENV, "auto").strip().lower() or "auto"
    if mode not in JIT_MODES:
        raise ValueError(f"{JIT_ENV}={mode!r} is not a valid setting; valid: {', '.join(JIT_MODES)}")
    return mode


def cache_dir() -> Path:
    """Where compiled solvers are kept (`CROWDNAV_CACHE_DIR`, else the user's cache folder)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "crowdnav"


def compiler() -> str | None:
    """The C compiler CasADi's shell JIT would call, if any."""
    return shutil.which("gcc") or shutil.which("cc")


def compiled_nlpsol(name: str, plugin: str, nlp: dict, opts: dict, reference: ca.Function) -> ca.Function:
    """`reference` (the nlpsol of `nlp` with `opts`, on CasADi's virtual machine) with its callbacks compiled, from the
    cache or compiled now (see the module docstring); `reference` itself where the setting or the machine says so."""
    mode = jit_mode()
    if mode == "off":
        return reference
    if compiler() is None:
        if mode == "on":
            raise RuntimeError(f"{JIT_ENV}=on but no C compiler (gcc or cc) is on PATH")
        return reference
    key = hashlib.sha256("\n".join([ca.__version__, *FLAGS, reference.serialize()]).encode()).hexdigest()[:24]
    path = cache_dir() / f"{name}-{plugin}-{key}.casadi"
    if path.exists():
        try:
            return ca.Function.load(str(path))
        except Exception:  # a truncated or foreign file: rebuild it
            path.unlink(missing_ok=True)
    try:
        return _compile(name, plugin, nlp, opts, path)
    except Exception as exc:
        if mode == "on":
            raise RuntimeError(f"compiling the MPC's NLP failed ({type(exc).__name__}: {exc})") from exc
        print(f"planner: compiling the MPC's NLP failed, solving on CasADi's virtual machine ({exc})", file=sys.stderr)
        return reference


def _compile(name: str, plugin: str, nlp: dict, opts: dict, path: Path) -> ca.Function:
    """Compile, save to `path` atomically (a temporary file in the same folder, then a rename), return the solver."""
    print(f"planner: compiling the MPC's NLP once for this configuration (~30 s; cached in {path.parent}; "
          f"{JIT_ENV}=off skips)", file=sys.stderr, flush=True)
    jit_opts = {"jit": True, "compiler": "shell", "jit_serialize": "embed",
                "jit_options": {"flags": list(FLAGS), "verbose": False}}
    solver = ca.nlpsol(name, plugin, nlp, {**opts, **jit_opts})
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        solver.save(tmp)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return solver
