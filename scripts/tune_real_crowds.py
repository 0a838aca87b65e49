"""Tune the crowd MPC among real (replayed ETH/UCY) pedestrians on recordings disjoint from the reported ones.

Runs N episodes per recording for each (policy, MPC variant) on the same seeds, in at most 2 worker processes,
and prints one row per (recording, policy, variant): success / collision (of which kind "spawn",
`envs.scoring.collisions`) / timeout rates and plan-time p50/p95 (ms, every solver call). Episodes follow the
suites' rules (the defaults of `crowdnav-tune`, equal to crowdnav-v1's: 40 s, a spawn contact does not end the
episode), and each collision line names its kind (robot / pedestrian). For the paired, suite-based check on the
tuning suite see `crowdnav benchmark --suite crowdnav-tune` and `scripts/compare_runs.py`.

A variant is ``NAME`` or ``NAME:field=value,field=value`` where the fields are `MPCConfig` fields applied on top
of the base settings (``--base env``: the env's `ENV_MPC`; ``--base crowd``: `planner.CROWD_MPC`), e.g.
``--variant base --variant wide:safety_margin_m=0.4,shield_margin_m=0.2``; a nested config's defaults as
``foresight=default``. ``weights.<name>=value``
sets a cost weight. Tune only on recordings that are not reported (the defaults: crowds_zara03, uni_examples).
Both are sparse (median 3-6 people per frame against 34-49 in the univ test scene); ``--overlay K`` superimposes
K time-shifted copies of each for a dense tuning crowd (the env's ``ReplayConfig.overlay``; before 2026-11-27
this script wrote its own overlaid files, with other ids, which the decision records of earlier runs used).

    .venv/bin/python scripts/tune_real_crowds.py --episodes 20 --variant base --variant crowd:@crowd
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
import time
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from crowdsim.distributed import WorkerDied, process_context, run_in_processes
from predictor.ethucy import DEFAULT_DATA_DIR

DATA = DEFAULT_DATA_DIR / "eth"  # ETH/UCY (predictor.ethucy; ETH_UCY_DIR overrides it)
DEFAULT_RECORDINGS = (DATA / "train/crowds_zara03_train.txt", DATA / "train/uni_examples_train.txt")
POLICIES = ("mpc-gpgraph", "mpc-cv")
TUNING_SUITE = "crowdnav-tune"  # its defaults (the same as crowdnav-v1's) set the episodes' rules
REPORTED = ("biwi_eth", "biwi_hotel", "students001", "students003", "crowds_zara01", "crowds_zara02")


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME[:k=v,k=v]`` -> (name, overrides); ``NAME:@crowd`` starts from planner.CROWD_MPC's fields."""
    name, _, rest = text.partition(":")
    overrides: dict = {}
    for item in filter(None, rest.split(",")):
        if item == "@crowd":
            overrides["@crowd"] = True
            continue
        key, _, value = item.partition("=")
        try:
            overrides[key.strip()] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            overrides[key.strip()] = value.strip()
    return name, overrides


def build_mpc_config(robot, overrides: dict, base: str):
    """The MPC config of a variant: base settings (env or crowd), the robot of the env, then overrides."""
    from envs.policies import ENV_MPC
    from planner import CROWD_MPC

    cfg = CROWD_MPC if base == "crowd" or overrides.get("@crowd") else ENV_MPC
    top = {k: v for k, v in overrides.items() if "." not in k and k != "@crowd"}
    weights = {k.split(".", 1)[1]: v for k, v in overrides.items() if k.startswith("weights.")}
    known = {f.name for f in fields(cfg)}
    unknown = set(top) - known
    if unknown:
        raise ValueError(f"unknown MPCConfig fields {sorted(unknown)}")
    from envs.cli_options import NESTED

    top = {k: NESTED[k]() if k in NESTED and v == "default" else v for k, v in top.items()}  # e.g. foresight=default
    return replace(cfg, robot=robot, weights=replace(cfg.weights, **weights), **top)


# -- worker side ---------------------------------------------------------------------------------------------
_CACHE: dict = {}


def _env_and_policy(recording: str, policy: str, variant: str, overrides: dict, base: str,
                    predictor: str | None = None, overlay: int = 1):
    """The (config, env, policy) of a task, built once per process; predictor: mpc-gpgraph's (None: the env's);
    overlay: copies of the recording superimposed (`ReplayConfig.overlay`)."""
    key = (recording, policy, variant, predictor, overlay)
    if key not in _CACHE:
        from envs.config import CrowdNavConfig
        from envs.crowds.replay import ReplayConfig
        from envs.env import CrowdNavEnv
        from envs.evaluation.suite import load_suite
        from envs.policies import GPGraphPolicy, PlannerPolicy, singleton_prediction
        from planner import ConstantVelocityMPC

        defaults = load_suite(TUNING_SUITE).cells[0].defaults  # the suites' episode rules (time limit, spawns)
        cfg = CrowdNavConfig(scenario="replay", **defaults, replay=ReplayConfig(
            path=recording, frame_step_s=0.4, min_remaining_s=float(defaults["time_limit_s"]), overlay=overlay))
        env = CrowdNavEnv(cfg)
        mpc_cfg = build_mpc_config(cfg.robot, overrides, base)
        if policy == "mpc-gpgraph":
            pol = GPGraphPolicy(mpc_cfg) if predictor is None else GPGraphPolicy(mpc_cfg, predictor)
        else:
            pol = PlannerPolicy("mpc-cv", ConstantVelocityMPC(mpc_cfg), singleton_prediction)
        _CACHE[key] = (cfg, env, pol)
    return _CACHE[key]


def _collision_geometry(env) -> dict:
    """At the end of a collision episode: robot speed (m/s) and where the nearest pedestrian came from
    (bearing in the robot frame, deg; 0 = ahead) and its speed (m/s)."""
    state = env.robot_state
    peds = env.pedestrians()
    if len(peds.pos) == 0:
        return {}
    rel = peds.pos - state[:2]
    i = int(np.argmin(np.linalg.norm(rel, axis=1)))
    bearing = np.degrees(np.arctan2(rel[i, 1], rel[i, 0]) - state[2])
    seen = env.history.times_seen(peds.ped_id[i])  # 0.4 s snapshots (of the last 8) that contain the collider
    return {"robot_speed": float(state[3]), "bearing_deg": float((bearing + 180) % 360 - 180),
            "ped_speed": float(np.linalg.norm(peds.vel[i])), "seen_snapshots": int(seen)}


def run_one(task: tuple) -> dict:
    """One episode: (recording, policy, variant, overrides, base, seed[, predictor[, overlay]]) -> a flat record;
    its "recording" is the file's stem, with `_x<overlay>` when overlaid."""
    import torch

    from envs.evaluation.episode import run_episode

    torch.set_num_threads(1)
    recording, policy, variant, overrides, base, seed, *rest = task
    cfg, env, pol = _env_and_policy(recording, policy, variant, overrides, base, *rest)
    result = run_episode(cfg, pol.name, seed, env=env, policy=pol)
    m = result.metrics
    overlay = rest[1] if len(rest) > 1 else 1
    label = Path(recording).stem + (f"_x{overlay}" if overlay > 1 else "")
    rec = {"recording": label, "policy": policy, "variant": variant, "seed": seed,
           "outcome": m["outcome"], "collision_with": m["collision_with"], "kind": m["at_fault"],
           "steps": m["steps"],
           "min_distance_m": m["min_distance_m"], "fallbacks": m["fallbacks"], "times_ms": result.solve_times_ms}
    if m["outcome"] == "collision":
        rec.update(_collision_geometry(env))
    return rec


# -- driver side ---------------------------------------------------------------------------------------------
def summarise(records: list[dict]) -> list[dict]:
    """One row per (recording, policy, variant), plus a pooled row per (policy, variant)."""
    rows = []
    keys = sorted({(r["recording"], r["policy"], r["variant"]) for r in records})
    pooled = sorted({("pooled", r["policy"], r["variant"]) for r in records})
    for rec_name, policy, variant in keys + pooled:
        sel = [r for r in records if r["policy"] == policy and r["variant"] == variant
               and rec_name in ("pooled", r["recording"])]
        times = np.concatenate([r["times_ms"] for r in sel]) if sel else np.zeros(0)
        n = len(sel)
        rows.append({"recording": rec_name, "policy": policy, "variant": variant, "n": n,
                     **{k: sum(r["outcome"] == k for r in sel) / n for k in ("success", "collision", "timeout")},
                     "spawn": sum(r.get("kind") == "spawn" for r in sel) / n,
                     "p50_ms": float(np.percentile(times, 50)) if times.size else float("nan"),
                     "p95_ms": float(np.percentile(times, 95)) if times.size else float("nan")})
    return rows


def print_table(rows: list[dict], variants: dict[str, dict]) -> None:
    print(f"{'recording':24s} {'policy':12s} {'variant':14s} {'n':>3s} {'success':>7s} {'collis':>7s} "
          f"{'(spawn)':>7s} {'timeout':>7s} {'p50ms':>6s} {'p95ms':>6s}")
    for r in rows:
        print(f"{r['recording']:24s} {r['policy']:12s} {r['variant']:14s} {r['n']:3d} {r['success']:7.2f} "
              f"{r['collision']:7.2f} {r['spawn']:7.2f} {r['timeout']:7.2f} {r['p50_ms']:6.1f} {r['p95_ms']:6.1f}")
    print("settings:")
    for name, ov in variants.items():
        print(f"  {name}: {ov or '(base)'}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recordings", nargs="+", default=[str(p) for p in DEFAULT_RECORDINGS])
    ap.add_argument("--policies", nargs="+", default=list(POLICIES), choices=POLICIES)
    ap.add_argument("--variant", action="append", default=None, help="NAME[:field=value,...] (repeatable)")
    ap.add_argument("--base", choices=("env", "crowd"), default="env", help="settings the overrides start from")
    ap.add_argument("--episodes", type=int, default=20, help="episodes per recording (seeds seed0, seed0+1, ..)")
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2, choices=(1, 2))
    ap.add_argument("--predictor", default=None, help="mpc-gpgraph's predictor (default: the env's); note that "
                    "every packaged ETH/UCY checkpoint was trained on the tuning recordings")
    ap.add_argument("--overlay", type=int, default=1, help="superimpose this many time-shifted copies of each "
                    "recording (denser crowds, e.g. 10 makes uni_examples about as dense as the univ test scene)")
    ap.add_argument("--json", type=Path, default=None, help="also write every episode's record here")
    args = ap.parse_args(argv)

    if any(tag in Path(rec).stem for rec in args.recordings for tag in REPORTED):
        print("refusing to tune on a reported test recording", file=sys.stderr)
        return 2
    if args.seed0 < 1000:
        print("tune on seeds 1000+", file=sys.stderr)
        return 2
    if args.overlay < 1:
        print("--overlay must be >= 1", file=sys.stderr)
        return 2
    variants = dict(parse_variant(v) for v in (args.variant or ["base"]))
    tasks = [(rec, pol, name, ov, args.base, seed, args.predictor, args.overlay)
             for rec in args.recordings for pol in args.policies for name, ov in variants.items()
             for seed in range(args.seed0, args.seed0 + args.episodes)]
    start = time.perf_counter()
    results: dict[int, dict] = {}
    for i, rec in run_in_processes(run_one, tasks, args.workers, process_context()):  # heals a dead worker
        if isinstance(rec, WorkerDied):
            print(f"episode {tasks[i][:3]} seed {tasks[i][5]} left out: {rec}", file=sys.stderr)
        else:
            results[i] = rec
    records = [results[i] for i in sorted(results)]
    print(f"{len(records)} episodes in {time.perf_counter() - start:.0f} s")
    for r in records:
        if r["outcome"] == "collision":
            geo = {k: round(r[k], 2) for k in ("robot_speed", "bearing_deg", "ped_speed", "seen_snapshots") if k in r}
            print(f"  collision {r['recording']} {r['policy']} {r['variant']} seed {r['seed']} step {r['steps']} "
                  f"{r['collision_with']} {r['kind']} {geo}")
    print_table(summarise(records), variants)
    if args.json:
        args.json.write_text(json.dumps(records))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
