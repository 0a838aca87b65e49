"""Score the baselines on a test split with the metrics ``gpgraph evaluate`` uses.

    python scripts/eval_baselines.py --data out/synthetic_predictor/data --seed 0 --trials 10 \
        --json out/synthetic_predictor/eval/constant-velocity.json
    python scripts/eval_baselines.py --data out/synthetic_predictor/data --split val --trials 1 \
        --json out/synthetic_predictor/eval/baselines-val.json   # choose a distance rule on val

``gpgraph evaluate`` only takes GP-Graph checkpoints, so this runs ``load_predictor("constant-velocity")``
(last-step velocity, per-pedestrian velocity noise of 0.05 m per step held over the horizon: its own
sampling, neither ``iid`` nor ``paper``) on the same windows (DATA/test) with the same metric functions:
best-of-K ADE/FDE, COL, TCC averaged over pedestrians and trials, and, since every pedestrian is its own
group, the all-singletons PW/G-MITRE baseline. Also reports the deterministic extrapolation (K = 1, no
noise) as ``ade_k1``/``fde_k1``, and under ``proximity`` distance-threshold grouping baselines: connected
components of the pedestrians closer than R m at the last observed step (``last``) or at every one of the 8
observed steps (``all``), R = 0.5 ... 2.0 m (crowdsim spawns group members 0.75 m apart), and the best of them
by PW F1 (``best_proximity``). ``--split val`` scores DATA/val instead (to choose a rule without the test split).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from predictor import metrics
from predictor.cli import split_folder
from predictor.evaluate import evaluate_constant_velocity as evaluate_cv
from predictor.group_rules import ProximityRule
from predictor.metrics import f1
from predictor.report import nan_to_none
from predictor.windows import has_labels, load_windows

PROXIMITY_RADII_M = (0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0)  # the rule family of issue 11: 0.5-2 m


def proximity_groups(obs: np.ndarray, radius_m: float, steps: str = "last") -> np.ndarray:
    """Group ids (N,): connected components of pedestrians closer than ``radius_m`` at the last observed step
    (``steps='last'``) or at every observed step (``steps='all'``) of obs (T, N, 2) (`predictor.group_rules`)."""
    return ProximityRule(radius_m=radius_m, steps="max" if steps == "all" else steps)(obs)


def proximity_scores(windows: list) -> dict[str, dict[str, float]]:
    """PW and G-MITRE of the proximity groupings, keyed e.g. 'last-1.5m', for each radius and step rule."""
    out = {}
    for steps in ("last", "all"):
        for r in PROXIMITY_RADII_M:
            scores = metrics.GroupScores()
            for w in windows:
                scores.add(w.group_id, proximity_groups(w.obs, r, steps))
            out[f"{steps}-{r:.2f}m"] = scores.result()
    return out


def best_rule(scores: dict[str, dict[str, float]]) -> dict:
    """The rule of ``proximity_scores`` with the highest PW F1 (NaN counts as lowest), with both F1s."""
    def pw_f1(item: tuple[str, dict]) -> float:
        v = f1(item[1]["pw_precision"], item[1]["pw_recall"])
        return -1.0 if v != v else v

    name, s = max(scores.items(), key=pw_f1)
    return {"rule": name, **s, "pw_f1": f1(s["pw_precision"], s["pw_recall"]),
            "gmitre_f1": f1(s["gmitre_precision"], s["gmitre_recall"])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, required=True, help="dataset folder (DATA/SPLIT is scored)")
    p.add_argument("--split", choices=("train", "val", "test"), default="test")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--samples", type=int, default=20)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    windows = load_windows(split_folder(args.data, args.split))
    if not windows:
        p.error(f"no windows in {split_folder(args.data, args.split)}")
    result = evaluate_cv(windows, args.seed, args.trials, args.samples)
    result["split"] = args.split
    print(" ".join(f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}" for k, v in result.items()))
    if has_labels(windows):
        result["proximity"] = proximity_scores(windows)
        for r, scores in result["proximity"].items():
            print(f"proximity {r}: " + " ".join(f"{k}={v:.4f}" for k, v in scores.items()))
        result["best_proximity"] = best_rule(result["proximity"])
        print("best proximity rule by PW F1: " + " ".join(
            f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}" for k, v in result["best_proximity"].items()))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)

        clean = nan_to_none(result)
        args.json.write_text(json.dumps(clean, indent=2, allow_nan=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
