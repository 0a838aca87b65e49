"""Choose the settings of the group rules on the UCY group annotations (validation), with a leave-one-file-out check.

    python scripts/group_rule_selection.py --groups ../shared/datasets/eth_ucy_groups --json out/simreal/rules.json
    python scripts/group_rule_selection.py --groups ../shared/datasets/eth_ucy_groups --track-steps 8,12,20,32,48,80
    python scripts/group_rule_selection.py --groups ../shared/datasets/eth_ucy_groups --families coherent-average \
        --criterion worst

Scores every setting of a small grid (predictor.group_rules: CoherentMotionRule over distance_m x rel_speed_mps x
linkage, the motion-aware ``coherent-average-stand`` family over distance_m x rel_speed_mps x stand_speed_mps x
stand_distance_m, ProximityRule over radius_m x steps) on every window of each annotated recording (``gpgraph groups``'
windows, students003's overlapping lines merged and its two absent ids dropped, both noted), then:

- the choice: the setting with the highest mean PW F1 over the recordings (ties: mean G-MITRE F1), per family;
  ``--criterion worst``: the highest PW F1 of its worst recording instead (ties: mean PW F1), a choice that must
  hold on every recording rather than on average;
- leave-one-file-out: for each recording, the setting chosen on the other two, scored on it. This is the honest
  estimate of how a chosen rule does on people it was not chosen on; the choice's own scores are optimistic.

``--track-steps``: the rules read each pedestrian's last H positions up to the window's last observed one
(``predictor.windows.window_tracks``, NaN before it was first seen) instead of the 8 observed steps; one table per H
(how ``coherent-motion-track``'s 48 was chosen). ``--families``: only the families whose names start with one of
these (the full grid takes minutes per H on two cores). Each row also prints the worst recording's PW F1.

The annotations are for validation only: nothing is trained on them. The BIWI scenes (eth, hotel) are never read.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

from predictor.ethucy import DEFAULT_DATA_DIR
from predictor.group_rules import CoherentMotionRule, GroupRule, ProximityRule
from predictor.group_validation import read_annotations, score_windows, summary
from predictor.windows import window_tracks

DISTANCES_M = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0)
REL_SPEEDS_MPS = (0.3, 0.5, 0.8, 1.2)
RADII_M = (0.75, 1.0, 1.25, 1.5, 2.0)
# the motion-aware family (a pair with a standing member measured against stand_distance_m): around the plain
# rule's choice, so the grid stays small enough for two cores
STAND_DISTANCES_M = (1.25, 1.5, 2.0)
STAND_REL_SPEEDS_MPS = (0.8, 1.2)
STAND_SPEEDS_MPS = (0.2, 0.3, 0.5)
STAND_RADII_M = (0.6, 0.75, 0.9, 1.0, 1.25)
CRITERIA = ("mean", "worst")


def grid(track_steps: int = 8) -> dict[str, GroupRule]:
    """Every candidate reading ``track_steps`` positions per pedestrian, keyed by a readable name."""
    rules: dict[str, GroupRule] = {}
    for link, d, v in itertools.product(("average", "single"), DISTANCES_M, REL_SPEEDS_MPS):
        rules[f"coherent-{link}-{d}m-{v}mps"] = CoherentMotionRule(distance_m=d, rel_speed_mps=v, linkage=link,
                                                                   track_steps=track_steps)
    for d, v, vs, ds in itertools.product(STAND_DISTANCES_M, STAND_REL_SPEEDS_MPS, STAND_SPEEDS_MPS, STAND_RADII_M):
        if ds <= d:
            rules[f"coherent-average-stand-{d}m-{v}mps-{vs}mps-{ds}m"] = CoherentMotionRule(
                distance_m=d, rel_speed_mps=v, track_steps=track_steps, stand_speed_mps=vs, stand_distance_m=ds)
    for steps, r in itertools.product(("last", "max", "mean"), RADII_M):
        rules[f"proximity-{steps}-{r}m"] = ProximityRule(radius_m=r, steps=steps, track_steps=track_steps)
    return rules


def family(name: str) -> str:
    if name.startswith("coherent-average-stand"):
        return "coherent-average-stand"
    return name.rsplit("-", 2)[0] if name.startswith("coherent") else "-".join(name.split("-")[:2])


def choose(scores: dict[str, dict[str, dict]], files: list[str], criterion: str = "mean") -> str:
    """The name with the highest mean PW F1 over ``files`` (ties: mean G-MITRE F1); ``criterion`` "worst": the
    highest PW F1 of the worst of ``files`` (ties: mean PW F1, then mean G-MITRE F1)."""
    def key(n: str) -> tuple[float, ...]:
        pw = [scores[n][f]["pw_f1"] for f in files]
        mean = (float(np.mean(pw)), float(np.mean([scores[n][f]["gmitre_f1"] for f in files])))
        return (min(pw), *mean) if criterion == "worst" else mean
    return max(scores, key=key)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    p.add_argument("--data", type=Path, default=DEFAULT_DATA_DIR)
    p.add_argument("--groups", type=Path, required=True, help="folder of X.groups.txt (UCY annotations)")
    p.add_argument("--track-steps", default="8", metavar="H[,H...]",
                   help="positions the rules read per pedestrian (8: the window's observed steps)")
    p.add_argument("--families", default="", metavar="PREFIX[,PREFIX...]",
                   help="only the families whose names start with one of these (default: all)")
    p.add_argument("--criterion", choices=CRITERIA, default="mean",
                   help="choose by the mean PW F1 over the recordings or by the worst recording's")
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    try:
        steps = [int(h) for h in args.track_steps.split(",")]
        if min(steps) < 8:
            raise ValueError(f"--track-steps must be >= 8, got {args.track_steps}")
        prefixes = tuple(f for f in args.families.split(",") if f)
        families = sorted({family(n) for n in grid()})
        if prefixes and not any(f.startswith(prefixes) for f in families):
            raise ValueError(f"--families {args.families} matches no family; valid: {', '.join(families)}")
        recordings = read_annotations(args.data, args.groups, overlaps="merge", absent_ids="drop")
    except (FileNotFoundError, ValueError) as exc:
        print(f"group_rule_selection: error: {exc}", file=sys.stderr)
        return 2
    out = {}
    for h in steps:
        print(f"track steps {h}" + (" (the window's observed steps)" if h == 8 else ""))
        out[h] = select(recordings, h, prefixes, args.criterion)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out if len(steps) > 1 else out[steps[0]], indent=1) + "\n")
    return 0


def _row(label: str, best: str, cells: list[dict]) -> str:
    pw = [c["pw_f1"] for c in cells]
    text = " ".join(f"{c['pw_f1']:>6.3f}/{c['gmitre_f1']:.3f}" for c in cells)
    return (f"{label:<22} {best:<44} {text}   {np.mean(pw):.3f}/{np.mean([c['gmitre_f1'] for c in cells]):.3f}"
            f"   {min(pw):.3f}")


def select(recordings: list, track_steps: int, prefixes: tuple[str, ...] = (), criterion: str = "mean") -> dict:
    """Score the grid's families starting with ``prefixes`` (all if empty) on ``track_steps`` positions per
    pedestrian (8: each window's observed steps exactly); print the choice by ``criterion`` and the
    leave-one-file-out scores per family."""
    files = [r.name for r in recordings]
    track = {id(w): t for r in recordings
             for w, t in zip(r.windows, window_tracks(r.rows, r.windows, track_steps), strict=True)}
    rules = {n: r for n, r in grid(track_steps).items() if not prefixes or family(n).startswith(prefixes)}
    scores = {name: {r.name: summary(score_windows(r.windows, lambda w, rule=rule: rule(track[id(w)])))
                     for r in recordings} for name, rule in rules.items()}
    out: dict = {"files": files, "criterion": criterion, "scores": scores, "chosen": {}, "leave_one_file_out": {}}
    print(f"{'family':<22} {'chosen on all three (' + criterion + ')':<44} "
          + " ".join(f"{f:>14}" for f in files) + "   mean PW/G-MITRE   worst PW")
    for fam in sorted({family(n) for n in scores}):
        cand = {n: s for n, s in scores.items() if family(n) == fam}
        best = choose(cand, files, criterion)
        out["chosen"][fam] = best
        print(_row(fam, best, [cand[best][f] for f in files]))
        lofo = {f: (held := choose(cand, [g for g in files if g != f], criterion), cand[held][f]) for f in files}
        out["leave_one_file_out"][fam] = {f: {"chosen": n, **s} for f, (n, s) in lofo.items()}
        print(_row("", "leave-one-file-out", [s for _, s in lofo.values()]))
    return out


if __name__ == "__main__":
    sys.exit(main())
