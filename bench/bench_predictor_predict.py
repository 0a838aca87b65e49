"""``predict`` latency of the inference API for N = 5, 20, 50 pedestrians and K = 20 samples.

Usage: python bench/bench_predictor_predict.py [--threads 1] [--repeats 50]
Models: GP-Graph-SGCN (the published hotel checkpoint when ../shared is present, else random weights),
GP-Graph-STGCNN (random weights: latency does not depend on the values), the same grouping by the coherent-motion
rule instead of its learned assigner (``GPGraph.group_rule``, the env's default grouping), the same rule on a 48-row
track (``coherent-motion-track``, its ``track`` argument; a quarter of the people seen for 8 rows only) and constant
velocity.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from predictor import ConstantVelocityPredictor, GPGraph, GPGraphConfig, GPGraphPredictor, load_predictor

REF = Path(__file__).resolve().parents[1] / ".." / "shared" / "reference" / "gpgraph_sgcn" / "hotel" / "val_best.pth"


def history(n: int, rng: np.random.Generator, rows: int = 8) -> np.ndarray:
    start = rng.uniform(-6, 6, size=(n, 2))
    vel = rng.normal(scale=0.5, size=(n, 2))
    return start[None] + vel[None] * np.arange(rows)[:, None, None]


def latency_ms(pred, n: int, repeats: int, rng: np.random.Generator) -> tuple[float, float]:
    track = history(n, rng, rows=48)
    track[:40, : max(1, n // 4)] = np.nan  # some people seen for the window only
    h = track[-8:].copy()
    kwargs = {"track": track} if getattr(pred, "reads_track", False) else {}
    for _ in range(3):
        pred.predict(h, n_samples=20, rng=rng, **kwargs)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        pred.predict(h, n_samples=20, rng=rng, **kwargs)
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3), float(np.percentile(times, 95) * 1e3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=50)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    models = {
        "GP-Graph-SGCN": load_predictor(REF) if REF.is_file() else GPGraphPredictor(GPGraph(GPGraphConfig())),
        "GP-Graph-STGCNN": GPGraphPredictor(GPGraph(GPGraphConfig(backbone="stgcnn"))),
        "STGCNN + rule": GPGraphPredictor(GPGraph(GPGraphConfig(backbone="stgcnn"), group_rule="coherent-motion")),
        "STGCNN + track rule": GPGraphPredictor(GPGraph(GPGraphConfig(backbone="stgcnn"),
                                                        group_rule="coherent-motion-track")),
        "constant velocity": ConstantVelocityPredictor(),
    }
    print(f"threads {args.threads}, K = 20, {args.repeats} calls each; median / p95 ms")
    print(f"{'model':<20}" + "".join(f"{'N=' + str(n):>16}" for n in (5, 20, 50)))
    rng = np.random.default_rng(0)
    for name, pred in models.items():
        cells = [latency_ms(pred, n, args.repeats, rng) for n in (5, 20, 50)]
        print(f"{name:<20}" + "".join(f"{m:>9.2f} / {p:<5.1f}" for m, p in cells))


if __name__ == "__main__":
    main()
