"""The MPC's solver with its NLP callbacks compiled to machine code (CasADi's JIT through a C compiler), cached on disk.

fatrop spends about a third of a solve in CasADi's SX virtual machine evaluating the NLP's functions (the constraints,
their Jacobian, the Lagrangian's Hessian). Compiled with ``gcc -O1`` they run the same floating-point operations in
the same order, so a solve returns the same iterates bit for bit (checked on 144 dense-corridor solves and in
tests/planner/test_jit.py), about a third faster (crowdnav-v1 corridor-high-visible, mpc-gpgraph's solver calls: p50
17.6 -> 11.8 ms, p95 56.3 -> 37.0 ms; BENCHMARKS.md "planner").

Compiling takes ~30 s per configuration, so the compiled library (`STEM.so`) and the solver that links it (CasADi
serialisation, `STEM.casadi`) stay in the cache folder, STEM naming a hash of the CasADi version, the flags and the
whole serialised NLP: any change to the problem is a new file. A later process loads them in ~0.2 s, writing nothing.
A file that fails to load is removed and compiled again. A lock file per STEM lets one process compile while the
others (benchmark workers) wait and then load its result.

Settings (environment variables, read when a problem is built; they never change a result):
- ``CROWDNAV_MPC_JIT``: ``auto`` (default: compile when a C compiler is on PATH, else keep the virtual machine),
  ``on`` (a missing compiler or a failed compile is an error), ``off``.
- ``CROWDNAV_CACHE_DIR``: the cache folder (default ``$XDG_CACHE_HOME/crowdnav`` or ``~/.cache/crowdnav``). The
  files hold native code that is loaded and run: keep the folder private, as any folder on PATH.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import casadi as ca

JIT_ENV = "CROWDNAV_MPC_JIT"
CACHE_ENV = "CROWDNAV_CACHE_DIR"
JIT_MODES = ("auto", "on", "off")
FORMAT = "link-1"  # how the cache stores a solver: its .casadi links the compiled .so beside it
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
    key = hashlib.sha256("\n".join([ca.__version__, FORMAT, *FLAGS, reference.serialize()]).encode()).hexdigest()[:24]
    stem, folder = f"{name}_{plugin}_{key}", cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with _locked(folder / f"{stem}.lock"):  # one process compiles a file; the others wait, then load it
            return _load(folder, stem) or _compile(name, plugin, nlp, opts, folder, stem)
    except Exception as exc:
        if mode == "on":
            raise RuntimeError(f"compiling the MPC's NLP failed ({type(exc).__name__}: {exc})") from exc
        print(f"planner: compiling the MPC's NLP failed, solving on CasADi's virtual machine ({exc})", file=sys.stderr)
        return reference


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    with path.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _load(folder: Path, stem: str) -> ca.Function | None:
    """The cached solver (its .casadi links the .so beside it), or None; a file that fails to load is removed."""
    path = folder / f"{stem}.casadi"
    if not (path.exists() and (folder / f"{stem}.so").exists()):
        return None
    try:
        return ca.Function.load(str(path))
    except Exception:  # a truncated or foreign file: compile it again
        for suffix in (".casadi", ".so"):
            (folder / f"{stem}{suffix}").unlink(missing_ok=True)
        return None


def _compile(name: str, plugin: str, nlp: dict, opts: dict, folder: Path, stem: str) -> ca.Function:
    """Compile to folder/stem.so, save the solver (linking that library) to folder/stem.casadi atomically (a temporary
    file, then a rename), drop the C source (CasADi writes it to the working folder while compiling) and the object
    file, return the solver."""
    print(f"planner: compiling the MPC's NLP once for this configuration (~30 s; cached in {folder}; "
          f"{JIT_ENV}=off skips)", file=sys.stderr, flush=True)
    names = {"name": stem, "directory": f"{folder}{os.sep}", "temp_suffix": False, "cleanup": False}
    jit_opts = {"jit": True, "compiler": "shell", "jit_serialize": "link", "jit_name": stem, "jit_temp_suffix": False,
                "jit_cleanup": False, "jit_options": {"flags": list(FLAGS), "verbose": False, **names}}
    tmp = None
    try:  # the leftovers go whether the compile works or not (a failed one left its C source in the working folder)
        solver = ca.nlpsol(name, plugin, nlp, {**opts, **jit_opts})
        fd, tmp = tempfile.mkstemp(prefix=stem, suffix=".tmp", dir=folder)
        os.close(fd)
        solver.save(tmp)
        os.replace(tmp, folder / f"{stem}.casadi")
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        for leftover in (Path.cwd() / f"{stem}.c", folder / f"{stem}.c", folder / f"{stem}.o"):
            leftover.unlink(missing_ok=True)  # CasADi writes the source to the working folder
    return solver
