"""Learning curves of `crowdnav train` runs: evaluation success and collision rate against env steps (and wall time).

    python scripts/plot_learning_curves.py out/train/cc5-dagger out/train/cc5-cold --out docs/rl_learning_curves.png

Each run folder's eval.csv (written by `envs.train`) is one line per curve; the label is the folder name and
the warm start read from its config.json. Wall time includes the warm start (demonstrations, cloning, DAgger).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path


def read_run(path: Path) -> tuple[str, dict[str, list[float]]]:
    rows = list(csv.DictReader((path / "eval.csv").open()))
    if not rows:
        raise ValueError(f"{path}/eval.csv has no rows")
    cfg = json.loads((path / "config.json").read_text())
    label = f"{path.name} (warm start: {cfg['warm_start']})"
    return label, {k: [float(r[k]) for r in rows] for k in ("steps", "wall_s", "success", "collision")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--title", default="PPO on circle_crossing, 5 invisible pedestrians")
    args = ap.parse_args(argv)
    try:
        runs = [read_run(r) for r in args.runs]
    except (OSError, ValueError, KeyError) as exc:
        print(f"plot_learning_curves: error: {exc}", file=sys.stderr)
        return 2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for label, d in runs:
        line = axes[0].plot([s / 1e6 for s in d["steps"]], d["success"], label=label)[0]
        axes[0].plot([s / 1e6 for s in d["steps"]], d["collision"], ls="--", color=line.get_color())
        axes[1].plot([w / 60 for w in d["wall_s"]], d["success"], color=line.get_color())
    axes[0].set(xlabel="env steps (millions)", ylabel="rate (solid: success, dashed: collision)", ylim=(0, 1))
    axes[1].set(xlabel="wall time incl. warm start (min)", ylabel="success rate", ylim=(0, 1))
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(args.title)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
