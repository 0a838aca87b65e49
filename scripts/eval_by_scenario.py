"""Per-recording breakdown of a test split: ``gpgraph evaluate``'s metrics for each test file separately.

    python scripts/eval_by_scenario.py --checkpoint out/.../best.pt --data DATA --protocol iid --seed 0 \
        --trials 10 --json out.json
    python scripts/eval_by_scenario.py --checkpoint constant-velocity --data DATA --seed 0 --trials 10

Each file is scored on its own with a fresh Generator seeded with ``--seed`` (so the rows are not the
whole-split run cut into pieces, and do not average exactly to it). ``constant-velocity`` uses
``scripts/eval_baselines.py``'s scoring (its own sampling; ``--protocol`` is ignored).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from predictor.checkpoint import load_model
from predictor.cli import split_folder
from predictor.evaluate import EvalConfig, evaluate
from predictor.evaluate import evaluate_constant_velocity as evaluate_cv
from predictor.sampling import PROTOCOLS
from predictor.windows import load_windows

KEYS = ("ade", "fde", "col", "tcc", "pw_precision", "pw_recall", "gmitre_precision", "gmitre_recall")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", required=True, help="checkpoint path, packaged name or 'constant-velocity'")
    p.add_argument("--data", type=Path, required=True, help="dataset folder (DATA/test is scored)")
    p.add_argument("--protocol", choices=PROTOCOLS, default="iid")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    windows = load_windows(split_folder(args.data, "test"))
    cv = args.checkpoint == "constant-velocity"
    model = None if cv else load_model(args.checkpoint)[0]
    rows = {}
    for source in sorted({w.source for w in windows}):
        part = [w for w in windows if w.source == source]
        if cv:
            r = evaluate_cv(part, args.seed, args.trials, 20)
        else:
            r = evaluate(model, part, EvalConfig(protocol=args.protocol, seed=args.seed, trials=args.trials))
        rows[source] = {k: r[k] for k in (*KEYS, "windows", "pedestrians") if k in r}
        print(source, " ".join(f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}" for k, v in rows[source].items()))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        clean = {s: {k: (None if isinstance(v, float) and v != v else v) for k, v in r.items()}
                 for s, r in rows.items()}
        meta = {"checkpoint": args.checkpoint, "protocol": "constant-velocity" if cv else args.protocol,
                "seed": args.seed, "trials": args.trials}
        args.json.write_text(json.dumps({**meta, "by_file": clean}, indent=2, allow_nan=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
