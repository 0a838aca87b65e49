"""Dataset backends: the local process pool and Ray write the same bytes; backend options and their errors."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from crowdsim.cli import main
from crowdsim.config import GroupConfig, SimConfig
from crowdsim.distributed import RAY_MISSING, ray_session
from crowdsim.generate import RunSpec, make_dataset

# tiny: 2 scenarios x 2 seeds, 10 pedestrians with group events, 20 s recorded
BASE = SimConfig(scenario="corridor", n_pedestrians=10, groups=GroupConfig(leave_rate_hz=0.05, merge_rate_hz=0.05))
SCENARIOS = ["corridor", "plaza"]
SPEC = RunSpec(duration_s=20.0, warmup_s=2.0, seed=3)
CLI_ARGS = ["dataset", "--scenarios", "corridor", "--seeds-per-scenario", "1", "--pedestrians", "6",
            "--duration", "4"]


def _tree(folder: Path) -> dict[str, bytes]:
    """Every file under folder: relative path -> bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _dataset(out: Path, **backend) -> dict[str, list[str]]:
    paths = make_dataset(out, SCENARIOS, 2, BASE, SPEC, progress=False, **backend)
    return {split: [p.relative_to(out).as_posix() for p in ps] for split, ps in paths.items()}


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray instance of 2 CPUs for the module, shut down at the end."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False)
    yield ray
    ray.shutdown()


@pytest.mark.slow
@pytest.mark.xdist_group("crowdsim-parallel")  # keeps the two multi-process tests on one xdist worker
def test_ray_backend_writes_byte_identical_files(tmp_path, local_ray):
    local = _dataset(tmp_path / "local")
    ray = _dataset(tmp_path / "ray", backend="ray")
    assert local == ray == {"train": ["train/corridor_n10_s3.txt", "train/corridor_n10_s4.txt",
                                      "train/plaza_n10_s3.txt", "train/plaza_n10_s4.txt"], "val": [], "test": []}
    a, b = _tree(tmp_path / "local"), _tree(tmp_path / "ray")
    assert len(a) == 4 * 4 and a.keys() == b.keys()
    for name in a:
        assert a[name] == b[name], name
    assert local_ray.is_initialized()  # an instance make_dataset did not start is left running


@pytest.mark.slow
@pytest.mark.xdist_group("crowdsim-parallel")
def test_local_process_pool_writes_byte_identical_files(tmp_path):
    assert _dataset(tmp_path / "serial") == _dataset(tmp_path / "pool", workers=2)
    a, b = _tree(tmp_path / "serial"), _tree(tmp_path / "pool")
    assert len(a) == 4 * 4 and a == b


def _fake_ray(initialised: bool) -> SimpleNamespace:
    """A stand-in for the `ray` module that records init/shutdown calls."""
    calls: list[tuple] = []
    return SimpleNamespace(calls=calls, is_initialized=lambda: initialised,
                           init=lambda **kw: calls.append(("init", kw)), shutdown=lambda: calls.append(("shutdown",)))


@pytest.mark.parametrize("address, num_cpus, initialised, calls", [
    (None, 2, False, [("init", {"num_cpus": 2, "include_dashboard": False}), ("shutdown",)]),
    ("auto", None, False, [("init", {"address": "auto"}), ("shutdown",)]),
    ("10.0.0.5:6379", None, False, [("init", {"address": "10.0.0.5:6379"}), ("shutdown",)]),
    (None, None, True, []),  # already initialised: used as it is, left running
    ("auto", None, True, []),
])
def test_ray_session_initialises_only_when_needed(monkeypatch, address, num_cpus, initialised, calls):
    fake = _fake_ray(initialised)
    monkeypatch.setitem(sys.modules, "ray", fake)
    with ray_session(address, num_cpus) as ray:
        assert ray is fake
    assert fake.calls == calls


def test_ray_session_rejects_cpus_with_an_address():
    with pytest.raises(ValueError, match="cluster"):
        with ray_session("auto", 4):
            pass


def test_make_dataset_rejects_bad_backend_options(tmp_path):
    with pytest.raises(ValueError, match="valid names: local, ray"):
        make_dataset(tmp_path, SCENARIOS, 1, BASE, SPEC, backend="dask")
    with pytest.raises(ValueError, match="address"):
        make_dataset(tmp_path, SCENARIOS, 1, BASE, SPEC, address="auto")
    with pytest.raises(ValueError, match="workers"):
        make_dataset(tmp_path, SCENARIOS, 1, BASE, SPEC, workers=0)
    assert not any(tmp_path.iterdir())


def test_cli_unknown_backend_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([*CLI_ARGS, "--out", str(tmp_path / "d"), "--backend", "dask"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'dask'" in err and "'local'" in err and "'ray'" in err
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("extra, message", [
    (["--address", "auto"], "--address needs --backend ray"),
    (["--backend", "local", "--address", "127.0.0.1:6379"], "--address needs --backend ray"),
    (["--backend", "ray", "--address", "auto", "--workers", "2"], "--workers sizes a local Ray instance"),
    (["--workers", "0"], "--workers must be >= 1"),
])
def test_cli_backend_option_errors_exit_2_and_write_nothing(tmp_path, capsys, extra, message):
    assert main([*CLI_ARGS, "--out", str(tmp_path / "d"), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"crowdsim: error: {message}") and err.count("\n") == 1
    assert not (tmp_path / "d").exists()


def test_cli_ray_backend_without_ray_exits_2_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    assert main([*CLI_ARGS, "--out", str(tmp_path / "d"), "--backend", "ray"]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"crowdsim: error: {RAY_MISSING}\n" and captured.out == ""
    assert RAY_MISSING == "--backend ray needs the 'ray' extra (pip install ray)"
    assert not (tmp_path / "d").exists()
