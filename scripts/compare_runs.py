"""Compare one policy between two benchmark runs on the same episodes (paired, exact McNemar).

Two runs of `crowdnav benchmark` with different settings (for example `--mpc max_peds=12` against the default)
write records under the same policy name; this pairs them by (cell, seed) and prints, per cell and pooled, the
counts of each event in run A and run B, the discordant pairs and the two-sided exact McNemar p-value, then each
run's social-navigation metrics ("n/a" for records written before them). Use it on
the tuning suite (`--suite crowdnav-tune`), never to choose settings on a reported suite.

    .venv/bin/python scripts/compare_runs.py out/tune-base/records.jsonl out/tune-peds12/records.jsonl \
        --policy mpc-gpgraph
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from envs.evaluation.records import EpisodeRecord, read_records
from envs.evaluation.report import SOCIAL_ROWS
from envs.evaluation.stats import PAIRED_EVENTS, aggregate, paired_comparison

EVENTS = tuple(PAIRED_EVENTS)  # success, collision, avoidable collision, group intrusion


def compare(a: list[EpisodeRecord], b: list[EpisodeRecord]) -> list[tuple[str, dict]]:
    """(cell or "pooled", paired_comparison of a against b) per cell both runs share, then pooled."""
    cells = sorted({r.cell for r in a} & {r.cell for r in b})
    rows = [(c, paired_comparison([r for r in a if r.cell == c], [r for r in b if r.cell == c])) for c in cells]
    shared_a = [r for r in a if r.cell in cells]
    return [*rows, ("pooled", paired_comparison(shared_a, [r for r in b if r.cell in cells]))]


def social_lines(a: list[EpisodeRecord], b: list[EpisodeRecord]) -> list[str]:
    """Per cell both runs share, then pooled: each social-navigation metric of run A and run B ("n/a" where a run's
    records predate these metrics)."""
    cells = sorted({r.cell for r in a} & {r.cell for r in b})
    out = []
    for cell in [*cells, "pooled"]:
        ra, rb = (aggregate([r for r in rs if r.cell == cell or (cell == "pooled" and r.cell in cells)])
                  for rs in (a, b))
        out += [f"{cell:30s} {name}: A {f(ra)} | B {f(rb)}" for name, f in SOCIAL_ROWS]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("run_a", type=Path, help="records.jsonl of run A")
    ap.add_argument("run_b", type=Path, help="records.jsonl of run B")
    ap.add_argument("--policy", required=True, help="policy name in both runs")
    args = ap.parse_args(argv)
    try:
        a, b = ([r for r in read_records(p) if r.policy == args.policy] for p in (args.run_a, args.run_b))
    except (OSError, ValueError) as exc:
        print(f"compare_runs: error: {exc}", file=sys.stderr)
        return 2
    if not a or not b:
        print(f"compare_runs: error: policy {args.policy!r} has no records in one of the runs", file=sys.stderr)
        return 2
    print(f"{args.policy}: A = {args.run_a}, B = {args.run_b}")
    print(f"{'cell':30s} {'pairs':>5s} " + " ".join(f"{e + ' A/B (A only, B only) p':>44s}" for e in EVENTS))
    for cell, cmp in compare(a, b):
        parts = [f"{cmp[e]['a']:4d}/{cmp[e]['b']:<4d} ({cmp[e]['a_only']:3d}, {cmp[e]['b_only']:3d}) "
                 f"p={cmp[e]['p_value']:.3g}{'*' if cmp[e]['significant'] else ' '}" for e in EVENTS]
        print(f"{cell:30s} {cmp['pairs']:5d} " + " ".join(f"{p:>44s}" for p in parts))
    print("\nsocial-navigation metrics (all completed episodes; n/a: not in that run's records)")
    print("\n".join(social_lines(a, b)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
