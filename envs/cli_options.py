"""Shared `crowdnav` options: the flags that map onto `PolicyConfig` and the run backend, and their checks.

Every flag has a default shown in --help; a misspelt flag, an unknown name or a flag that the chosen policy
ignores is an error (one line on stderr, exit 2), raised before any episode runs. Which policy reads which flag:
`POLICY_FLAGS` (registry policies), `SB3_FLAGS` (`sb3:PATH.zip`); a `module:factory` plug-in receives the whole
`PolicyConfig`, so it may read any. With several policies a flag applies to those that read it (the others keep
their defaults, and their results say so); a flag that none of the chosen policies reads is an error.
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import fields, replace
from typing import TYPE_CHECKING, Any

from crowdsim.distributed import BACKENDS
from crowdsim.names import unknown_name
from envs.config import DEFAULT_PREDICTOR, REPLAY_SCENARIO
from envs.policies import ENV_MPC, PACKAGED_AGENTS, POLICIES, REPLAN_EVERY_STEPS, PolicyConfig
from envs.policies.plugins import SB3_PREFIX
from envs.policies.wrappers import base_name, split_wrappers
from planner import CostWeights, ForesightConfig, GuidanceConfig, RouteConfig

if TYPE_CHECKING:
    from envs.evaluation.suite import Suite

# flag -> the `PolicyConfig` field it sets
FLAG_FIELDS = {"--predictor": "predictor", "--samples": "n_samples", "--replan-every": "replan_every_steps",
               "--threads": "threads", "--mpc": "mpc"}
# registry policy -> the flags it reads (envs.policies.registry: mpc-gpgraph loads a torch predictor and draws
# samples; the baseline MPCs re-plan on their own predictions; social-force acts every step, random reads nothing;
# orca decides every ORCA step (0.25 s) with the crowd's ORCA settings; ppo-crowdnav is an SB3 agent).
# PolicyConfig.deterministic has no flag.
SB3_FLAGS = ("--threads",)  # what an SB3 agent (packaged or sb3:PATH.zip) reads
POLICY_FLAGS: dict[str, tuple[str, ...]] = {
    "mpc-gpgraph": ("--predictor", "--samples", "--replan-every", "--threads", "--mpc"),
    "mpc-oracle": ("--replan-every", "--mpc"),
    "mpc-oracle-paths": ("--predictor", "--samples", "--replan-every", "--threads", "--mpc"),
    "mpc-oracle-groups": ("--predictor", "--samples", "--replan-every", "--threads", "--mpc"),
    "mpc-cv": ("--replan-every", "--mpc"),
    "mpc-none": ("--replan-every", "--mpc"),
    "social-force": (),
    "random": (),
    "orca": (),
    **{name: SB3_FLAGS for name in PACKAGED_AGENTS},
}
# registry policies acting on the observation (as sb3: and plug-ins do)
OBSERVATION_POLICIES = PACKAGED_AGENTS


def flags_read(name: str) -> tuple[str, ...]:
    """The policy flags the policy `name` reads: a registry policy's `POLICY_FLAGS`, an SB3 agent's `SB3_FLAGS`,
    and every flag for any other name (a `module:factory` plug-in; `PolicyConfig` rejects what is neither)."""
    base, wrappers = split_wrappers(name)
    if wrappers:  # the route and the shield read their settings from --mpc
        return tuple(dict.fromkeys((*flags_read(base), "--mpc")))
    if name in POLICY_FLAGS:
        return POLICY_FLAGS[name]
    return SB3_FLAGS if name.startswith(SB3_PREFIX) else tuple(FLAG_FIELDS)


def reads_observation(name: str) -> bool:
    """Whether the policy acts on the env's observation (so that --wall-rays can matter to it): an SB3 agent, a
    plug-in or one of `OBSERVATION_POLICIES`."""
    name = base_name(name)
    return name not in POLICY_FLAGS or name in OBSERVATION_POLICIES


class DefaultInt(int):
    """A flag's default value that remembers it was not given on the command line (`given`)."""


class DefaultStr(str):
    """A flag's default text that remembers it was not given on the command line (`given`)."""


def given(value: object) -> bool:
    """Whether a flag's value came from the command line (not its default: None, [], a `DefaultInt` or a
    `DefaultStr`)."""
    return value is not None and value != [] and not isinstance(value, DefaultInt | DefaultStr)


def add_video_options(p: argparse.ArgumentParser) -> None:
    """`crowdnav evaluate`'s --video, --video-format, --video-size (`envs.drawing.video`)."""
    from envs.drawing.video import DEFAULT_SIZE_PX, VIDEO_FORMATS

    p.add_argument("--video", type=int, default=0, metavar="N",
                   help="videos of the first N episodes per policy: <out>/videos/<policy>-<scenario>-seed<k>.mp4")
    p.add_argument("--video-format", choices=VIDEO_FORMATS, default=DefaultStr("mp4"),
                   help='mp4 (H.264; the video extra: pip install -e ".[video]") or gif (Pillow)')
    p.add_argument("--video-size", type=int, default=DefaultInt(DEFAULT_SIZE_PX), metavar="PX",
                   help="video frame side, px (even)")


def check_video_flags(args: argparse.Namespace) -> None:
    """--video >= 0; --video-format / --video-size only with --video N > 0; the format's encoder installed."""
    from envs.drawing.video import check_video_options

    if args.video < 0:
        raise ValueError(f"--video must be >= 0, got {args.video}")
    if args.video == 0:
        extra = [f for f, v in (("--video-format", args.video_format), ("--video-size", args.video_size)) if given(v)]
        if extra:
            raise ValueError(f"{' and '.join(extra)} need --video N (N > 0)")
        return
    from envs.drawing.video import MIN_SIZE_PX

    if args.video_size < MIN_SIZE_PX or args.video_size % 2:
        raise ValueError(f"--video-size must be an even number of pixels >= {MIN_SIZE_PX}, got {args.video_size}")
    check_video_options(str(args.video_format), int(args.video_size))


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


def add_policy_options(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument("--policy", nargs="+", action="extend", required=required, metavar="NAME",
                   help="one or more (repeatable) of: " + ", ".join(POLICIES)
                   + ", module:factory (a Policy plug-in) or sb3:PATH.zip (a stable-baselines3 agent); any but the "
                   "mpc-* policies may end in +route (it heads for the global route's subgoal through walls) and/or "
                   "+shield (its decisions checked by the MPC's safety shield; settings from --mpc route=, shield_*)")
    p.add_argument("--predictor", default=None, metavar="NAME",
                   help="for mpc-gpgraph and plug-in policies: predictor name, checkpoint path or module:factory "
                   f"(default: the shipped {DEFAULT_PREDICTOR})")
    p.add_argument("--samples", type=int, default=DefaultInt(PolicyConfig.n_samples), metavar="K",
                   help="predicted samples per plan (mpc-gpgraph, plug-ins)")
    p.add_argument("--replan-every", type=int, default=DefaultInt(REPLAN_EVERY_STEPS), metavar="STEPS",
                   help="env steps between re-plans (mpc-gpgraph, mpc-oracle, mpc-cv, mpc-none, plug-ins; default 1, "
                   "or the benchmark suite's planner default)")
    p.add_argument("--threads", type=int, default=DefaultInt(PolicyConfig.threads),
                   help="torch threads per process (mpc-gpgraph, ppo-crowdnav agents, sb3: agents, plug-ins)")
    p.add_argument("--mpc", action="append", default=[], metavar="FIELD=VALUE",
                   help="override an MPCConfig field of the MPC policies (repeatable), e.g. safety_margin_m=0.4; on "
                   "top of the benchmark suite's planner defaults, if it has any (crowdnav suites lists them); a "
                   "nested config (route, guidance, foresight) takes none or default, or one field as "
                   "NESTED.FIELD=VALUE, e.g. foresight.horizon_s=6; the cost weights one field at a time, e.g. "
                   "weights.social=0.2")


def add_backend_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=DefaultInt(default_workers()),
                   help="processes (1: in this process); with --backend ray, the CPUs of the local Ray instance")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local process pool or Ray tasks (the 'ray' extra)")
    p.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="Ray cluster to connect to (default: start a local Ray instance); needs --backend ray")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def mpc_overrides(items: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """{field: value} of `--mpc FIELD=VALUE` items on top of the env's MPC (`ENV_MPC`); ValueError naming the valid
    fields for an unknown one and the type for a malformed value."""
    valid = {f.name: f for f in fields(ENV_MPC) if f.name not in ("robot", "weights")}
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if sep and "." in key:
            out.update(_nested_override(item, key, text, out))
            continue
        if key in FIELDS_ONLY:
            raise ValueError(f"--mpc {item!r}: {key} is set one field at a time, e.g. {key}.social=0.2")
        if not sep or key not in valid:
            if sep:
                raise ValueError(unknown_name("--mpc field", key, valid))
            raise ValueError(f"--mpc {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(valid)}")
        out[key] = _mpc_value(item, key, text, "None" in str(valid[key].type))
    return out


NESTED = {"route": RouteConfig, "guidance": GuidanceConfig,  # --mpc FIELD=default gives these configs
          "foresight": ForesightConfig}
# nested configs set one field at a time only (NESTED.FIELD=VALUE), on top of the env's MPC: the cost weights
FIELDS_ONLY = {"weights": CostWeights}


def _nested_override(item: str, key: str, text: str, out: dict[str, Any]) -> dict[str, Any]:
    """--mpc NESTED.FIELD=VALUE (e.g. foresight.horizon_s=6): that field of the nested config, on top of what an
    earlier item set, else of its defaults."""
    outer, _, inner = key.partition(".")
    kinds = {**NESTED, **FIELDS_ONLY}
    if outer not in kinds:
        raise ValueError(unknown_name("--mpc nested config", outer, kinds))
    valid = {f.name: f for f in fields(kinds[outer])}
    if inner not in valid:
        raise ValueError(unknown_name(f"--mpc {outer} field", inner, valid))
    base = out.get(outer) or (getattr(ENV_MPC, outer) if outer in FIELDS_ONLY else NESTED[outer]())
    current = getattr(base, inner)
    if isinstance(current, tuple):
        raise ValueError(f"--mpc {item!r}: {outer}.{inner} is a tuple, which this option cannot set")
    return {outer: replace(base, **{inner: _scalar(item, text, type(current))})}


def _mpc_value(item: str, key: str, text: str, optional: bool) -> Any:
    """The value of one --mpc FIELD=VALUE: a scalar of the field's type, `none` for an optional field, and for
    the nested configs (`NESTED`: `route`, `guidance`, `foresight`) one of none (e.g. no global route) or default (e.g.
    `planner.RouteConfig()`)."""
    if optional and text.lower() == "none":
        return None
    if key in NESTED:
        if text.lower() != "default":
            raise ValueError(f"--mpc {item!r}: {key} is one of none, default")
        return NESTED[key]()
    current = getattr(ENV_MPC, key)
    return _scalar(item, text, float if current is None else type(current))


def _scalar(item: str, text: str, kind: type) -> Any:
    """`text` as a value of `kind` (bool: true, false, 1 or 0); ValueError naming the --mpc `item` otherwise."""
    try:
        if kind is bool:
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.lower() in ("true", "1")
        return kind(text)
    except ValueError as exc:
        raise ValueError(f"--mpc {item!r}: {text!r} is not a {kind.__name__}") from exc


def ignored_flag(flag: str, names: list[str], readers: list[str]) -> ValueError:
    """The error for a flag that none of the chosen policies `names` reads (`readers`: the policies that do)."""
    return ValueError(f"{flag} is ignored by {', '.join(names)}: it applies only to "
                      f"{', '.join(readers[:-1])}{' and ' if len(readers) > 1 else ''}{readers[-1]}")


def _readers(flag: str) -> list[str]:
    names = [n for n, flags in POLICY_FLAGS.items() if flag in flags]
    return [*names, *(["sb3:PATH.zip"] if flag in SB3_FLAGS else []), "module:factory policies"]


def policy_configs(args: argparse.Namespace, suite: Suite | None = None) -> list[PolicyConfig]:
    """The `PolicyConfig`s the flags describe, each flag set only for the policies that read it (`flags_read`),
    on top of the benchmark suite's planner defaults (`Suite.replan_every_steps`, `Suite.mpc`) where the flag is
    not given. ValueError on a bad value, or on a flag that none of the chosen policies reads."""
    if len(set(args.policy)) != len(args.policy):
        raise ValueError("a policy is named twice")
    values = {"--predictor": args.predictor, "--samples": args.samples, "--replan-every": args.replan_every,
              "--threads": args.threads, "--mpc": args.mpc}
    chosen = {flag: value for flag, value in values.items() if given(value)}
    for flag in ("--samples", "--replan-every", "--threads"):
        if flag in chosen and chosen[flag] < 1:
            raise ValueError(f"{flag} must be >= 1, got {chosen[flag]}")
    for flag in chosen:
        if not any(flag in flags_read(n) for n in args.policy):
            raise ignored_flag(flag, args.policy, _readers(flag))
    if "--mpc" in chosen or (suite is not None and suite.mpc):
        base = suite.mpc_config(ENV_MPC) if suite is not None else ENV_MPC
        chosen["--mpc"] = replace(base, **mpc_overrides(args.mpc or []))
    if suite is not None and suite.replan_every_steps is not None and "--replan-every" not in chosen:
        chosen["--replan-every"] = suite.replan_every_steps
    return [PolicyConfig(name=n, **{FLAG_FIELDS[f]: v for f, v in chosen.items() if f in flags_read(n)})
            for n in args.policy]


def check_backend(args: argparse.Namespace) -> None:
    if args.workers < 1:
        raise ValueError("--workers must be >= 1")
    if args.address is not None and args.backend != "ray":
        raise ValueError("--address needs --backend ray")
    if args.address is not None and given(args.workers):
        raise ValueError("--workers is ignored with --address: the Ray cluster's CPUs run the episodes")
    if args.backend == "ray":
        from envs.evaluation.pool import require_ray

        require_ray()


def replay_predictors(args: argparse.Namespace, configs: list[PolicyConfig]) -> tuple[list[PolicyConfig], str | None]:
    """For --scenario replay: each predictor policy as it runs on this recording (a known ETH/UCY test recording:
    the scene's leave-one-out model of the reference suite's real cell, `PolicyConfig.for_cell`; a given --predictor
    wins, `{scene}` in it is filled in), and one line saying which predictor each uses (None: nothing to say)."""
    if args.scenario != REPLAY_SCENARIO:
        return configs, None
    from envs.evaluation.suite import REFERENCE_SUITE, recording_cell

    cell = recording_cell(args.replay_file)
    if cell is not None:
        configs = [p.for_cell(cell.scene, cell.predictor) for p in configs]
    used = ", ".join(f"{p.name} predicts with {p.predictor_used()}" for p in configs if p.predictor_used())
    if not used:
        return configs, None
    name = args.replay_file.name
    if cell is None:
        why = "" if args.predictor else " (the default, trained on crowdsim; --predictor NAME to change it)"
        return configs, f"crowdnav: {name} is no known ETH/UCY test recording: {used}{why}"
    why = "" if args.predictor else f" (the scene's leave-one-out model, as in {REFERENCE_SUITE}'s {cell.name}; " \
        "--predictor NAME overrides)"
    return configs, f"crowdnav: {name} is ETH/UCY scene {cell.scene}'s test recording: {used}{why}"


def check_env_flags(args: argparse.Namespace) -> None:
    """`crowdnav evaluate`'s env flags in range, each error naming its flag (before a config would name its own
    field: `--pedestrians must be >= 1, got -3`, not `n_pedestrians ...`)."""
    for flag, value, low in (("--pedestrians", args.pedestrians, 1), ("--wall-rays", args.wall_rays, 0)):
        if value is not None and value < low:
            raise ValueError(f"{flag} must be >= {low}, got {value}")
    for flag, value in (("--time-limit", args.time_limit), ("--frame-step", args.frame_step)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{flag} must be a positive finite number of seconds, got {value}")
    if args.fov_deg is not None and not 0 < args.fov_deg <= 360:
        raise ValueError(f"--fov-deg must be in (0, 360] degrees (360: all round), got {args.fov_deg}")


def check_input_files(args: argparse.Namespace) -> None:
    """`crowdnav evaluate`'s input files there, each error naming its flag (not Python's "[Errno 2] ...")."""
    for flag, path in (("--replay-file", args.replay_file), ("--groups-file", args.groups_file)):
        if path is not None and not path.is_file():
            raise ValueError(f"{flag} {path}: {'not a file' if path.exists() else 'no such file'}")
