"""Walking speed by group size, and the share of people in groups over time, in the built-in scenario crowds
(issue 50, item 3).

The open-space calibration (scripts/calibrate_group_speed.py) checks Moussaïd et al.'s (2010, Fig. 2, low
density) fall of walking speed with group size, 0.04 m/s per member, in a sparse plaza. This measures it in the
crowds the benchmarks use: `SimConfig(scenario, n_pedestrians=24)` with everything else at its defaults (the env's
crowd; `--people` to change), for plaza, corridor and crossing.

Per group: the mean over its members of each member's mean speed over its walking steps (not stopping or standing;
its first 2 s, the acceleration from rest, left out), `crowdsim.walking.group_walks`; per size, the mean over groups
with a 95 % percentile bootstrap interval over groups (frames of one walk are correlated; groups are the units).
Also the desired speeds of those groups (what they were drawn with); the speed relative to people alone with each
group's draw of desired speed replaced by its expectation (`GroupWalks.relative_by_size`: the same expectation as
the plain difference of means, a fraction of its spread; the interval leaves out the singles' own small error);
and the grouped share (the fraction of active pedestrians in groups of two or more): its mean over all recorded
steps (interval: bootstrap over runs, each run's mean one unit), and the range over time windows of `--window-s`
of the seeds' mean in each window (a drift over the run shows as a wide range). Seeds 2000-2009 for the docs'
numbers; the test uses 10-25.

    .venv/bin/python scripts/measure_group_speed.py --seeds 2000-2009 --duration-s 600

`--small`: 2 seeds x 60 s of plaza only, for the test (tests/crowdsim/test_group_speed.py).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from crowdsim.config import GroupConfig, GroupForceParams, SimConfig, SocialForceParams
from crowdsim.walking import GroupWalks, group_walks

SCENARIOS = ("plaza", "corridor", "crossing")
SIZES = (1, 2, 3, 4, 5)


def bootstrap_mean(values: np.ndarray, rng: np.random.Generator, draws: int = 2000) -> tuple[float, float, float]:
    """(mean, 2.5th, 97.5th percentile of the bootstrap means) of values (n,); NaNs for n < 2."""
    if len(values) < 2:
        mean = float(values.mean()) if len(values) else float("nan")
        return mean, float("nan"), float("nan")
    means = values[rng.integers(0, len(values), (draws, len(values)))].mean(axis=1)
    return float(values.mean()), float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def window_shares(share: np.ndarray, steps_per_window: int) -> np.ndarray:
    """(W,) mean grouped share in each whole time window of steps_per_window steps, over runs and steps;
    share (R, T)."""
    w = share.shape[1] // steps_per_window
    return np.nanmean(share[:, : w * steps_per_window].reshape(len(share), w, steps_per_window), axis=(0, 2))


def summarise(walks: GroupWalks, steps_per_window: int, drop_per_member_mps: float, seed: int = 0) -> dict:
    """Per size (mean, lo, hi, groups, mean desired), per size the same of the speed relative to people alone
    (`GroupWalks.relative_by_size` less its mean for size 1) and the share (mean, window min, window max)."""
    rng = np.random.default_rng(seed)
    sizes = {n: (*bootstrap_mean(walks.by_size(n), rng), int((walks.size == n).sum()),
                 float(walks.desired[walks.size == n].mean()) if (walks.size == n).any() else float("nan"))
             for n in SIZES}
    alone = float(walks.relative_by_size(1, drop_per_member_mps).mean())
    relative = {n: bootstrap_mean(walks.relative_by_size(n, drop_per_member_mps) - alone, rng) for n in SIZES}
    windows = window_shares(walks.share, steps_per_window)
    _, share_lo, share_hi = bootstrap_mean(np.nanmean(walks.share, axis=1), rng)
    return {"sizes": sizes, "relative": relative, "share_interval": (share_lo, share_hi),
            "share": (float(np.nanmean(walks.share)), float(windows.min()), float(windows.max()))}


def config_for(scenario: str, people: int, overrides: dict[str, dict[str, float]]) -> SimConfig:
    config = SimConfig(scenario=scenario, n_pedestrians=people)
    return replace(config, groups=replace(GroupConfig(), **overrides.get("groups", {})),
                   group_forces=replace(GroupForceParams(), **overrides.get("group_forces", {})),
                   social=replace(SocialForceParams(), **overrides.get("social", {})))


def report(scenario: str, result: dict) -> None:
    print(f"## {scenario}")
    print("size | groups | speed m/s [95% CI]     | desired m/s | relative to alone m/s [95% CI]")
    for n, (mean, lo, hi, count, want) in result["sizes"].items():
        rel, rlo, rhi = result["relative"][n]
        print(f"{n:4d} | {count:6d} | {mean:.3f} [{lo:.3f}, {hi:.3f}] | {want:11.3f} | {rel:+.3f} [{rlo:+.3f}, "
              f"{rhi:+.3f}]")
    mean, lo, hi = result["share"]
    slo, shi = result["share_interval"]
    print(f"grouped share: mean {mean:.3f} [{slo:.3f}, {shi:.3f}] (95% over runs), window range [{lo:.3f}, {hi:.3f}]",
          flush=True)


def parse_overrides(items: list[str]) -> dict[str, dict[str, float]]:
    """`groups.field=value` / `group_forces.field=value` / `social.field=value` strings to {part: {field: value}}."""
    out: dict[str, dict[str, float]] = {}
    for item in items:
        key, _, value = item.partition("=")
        part, _, name = key.partition(".")
        fields = {"groups": GroupConfig, "group_forces": GroupForceParams, "social": SocialForceParams}.get(part)
        if fields is None or name not in fields.__dataclass_fields__ or not value:
            raise ValueError(f"--set {item!r}: expected groups.FIELD=VALUE, group_forces.FIELD=VALUE or "
                             "social.FIELD=VALUE")
        out.setdefault(part, {})[name] = float(value)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    ap.add_argument("--seeds", default="2000-2009", help="first-last (inclusive)")
    ap.add_argument("--duration-s", type=float, default=600.0)
    ap.add_argument("--window-s", type=float, default=60.0)
    ap.add_argument("--people", type=int, default=24)
    ap.add_argument("--set", action="append", default=[],
                    help="groups.FIELD=VALUE, group_forces.FIELD=VALUE or social.FIELD=VALUE (e.g. "
                    "social.detour_clearance_m=0.6: people walk round wall corners)")
    ap.add_argument("--small", action="store_true", help="2 seeds x 60 s of plaza (the test's size)")
    args = ap.parse_args(argv)
    try:
        lo, _, hi = args.seeds.partition("-")
        seeds = range(int(lo), int(hi or lo) + 1)
        overrides = parse_overrides(args.set)
        configs = {s: config_for(s, args.people, overrides) for s in args.scenarios}
        if not (seeds and args.duration_s > 0 and args.window_s > 0):
            raise ValueError("--seeds must be first-last with first <= last, --duration-s and --window-s > 0")
    except ValueError as exc:
        print(f"measure_group_speed: {exc}", file=sys.stderr)
        return 2
    if args.small:
        configs, seeds, args.duration_s, args.window_s = {"plaza": configs.get("plaza", config_for(
            "plaza", args.people, overrides))}, seeds[:2], 60.0, 20.0
    for scenario, config in configs.items():
        steps = int(round(args.duration_s / config.record_dt_s))
        window = max(1, int(round(args.window_s / config.record_dt_s)))
        walks = group_walks(config, seeds, steps)
        report(scenario, summarise(walks, window, config.groups.speed_drop_per_member_mps))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
