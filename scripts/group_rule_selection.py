"""Choose the settings of the group rules on the UCY group annotations (validation), with a leave-one-file-out check.

    python scripts/group_rule_selection.py --groups ../shared/datasets/eth_ucy_groups --json out/simreal/rules.json
    python scripts/group_rule_selection.py --groups ../shared/datasets/eth_ucy_groups --track-steps 8,12,20,32,48,80

Scores every setting of a small grid (predictor.group_rules: CoherentMotionRule over distance_m x rel_speed_mps x
linkage, ProximityRule over radius_m x steps) on every window of each annotated recording (``gpgraph groups``'
windows, students003's overlapping lines merged and its two absent ids dropped, both noted), then:

- the choice: the setting with the highest mean PW F1 over the recordings (ties: mean G-MITRE F1), per family;
- leave-one-file-out: for each recording, the setting chosen on the other two, scored on it. This is the honest
  estimate of how a chosen rule does on people it was not chosen on; the choice's own scores are optimistic.

``--track-steps``: the rules read each pedestrian's last H positions up to the window's last observed one
(``predictor.windows.window_tracks``, NaN before it was first seen) instead of the 8 observed steps; one table per H
(how ``coherent-motion-track``'s 48 was chosen).

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


def grid(track_steps: int = 8) -> dict[str, GroupRule]:
    """Every candidate reading ``track_steps`` positions per pedestrian, keyed by a readable name."""
    rules: dict[str, GroupRule] = {}
    for link, d, v in itertools.product(("average", "single"), DISTANCES_M, REL_SPEEDS_MPS):
        rules[f"coherent-{link}-{d}m-{v}mps"] = CoherentMotionRule(distance_m=d, rel_speed_mps=v, linkage=link,
                                                                   track_steps=track_steps)
    for steps, r in itertools.product(("last", "max", "mean"), RADII_M):
        rules[f"proximity-{steps}-{r}m"] = ProximityRule(radius_m=r, steps=steps, track_steps=track_steps)
    return rules


def family(name: str) -> str:
    return name.rsplit("-", 2)[0] if name.startswith("coherent") else "-".join(name.split("-")[:2])


def choose(scores: dict[str, dict[str, dict]], files: list[str]) -> str:
    """The name with the highest mean PW F1 over ``files`` (ties: mean G-MITRE F1)."""
    return max(scores, key=lambda n: (np.mean([scores[n][f]["pw_f1"] for f in files]),
                                      np.mean([scores[n][f]["gmitre_f1"] for f in files])))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    p.add_argument("--data", type=Path, default=DEFAULT_DATA_DIR)
    p.add_argument("--groups", type=Path, required=True, help="folder of X.groups.txt (UCY annotations)")
    p.add_argument("--track-steps", default="8", metavar="H[,H...]",
                   help="positions the rules read per pedestrian (8: the window's observed steps)")
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    try:
        steps = [int(h) for h in args.track_steps.split(",")]
        if min(steps) < 8:
            raise ValueError(f"--track-steps must be >= 8, got {args.track_steps}")
        recordings = read_annotations(args.data, args.groups, overlaps="merge", absent_ids="drop")
    except (FileNotFoundError, ValueError) as exc:
        print(f"group_rule_selection: error: {exc}", file=sys.stderr)
        return 2
    out = {}
    for h in steps:
        print(f"track steps {h}" + (" (the window's observed steps)" if h == 8 else ""))
        out[h] = select(recordings, h)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out if len(steps) > 1 else out[steps[0]], indent=1) + "\n")
    return 0


def select(recordings: list, track_steps: int) -> dict:
    """Score the grid on ``track_steps`` positions per pedestrian (8: each window's observed steps exactly); print
    the choice and the leave-one-file-out scores per family."""
    files = [r.name for r in recordings]
    track = {id(w): t for r in recordings
             for w, t in zip(r.windows, window_tracks(r.rows, r.windows, track_steps), strict=True)}
    scores = {name: {r.name: summary(score_windows(r.windows, lambda w, rule=rule: rule(track[id(w)])))
                     for r in recordings} for name, rule in grid(track_steps).items()}
    out: dict = {"files": files, "scores": scores, "chosen": {}, "leave_one_file_out": {}}
    print(f"{'family':<20} {'chosen on all three':<34} " + " ".join(f"{f:>14}" for f in files) + "   mean PW/G-MITRE")
    for fam in sorted({family(n) for n in scores}):
        cand = {n: s for n, s in scores.items() if family(n) == fam}
        best = choose(cand, files)
        out["chosen"][fam] = best
        cells = " ".join(f"{cand[best][f]['pw_f1']:>6.3f}/{cand[best][f]['gmitre_f1']:.3f}" for f in files)
        mean = (np.mean([cand[best][f]["pw_f1"] for f in files]), np.mean([cand[best][f]["gmitre_f1"] for f in files]))
        print(f"{fam:<20} {best:<34} {cells}   {mean[0]:.3f}/{mean[1]:.3f}")
        lofo = {f: (held := choose(cand, [g for g in files if g != f]), cand[held][f]) for f in files}
        out["leave_one_file_out"][fam] = {f: {"chosen": n, **s} for f, (n, s) in lofo.items()}
        cells = " ".join(f"{s['pw_f1']:>6.3f}/{s['gmitre_f1']:.3f}" for _, s in lofo.values())
        mean = (np.mean([s["pw_f1"] for _, s in lofo.values()]), np.mean([s["gmitre_f1"] for _, s in lofo.values()]))
        print(f"{'':<20} {'leave-one-file-out':<34} {cells}   {mean[0]:.3f}/{mean[1]:.3f}")
    return out


if __name__ == "__main__":
    sys.exit(main())
