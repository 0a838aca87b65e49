"""Calibrate GP-Graph's group assignment at inference: sweep ``group_threshold_scale`` on a validation split.

    python scripts/sweep_group_threshold.py --checkpoint gpgraph-stgcnn-synthetic \
        --data out/synthetic_predictor/data --split val --protocol iid --seed 0 --trials 3 \
        --json out/synthetic_predictor/eval/threshold-sweep-val.json
    python scripts/sweep_group_threshold.py ... --group-mode average --scales 0.9 1.0 1.1 1.2 1.3 1.4 1.5

Pedestrians are linked when their learned pair distance D <= pi * scale (``GPGraph.group_threshold_scale``),
so scales below 1 split the learned groups. For every scale this runs ``gpgraph evaluate``'s evaluation
(``predictor.evaluate.evaluate``: the same model, windows, protocol, seed and trials for each scale) and adds
PW F1 and G-MITRE F1. The chosen scale maximises PW F1 among the scales whose ADE and FDE are each at most
``--max-worse`` (default 1%) above those of scale 1.0 (which is always swept). The model is loaded with scale
1.0 as the reference, whatever calibration the checkpoint's meta holds. With ``--group-mode NAME`` the swept
rows use that hard grouping (``GPGraph.group_mode``, e.g. 'average' linkage) while the reference stays the
model as trained (its config's grouping at scale 1.0, always scored, first row); the choice is then among the
swept rows and the reference. Choose on val, then score the chosen setting once on test with
``gpgraph evaluate --group-mode NAME --group-threshold-scale X``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from predictor.checkpoint import load_model
from predictor.cli import SPLITS, group_threshold_scale_arg, split_folder
from predictor.evaluate import EvalConfig, evaluate
from predictor.grouping import THRESHOLD_MODES
from predictor.metrics import f1
from predictor.report import nan_to_none
from predictor.sampling import PROTOCOLS
from predictor.windows import load_windows

DEFAULT_SCALES = (0.3, 0.4, 0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95, 1.0, 1.1, 1.25)


def choose(rows: list[dict], max_worse: float) -> dict:
    """The row with the highest PW F1 whose ADE and FDE are within ``max_worse`` (a fraction) of the reference's
    (the row marked ``reference``, else the one at scale 1.0); ties go to the reference."""
    ref = next((r for r in rows if r.get("reference")), None) or next(
        r for r in rows if r["group_threshold_scale"] == 1.0)
    ok = [r for r in rows if r["ade"] <= ref["ade"] * (1 + max_worse) and r["fde"] <= ref["fde"] * (1 + max_worse)
          and r["pw_f1"] == r["pw_f1"]]
    return max(ok, key=lambda r: (r["pw_f1"], r is ref))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", required=True, help="checkpoint path or packaged name")
    p.add_argument("--data", type=Path, required=True, help="dataset folder (DATA/SPLIT is scored)")
    p.add_argument("--split", choices=SPLITS, default="val")
    p.add_argument("--scales", type=group_threshold_scale_arg, nargs="+", default=list(DEFAULT_SCALES),
                   help="scales to try (1.0 is added when missing)")
    p.add_argument("--group-mode", choices=THRESHOLD_MODES, default=None, metavar="NAME",
                   help=f"hard grouping of the swept rows, one of {', '.join(THRESHOLD_MODES)} (default: the "
                        "checkpoint's config grouping, as trained)")
    p.add_argument("--protocol", choices=PROTOCOLS, default="iid")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--trials", type=int, default=3)
    p.add_argument("--max-worse", type=float, default=0.01,
                   help="largest allowed relative increase of ADE and of FDE over scale 1.0")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    if args.threads < 1 or args.trials < 1 or args.max_worse < 0:
        p.error("--threads and --trials must be >= 1 and --max-worse >= 0")
    torch.set_num_threads(args.threads)
    windows = load_windows(split_folder(args.data, args.split))
    if not windows:
        p.error(f"no windows in {split_folder(args.data, args.split)}")
    model, _ = load_model(args.checkpoint, group_threshold_scale=1.0)
    trained = model.config.grouping
    mode = args.group_mode or trained
    cfg = EvalConfig(protocol=args.protocol, seed=args.seed, trials=args.trials)
    rows = []
    print(f"{args.checkpoint} on {split_folder(args.data, args.split)}: learned pi "
          f"{model.assigner.threshold.item():.4f}; grouping {mode} (trained: {trained}); protocol={args.protocol} "
          f"seed={args.seed} trials={args.trials}")
    heads = ("PW P", "PW R", "PW F1", "GM P", "GM R", "GM F1", "ADE", "FDE")
    print(f"{'mode':>8} {'scale':>6} " + " ".join(f"{h:>7}" for h in heads))
    settings = [(None, 1.0)] + [(mode, s) for s in sorted(set(args.scales) | {1.0}) if (mode, s) != (trained, 1.0)]
    for group_mode, scale in settings:
        model.group_mode, model.group_threshold_scale = group_mode, scale
        r = evaluate(model, windows, cfg)
        row = {"group_mode": model.effective_group_mode, "group_threshold_scale": scale,
               "reference": group_mode is None,
               **{k: r[k] for k in ("ade", "fde", "col", "tcc")},
               **{k: r.get(k) for k in ("pw_precision", "pw_recall", "gmitre_precision", "gmitre_recall")}}
        row["pw_f1"] = f1(row["pw_precision"], row["pw_recall"])
        row["gmitre_f1"] = f1(row["gmitre_precision"], row["gmitre_recall"])
        rows.append(row)
        print(f"{row['group_mode']:>8} {scale:>6.3f} " + " ".join(f"{row[k]:>7.4f}" for k in (
            "pw_precision", "pw_recall", "pw_f1", "gmitre_precision", "gmitre_recall", "gmitre_f1", "ade", "fde")),
            flush=True)
    best = choose(rows, args.max_worse)
    print(f"chosen: group mode {best['group_mode']}, scale {best['group_threshold_scale']} (highest PW F1 "
          f"{best['pw_f1']:.4f} with ADE/FDE within {100 * args.max_worse:g}% of {trained} at scale 1.0)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        clean = [nan_to_none(r) for r in rows]
        out = {"checkpoint": str(args.checkpoint), "split": args.split, "protocol": args.protocol,
               "seed": args.seed, "trials": args.trials, "n_samples": cfg.n_samples, "windows": len(windows),
               "learned_pi": model.assigner.threshold.item(), "max_worse": args.max_worse,
               "group_mode": mode, "trained_grouping": trained, "chosen": best["group_threshold_scale"],
               "chosen_group_mode": best["group_mode"], "rows": clean}
        args.json.write_text(json.dumps(out, indent=2, allow_nan=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
