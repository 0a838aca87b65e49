"""Training throughput: batched GP-Graph vs a batch-size-1 loop of the same model, in one run.

Usage: python bench/bench_predictor_train.py [--backbone stgcnn] [--threads 1] [--windows 512]
Reads ../shared/datasets/eth_ucy/<scene>/train when present, else synthetic windows.
Both modes do forward + backward + Adam steps over 128-window optimiser batches; the loop mode
accumulates gradients window by window, as the reference code does.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from predictor.backbones import BACKBONES
from predictor.batch import collate
from predictor.ethucy import DEFAULT_DATA_DIR
from predictor.gaussian import masked_nll
from predictor.model import GPGraph, GPGraphConfig
from predictor.train import make_batches, train_epoch
from predictor.windows import Window, load_windows

DATA = DEFAULT_DATA_DIR  # run from the repository root, as every bench/ script


def synthetic(n: int, rng: np.random.Generator) -> list[Window]:
    out = []
    for _ in range(n):
        k = int(rng.integers(2, 12))
        traj = np.cumsum(rng.normal(scale=0.3, size=(20, k, 2)), axis=0)
        out.append(Window(traj[:8], traj[8:], np.arange(k), None))
    return out


def run_batched(model: GPGraph, windows: list[Window], batch: int, bucket: int, max_pairs: int) -> float:
    """Windows/s of ``train_epoch`` over padded (micro-)batches."""
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    steps = make_batches(windows, batch, bucket, np.random.default_rng(0), max_pairs)
    t = time.perf_counter()
    train_epoch(model, steps, opt, clip=10.0)
    return len(windows) / (time.perf_counter() - t)


def run_loop(model: GPGraph, windows: list[Window], batch: int) -> float:
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    singles = [collate([w]) for w in windows]
    t = time.perf_counter()
    opt.zero_grad()
    for i, b in enumerate(singles, start=1):
        out = model(b.obs_abs, b.obs_rel, b.node_mask)
        (masked_nll(out.raw, b.pred_rel, b.node_mask) / batch).backward()
        if i % batch == 0 or i == len(singles):
            opt.step()
            opt.zero_grad()
    return len(windows) / (time.perf_counter() - t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--backbone", default="stgcnn")
    ap.add_argument("--scene", default="hotel")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--windows", type=int, default=512, help="windows for the batched run")
    ap.add_argument("--loop-windows", type=int, default=128, help="windows for the batch-size-1 loop")
    ap.add_argument("--batch", type=int, default=128)
    ap.add_argument("--max-pairs", type=int, default=None,
                    help="micro-batch budget B * N_max^2 (default: the backbone's pair_budget)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    if args.max_pairs is None:
        args.max_pairs = BACKBONES[args.backbone].pair_budget
    rng = np.random.default_rng(0)
    folder = DATA / args.scene / "train"
    source = str(folder) if folder.is_dir() else "synthetic"
    windows = load_windows(folder) if folder.is_dir() else synthetic(2000, rng)
    pick = rng.permutation(len(windows))
    print(f"data: {source}; backbone {args.backbone}; threads {args.threads}")
    modes = [("batch 128, random", 1, 0), ("batch 128, size-sorted", 8, 0),
             (f"random, micro {args.max_pairs}", 1, args.max_pairs),
             (f"size-sorted, micro {args.max_pairs}", 8, args.max_pairs)]
    print(f"{'model':<18}{'mode':<28}{'batched win/s':>14}{'bs-1 loop win/s':>17}{'speed-up':>10}")
    for name, cfg in [("GP-Graph-" + args.backbone, GPGraphConfig(backbone=args.backbone)),
                      (args.backbone + " alone", GPGraphConfig.backbone_only(args.backbone))]:
        torch.manual_seed(0)
        model = GPGraph(cfg).train()
        loop = run_loop(model, [windows[i] for i in pick[: args.loop_windows]], args.batch)
        for mode, bucket, max_pairs in modes:
            sel = [windows[i] for i in pick[: args.windows]]
            batched = run_batched(model, sel, args.batch, bucket, max_pairs)
            print(f"{name:<18}{mode:<28}{batched:>14.1f}{loop:>17.1f}{batched / loop:>9.1f}x")


if __name__ == "__main__":
    main()
