"""Shared `crowdnav` options: the flags that map onto `PolicyConfig` and the run backend, and their checks.

Every flag has a default shown in --help; a misspelt flag, an unknown name or a flag that the chosen policy
ignores is an error (one line on stderr, exit 2), raised before any episode runs.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import fields, replace
from typing import Any

from envs.evaluation.pool import BACKENDS
from envs.policies import ENV_MPC, POLICIES, PREDICTOR_POLICIES, REPLAN_EVERY_STEPS, PolicyConfig
from envs.policies.plugins import is_plugin


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


def add_policy_options(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument("--policy", nargs="+", action="extend", required=required, metavar="NAME",
                   help="one or more (repeatable) of: " + ", ".join(POLICIES)
                   + ", module:factory (a Policy plug-in) or sb3:PATH.zip (a stable-baselines3 agent)")
    p.add_argument("--predictor", default=None, metavar="NAME",
                   help="for mpc-gpgraph and plug-in policies: predictor name, checkpoint path or module:factory "
                   "(default: the shipped gpgraph-stgcnn-synthetic)")
    p.add_argument("--samples", type=int, default=PolicyConfig.n_samples, metavar="K",
                   help="predicted samples per plan")
    p.add_argument("--replan-every", type=int, default=REPLAN_EVERY_STEPS, metavar="STEPS",
                   help="env steps between re-plans")
    p.add_argument("--threads", type=int, default=PolicyConfig.threads, help="torch threads per process")
    p.add_argument("--mpc", action="append", default=[], metavar="FIELD=VALUE",
                   help="override an MPCConfig field of the MPC policies (repeatable), e.g. safety_margin_m=0.4")


def add_backend_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=default_workers(), help="processes (1: in this process)")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local process pool or Ray tasks (the 'ray' extra)")
    p.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="Ray cluster to connect to (default: start a local Ray instance); needs --backend ray")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _mpc_overrides(items: list[str]) -> dict[str, Any]:
    valid = {f.name: f for f in fields(ENV_MPC) if f.name not in ("robot", "weights")}
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or key not in valid:
            raise ValueError(f"--mpc {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(valid)}")
        current = getattr(ENV_MPC, key)
        try:
            if isinstance(current, bool):
                if text.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(text)
                out[key] = text.lower() in ("true", "1")
            else:
                out[key] = type(current)(text)
        except ValueError as exc:
            raise ValueError(f"--mpc {item!r}: {text!r} is not a {type(current).__name__}") from exc
    return out


def policy_configs(args: argparse.Namespace) -> list[PolicyConfig]:
    """The `PolicyConfig`s the flags describe (ValueError on a bad or ignored flag)."""
    if len(set(args.policy)) != len(args.policy):
        raise ValueError("a policy is named twice")
    if args.mpc and not any(n.startswith("mpc-") or is_plugin(n) for n in args.policy):
        raise ValueError("--mpc applies only to the MPC policies (mpc-gpgraph, mpc-cv, mpc-none) and plug-ins")
    mpc = replace(ENV_MPC, **_mpc_overrides(args.mpc))
    configs = [PolicyConfig(name=n, mpc=mpc, replan_every_steps=args.replan_every, n_samples=args.samples,
                            threads=args.threads) for n in args.policy]
    if args.predictor is not None:
        takes = [c for c in configs if c.name in PREDICTOR_POLICIES or is_plugin(c.name)]
        if not takes:
            raise ValueError("--predictor applies only to mpc-gpgraph and module:factory policies")
        configs = [replace(c, predictor=args.predictor) if c in takes else c for c in configs]
    return configs


def check_backend(args: argparse.Namespace) -> None:
    if args.workers < 1:
        raise ValueError("--workers must be >= 1")
    if args.address is not None and args.backend != "ray":
        raise ValueError("--address needs --backend ray")
    if args.backend == "ray":
        from envs.evaluation.pool import require_ray

        require_ray()
