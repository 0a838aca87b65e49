"""`crowdsim` console script: generate recordings, whole datasets, and the demo."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn

from crowdsim.config import GroupConfig, SimConfig
from crowdsim.distributed import BACKENDS
from crowdsim.export import FORMATS
from crowdsim.files import check_writable_dir
from crowdsim.generate import (
    SPLITS,
    DatasetIncomplete,
    DatasetInterrupted,
    RunSpec,
    generate,
    make_dataset,
)
from crowdsim.names import long_options, parser_hint
from crowdsim.presets import PRESETS, get_preset, sample_config
from crowdsim.scenarios import SCENARIO_OPTIONS, SCENARIOS, scenario_file


def console_script(name: str) -> str:
    """How the user's shell reaches this install's console script `name` (e.g. rerun): the bare name when it is on
    PATH, else its path beside this Python (a virtual environment that is not activated: `.venv/bin/rerun`)."""
    if shutil.which(name):
        return name
    beside = Path(sys.executable).parent / name
    return str(beside) if beside.is_file() else name


def _options(pairs: list[str]) -> tuple[tuple[str, float], ...]:
    out: dict[str, float] = {}
    for item in pairs:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--option expects NAME=VALUE, got {item!r}")
        if key in out:
            raise ValueError(f"--option {key} is given twice")
        try:
            out[key] = float(value)
        except ValueError:
            raise ValueError(f"--option {key}: {value!r} is not a number") from None
    return tuple(out.items())


def _config(args: argparse.Namespace, scenario: str) -> SimConfig:
    """The SimConfig of the flags (ValueError naming the bad flag: unknown scenario or option, bad values)."""
    scenario_file(scenario)  # ValueError: an unknown name, or a bad scenario file (one line naming file and key)
    if args.pedestrians < 1:
        raise ValueError(f"--pedestrians must be >= 1, got {args.pedestrians}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    groups = GroupConfig(leave_rate_hz=args.leave_rate, merge_rate_hz=args.merge_rate,
                         max_size=min(5, args.pedestrians))
    return SimConfig(scenario=scenario, n_pedestrians=args.pedestrians, groups=groups,
                     scenario_options=_options(args.option))


def _spec(args: argparse.Namespace) -> RunSpec:
    if not args.duration > 0 or not args.warmup >= 0:
        raise ValueError(f"--duration must be > 0 and --warmup >= 0 s, got {args.duration} and {args.warmup}")
    return RunSpec(args.duration, args.warmup, args.seed)


def _check_out_dir(path: Path, subfolders: tuple[str, ...] = ()) -> None:
    """ValueError unless `path` (and each of its `subfolders`) is, or can be created as, a folder this process can
    write into (`crowdsim.files.check_writable_dir`: tried for real). Leaves nothing behind."""
    for folder in (path, *(path / s for s in subfolders)):
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"--out {path}: {folder} is a file, not a folder")
    try:
        check_writable_dir(path)
    except OSError as exc:
        raise ValueError(f"--out {path}: {exc}") from None


class _DefaultInt(int):
    """A default value that remembers it was not given on the command line (a preset may not be mixed with
    the flags it sets)."""


class _DefaultFloat(float):
    """See `_DefaultInt`."""


DEFAULT_SCENARIOS = "corridor,crossing,plaza,circle_crossing"  # of `crowdsim dataset` without --preset
PRESET_SETS = ("pedestrians", "leave_rate", "merge_rate", "option")  # flags a --preset draws per recording


def _given(args: argparse.Namespace, dest: str) -> bool:
    value = getattr(args, dest)
    return bool(value) if isinstance(value, list) else not isinstance(value, _DefaultInt | _DefaultFloat)


def _common(p: argparse.ArgumentParser, duration: float) -> None:
    p.add_argument("--pedestrians", type=int, default=_DefaultInt(40), help="crowd size (kept constant by inflow)")
    p.add_argument("--duration", type=float, default=duration, help="recorded seconds")
    p.add_argument("--warmup", type=float, default=4.0, help="unrecorded seconds before recording")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--leave-rate", type=float, default=_DefaultFloat(0.0),
                   help="per-group rate (1/s) of a member leaving")
    p.add_argument("--merge-rate", type=float, default=_DefaultFloat(0.0), help="per-group rate (1/s) of merging")
    p.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                   help="scenario option, e.g. width_m=5 (repeatable)")
    p.add_argument("--format", choices=FORMATS, default="ethucy",
                   help="ethucy: X.txt, X.groups.txt, X.labels.tsv; trajnet: one TrajNet++ X.ndjson (scenes and "
                        "tracks, group labels as a 'group' field); X.json beside either")


class OneLineParser(argparse.ArgumentParser):
    """Argument errors as one line on stderr (`prog command: error: ...`, exit 2), without the usage block
    (`--help` still shows it). Options must be spelt out in full: no abbreviations."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self.typed = list(sys.argv[1:] if args is None else args)  # what error() compares with the valid flags
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        hint = parser_hint(message, long_options(self), getattr(self, "typed", ()))
        self.exit(2, f"{self.prog}: error: {hint}\n")


def show_defaults(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make `--help` print every option's default: options without help text get their name as help, which
    `ArgumentDefaultsHelpFormatter` completes with "(default: ...)". Returns the parser."""
    parser.formatter_class = argparse.ArgumentDefaultsHelpFormatter
    for action in parser._actions:
        if action.option_strings and action.help is None and action.default is not argparse.SUPPRESS:
            action.help = action.dest.replace("_", " ")
    return parser


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="crowdsim", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="simulate one scenario and export ETH/UCY files")
    g.add_argument("--scenario", default="plaza", metavar="NAME|PATH.toml",
                   help=f"one of: {', '.join(sorted(SCENARIOS))}; or a scenario file (docs/crowdsim.md)")
    g.add_argument("--out", type=Path, required=True)
    g.add_argument("--rrd", action="store_true", help="also write a rerun recording")
    _common(g, 120.0)
    d = sub.add_parser("dataset", help="several scenarios x seeds into train/val/test folders")
    d.add_argument("--scenarios", default=None,
                   help=f"comma-separated names or .toml scenario files (default: the preset's, or "
                        f"{DEFAULT_SCENARIOS})")
    d.add_argument("--preset", default=None, choices=sorted(PRESETS),
                   help="draw each recording's parameters from this training preset (crowdsim presets lists "
                        "them); it sets --pedestrians, --leave-rate, --merge-rate and --option")
    d.add_argument("--seeds-per-scenario", type=int, default=6)
    d.add_argument("--out", type=Path, required=True)
    d.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local: this machine's processes (default); ray: one Ray task per recording "
                        "(needs the 'ray' extra). The files are identical either way")
    d.add_argument("--workers", type=int, default=None,
                   help="local: processes (default 1: serial); ray: CPUs of the local Ray instance "
                        "(default: all cores)")
    d.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="with --backend ray: connect to a running Ray cluster instead of starting one")
    _common(d, 300.0)
    m = sub.add_parser("demo", help="generate and record a grouped crowd on built-in defaults")
    m.add_argument("--out", type=Path, default=Path("out/demo-crowd"))
    sub.add_parser("scenarios", help="list the built-in scenarios: name, file, description, options")
    sub.add_parser("presets", help="list the training presets of `dataset --preset`")
    for command in sub.choices.values():
        show_defaults(command)
    return parser


def _summary(paths: dict[str, Path]) -> str:
    """One line on what was written: the row and pedestrian counts from the recording's metadata JSON (written
    from the same table as the trajectory file, so the file itself need not be parsed again) and the groups."""
    meta = json.loads(paths["metadata"].read_text())
    if "groups" in paths:
        groups = len([ln for ln in paths["groups"].read_text().splitlines() if ln.strip()])
    else:  # a TrajNet++ recording: its metadata counts them
        groups = meta["groups_of_two_or_more"]
    return (f"{meta['rows']} rows, {meta['pedestrians']} pedestrians, "
            f"{groups} groups of 2+ -> {paths['trajectories'].parent}")


def _error(message: str) -> int:
    """One line on stderr, exit status 2 (a usage error)."""
    print(f"crowdsim: error: {message}", file=sys.stderr)
    return 2


def _dataset_usage_error(args: argparse.Namespace) -> str | None:
    """What is wrong with the backend options of `crowdsim dataset`, if anything (checked before any work)."""
    if args.address is not None and args.backend != "ray":
        return "--address needs --backend ray"
    if args.workers is not None and args.workers < 1:
        return f"--workers must be >= 1, got {args.workers}"
    if args.workers is not None and args.address is not None:
        return "--workers sizes a local Ray instance; with --address the cluster's CPUs decide"
    if args.backend == "ray":
        from crowdsim.distributed import RayUnavailableError, import_ray

        try:
            import_ray()
        except RayUnavailableError as exc:
            return str(exc)
    return None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except ValueError as exc:  # bad flags or values: one line, exit 2, nothing written (checked before work)
        return _error(str(exc))
    except DatasetInterrupted as exc:  # Ctrl-C in dataset: what is on disk is complete
        print(f"crowdsim: interrupted: {exc.written} of {exc.total} recordings written to {args.out} (each complete, "
              "the others absent); rerun the command to make them all", file=sys.stderr)
        return 130
    except KeyboardInterrupt:  # Ctrl-C elsewhere: one line, no traceback (a recording is written only at its end)
        print(f"crowdsim: interrupted: {args.command} stopped", file=sys.stderr)
        return 130


def _run(args: argparse.Namespace) -> int:
    if args.command == "scenarios":
        for name in sorted(SCENARIOS):
            opts = ", ".join(f"{k}={v:g}" for k, v in SCENARIO_OPTIONS[name].items())
            print(f"{name}  {SCENARIOS[name].source}\n    {SCENARIOS[name].description}  (options: {opts})")
        print("any other scenario: --scenario PATH.toml (the format: docs/crowdsim.md, or a file above)")
        return 0
    if args.command == "presets":
        for preset in PRESETS.values():
            print(f"{preset.name}  (version {preset.version}: {preset.description})")
        return 0
    if args.command == "generate":
        config, spec = _config(args, args.scenario), _spec(args)
        _check_out_dir(args.out)
        paths = generate(config, spec, args.out, rrd=args.rrd, progress=True, fmt=args.format)
        print(_summary(paths))
        return 0
    if args.command == "dataset":
        return _dataset(args)
    # demo: a plaza crowd with group events, exported and recorded for rerun
    _check_out_dir(args.out)
    config = SimConfig(scenario="plaza", n_pedestrians=60,
                       groups=replace(GroupConfig(), leave_rate_hz=0.01, merge_rate_hz=0.01))
    paths = generate(config, RunSpec(duration_s=60.0, seed=0), args.out, name="plaza_demo", rrd=True,
                     progress=True)
    print(_summary(paths))
    print(f"rerun recording: {paths['rrd']}  (view with: {console_script('rerun')} {paths['rrd']})")
    return 0


def _dataset(args: argparse.Namespace) -> int:
    problem = _dataset_usage_error(args)
    if problem is not None:
        return _error(problem)
    mixed = [f"--{d.replace('_', '-')}" for d in PRESET_SETS if args.preset and _given(args, d)]
    if mixed:
        raise ValueError(f"--preset {args.preset} draws {', '.join(mixed)} per recording; leave them out")
    default = ",".join(get_preset(args.preset).scenarios) if args.preset else DEFAULT_SCENARIOS
    scenarios = [s.strip() for s in (args.scenarios if args.scenarios is not None else default).split(",")
                 if s.strip()]
    if not scenarios:
        raise ValueError("--scenarios is empty; valid names: " + ", ".join(sorted(SCENARIOS)))
    if args.seeds_per_scenario < 3:
        raise ValueError(f"--seeds-per-scenario must be >= 3 so that train, val and test each get a recording, "
                         f"got {args.seeds_per_scenario}")
    base, spec = _config(args, scenarios[0]), _spec(args)
    for s in scenarios:
        _config(args, s)
        if args.preset:
            sample_config(get_preset(args.preset), s, args.seed)  # a scenario the preset lacks: error now
    _check_out_dir(args.out, SPLITS)
    try:
        out = make_dataset(args.out, scenarios, args.seeds_per_scenario, base, spec, backend=args.backend,
                           workers=args.workers, address=args.address, preset=args.preset, fmt=args.format)
    except ConnectionError as exc:  # ray.init could not reach --address
        print(f"crowdsim: error: cannot connect to Ray at {args.address}: {exc}", file=sys.stderr)
        return 1
    except DatasetIncomplete as exc:  # everything else was written: say so, then one line per missing recording
        for split in SPLITS:
            print(f"{split}: {len(exc.paths[split])} recordings in {args.out / split}")
        for name, cause in exc.failures.items():
            print(f"crowdsim: error: recording {name} not written: {cause}", file=sys.stderr)
        return 1
    for split in SPLITS:
        print(f"{split}: {len(out[split])} recordings in {args.out / split}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
