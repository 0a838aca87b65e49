"""Why does GP-Graph over-merge? Score other ways of turning its learned pair distances into groups (diagnostic).

    python -m experiments.diagnose_grouping --checkpoint gpgraph-stgcnn-synthetic --data out/synthetic_predictor/data \
        --split val --json out/synthetic_predictor/eval/threshold/diagnose-val.json

Group metrics only (no sampling, so no ADE/FDE): one forward pass of the group assigner gives the learned pair
distance D of every pair of every window, and the learned threshold pi. For each scale s it then scores
- ``pairs``: the raw pair decisions D <= pi * s, before any grouping (PW only: not a partition);
- ``components``: connected components of those pairs (single linkage; what the model does, 'exact');
- ``official``: the reference code's order-dependent relabelling of the same pairs;
- ``average`` / ``complete``: average- / complete-linkage agglomerative clustering of D cut at pi * s
  (scipy), which do not chain people through intermediate neighbours.
and counts the predicted same-group pairs of ``components`` that are not themselves pairs (added by chaining).
Use it on the validation split; it is not an evaluation protocol.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import squareform

from predictor import grouping, metrics
from predictor.batch import collate
from predictor.checkpoint import load_model
from predictor.cli import SPLITS, split_folder
from predictor.metrics import f1
from predictor.report import nan_to_none
from predictor.windows import load_windows

SCALES = (0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5)
METHODS = ("components", "official", "average", "complete")


def pair_distances(model, windows: list, batch: int = 128) -> list[np.ndarray]:
    """The learned pair distance D (n, n), float64, of each window."""
    out = []
    for start in range(0, len(windows), batch):
        b = collate(windows[start : start + batch])
        with torch.no_grad():
            d = model.assigner(b.obs_abs)
        out.extend(d[k, :n, :n].double().numpy() for k, n in enumerate(b.counts))
    return out


def labels_of(method: str, d: np.ndarray, threshold: float) -> np.ndarray:
    """Group labels (n,) of one window from its distances ``d`` and the threshold."""
    n = len(d)
    if n < 2:
        return np.zeros(n, dtype=np.int64)
    if method == "components":
        return connected_components(d <= threshold, directed=False)[1]
    if method == "official":
        return grouping.official_relabel(d <= threshold)
    sym = (d + d.T) / 2
    np.fill_diagonal(sym, 0.0)
    return fcluster(linkage(squareform(sym, checks=False), method), t=threshold, criterion="distance")


def score(windows: list, dists: list[np.ndarray], fn: Callable[[np.ndarray], np.ndarray]) -> dict:
    s = metrics.GroupScores()
    for w, d in zip(windows, dists, strict=True):
        s.add(w.group_id, fn(d))
    r = s.result()
    return {**r, "pw_f1": f1(r["pw_precision"], r["pw_recall"]),
            "gmitre_f1": f1(r["gmitre_precision"], r["gmitre_recall"])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--split", choices=SPLITS, default="val")
    p.add_argument("--scales", type=float, nargs="+", default=list(SCALES))
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    windows = load_windows(split_folder(args.data, args.split))
    if not windows or not all(w.group_id is not None for w in windows):
        p.error(f"need labelled windows in {split_folder(args.data, args.split)}")
    model, _ = load_model(args.checkpoint, group_threshold_scale=1.0)
    pi = model.assigner.threshold.item()
    dists = pair_distances(model, windows)
    iu = [np.triu_indices(len(d), 1) for d in dists]
    pair_d = np.concatenate([d[i] for d, i in zip(dists, iu, strict=True)])
    pair_t = np.concatenate([(w.group_id[:, None] == w.group_id[None])[i] for w, i in zip(windows, iu, strict=True)])
    print(f"{args.checkpoint} on {split_folder(args.data, args.split)}: learned pi {pi:.4f}; {len(pair_d)} pairs, "
          f"{int(pair_t.sum())} same-group")
    rows = []
    for s in args.scales:
        thr = pi * s
        direct = pair_d <= thr
        tp = int((direct & pair_t).sum())
        pp, pr = metrics.ratio(tp, int(direct.sum())), metrics.ratio(tp, int(pair_t.sum()))
        comp = np.concatenate([
            (lab[:, None] == lab[None])[i]
            for lab, i in zip((labels_of("components", d, thr) for d in dists), iu, strict=True)])
        row = {"scale": s, "pairs": {"pw_precision": pp, "pw_recall": pr, "pw_f1": f1(pp, pr)},
               "chained_pairs": int((comp & ~direct).sum()), "chained_true_pairs": int((comp & ~direct & pair_t).sum()),
               "component_pairs": int(comp.sum())}
        print(f"scale {s:.2f}: pairs D <= pi*s  P {pp:.3f} R {pr:.3f} F1 {row['pairs']['pw_f1']:.3f}; components "
              f"add {row['chained_pairs']} chained pairs ({row['chained_true_pairs']} true) to {int(direct.sum())}")
        for method in METHODS:
            row[method] = score(windows, dists, lambda d, m=method, t=thr: labels_of(m, d, t))
            r = row[method]
            print(f"    {method:10s} PW P {r['pw_precision']:.3f} R {r['pw_recall']:.3f} F1 {r['pw_f1']:.3f} | "
                  f"G-MITRE P {r['gmitre_precision']:.3f} R {r['gmitre_recall']:.3f} F1 {r['gmitre_f1']:.3f}",
                  flush=True)
        rows.append(row)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        out = {"checkpoint": str(args.checkpoint), "split": args.split, "learned_pi": pi, "rows": rows}
        args.json.write_text(json.dumps(nan_to_none(out), indent=2, allow_nan=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
