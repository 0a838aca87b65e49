"""Learning curves of `crowdnav train` runs: evaluation success and collision rate against env steps (and wall time).

    python scripts/plot_learning_curves.py out/train/cc5-dagger out/train/cc5-cold --out docs/rl/learning_curves.png

Each run folder's eval.csv (written by `envs.rl.train`) is one line per curve; the label is the folder name and
the warm start read from its config.json. Wall time includes the warm start (demonstrations, cloning, DAgger).
Where a run's checkpoints/state.json records DAgger rounds (`warm_start.dagger`), a third panel shows the learner's
success in its own roll-outs after each round against the expert labels gathered so far (the generalist's curve:
its training is DAgger; PPO did not improve on it). Runs without PPO at all (`--steps 0`) get that panel alone, with
their selection success at the end.

    python scripts/plot_learning_curves.py out/train/v1mix-a out/train/v1mix-b out/train/v1mix-c \
        --out docs/rl/learning_curves_generalist.png --title "ppo-crowdnav-mix: DAgger from mpc-oracle"
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # matplotlib itself is imported in main, after the arguments are checked
    from matplotlib.figure import Figure

Run = tuple[str, dict[str, list[float]]]


def read_run(path: Path) -> Run:
    rows = list(csv.DictReader((path / "eval.csv").open()))
    if not rows:
        raise ValueError(f"{path}/eval.csv has no rows")
    cfg = json.loads((path / "config.json").read_text())
    source = cfg.get("predictor") if cfg.get("prediction_source", "predictor") == "predictor" else "the oracle's future"
    inputs = ("groups" if cfg["groups"] else "no groups") + (f", predictions ({source})" if cfg["predictions"] else "")
    label = (f"{path.name}: warm start {cfg['warm_start']}, lr {cfg['learning_rate']:g}, "
             f"target_kl {cfg.get('target_kl')}, {inputs}")
    data = {k: [float(r[k]) for r in rows] for k in ("steps", "wall_s", "success", "collision")}
    every = int(cfg.get("decision_every_steps", 1))  # eval.csv counts decisions; the plot counts env steps
    data["steps"] = [s * every for s in data["steps"]]
    return label + (f", a decision every {every} env steps" if every > 1 else ""), data


def read_dagger(path: Path) -> list[tuple[int, float]]:
    """(labels so far, learner success) after each DAgger round of the run, from checkpoints/state.json; [] if none."""
    state = path / "checkpoints" / "state.json"
    if not state.exists():
        return []
    rounds = json.loads(state.read_text()).get("warm_start", {}).get("dagger", [])
    return [(int(r["steps"]), float(r["learner_success"])) for r in rounds]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--extra-wall", action="append", default=[], metavar="RUN=SECONDS",
                    help="add SECONDS to RUN's wall time (e.g. a warm start computed in another run)")
    ap.add_argument("--title", default="PPO on circle_crossing, 5 invisible pedestrians")
    args = ap.parse_args(argv)
    try:
        runs = [read_run(r) for r in args.runs]
        dagger = [read_dagger(r) for r in args.runs]
        for item in args.extra_wall:
            name, _, secs = item.partition("=")
            for label, d in runs:
                if label.startswith(name + ":"):
                    d["wall_s"] = [w + float(secs) for w in d["wall_s"]]
    except (OSError, ValueError, KeyError) as exc:
        print(f"plot_learning_curves: error: {exc}", file=sys.stderr)
        return 2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if any(dagger) and all(d["steps"] == [0] for _, d in runs):
        fig = plot_dagger_only(plt, runs, dagger)
    else:
        fig = plot_curves(plt, runs, dagger)
    fig.suptitle(args.title)
    fig.tight_layout(rect=(0, 0.08 + 0.035 * len(runs), 1, 1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


def plot_dagger_only(plt: ModuleType, runs: list[Run], dagger: list[list[tuple[int, float]]]) -> Figure:
    """Runs without PPO (``--steps 0``: the policy is the warm start's): one panel, the learner's success in its
    DAgger roll-outs against the labels so far, and its deterministic selection success (a star at the end)."""
    fig, ax = plt.subplots(1, 1, figsize=(9, 5))
    for (label, d), rounds in zip(runs, dagger, strict=True):
        wall = f", {d['wall_s'][0] / 60:.0f} min"
        line = ax.plot([n / 1e3 for n, _ in rounds], [v for _, v in rounds], marker="o", label=label + wall)[0]
        if rounds:
            ax.plot([rounds[-1][0] / 1e3], d["success"], marker="*", ms=14, color=line.get_color(), ls="none")
    ax.set(xlabel="expert labels so far (thousands)",
           ylabel="success: DAgger roll-outs (o), selection (*)", ylim=(0.5, 1.01))
    ax.grid(alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="lower center", fontsize=8, ncol=1)
    return fig


def plot_curves(plt: ModuleType, runs: list[Run], dagger: list[list[tuple[int, float]]]) -> Figure:
    """Success and collision against env steps and wall time; the DAgger panel where a run has rounds."""
    panels = 3 if any(dagger) else 2
    fig, axes = plt.subplots(1, panels, figsize=(6.5 * panels, 5))
    for (label, d), rounds in zip(runs, dagger, strict=True):
        line = axes[0].plot([s / 1e6 for s in d["steps"]], d["success"], marker=".", label=label)[0]
        axes[0].plot([s / 1e6 for s in d["steps"]], d["collision"], ls="--", color=line.get_color())
        axes[1].plot([w / 60 for w in d["wall_s"]], d["success"], marker=".", color=line.get_color())
        if rounds:
            axes[2].plot([n / 1e3 for n, _ in rounds], [v for _, v in rounds], marker="o", color=line.get_color())
    axes[0].set(xlabel="env steps (millions)", ylabel="rate (solid: success, dashed: collision)", ylim=(0, 1))
    axes[1].set(xlabel="wall time incl. warm start (min)", ylabel="success rate", ylim=(0, 1))
    if panels == 3:
        axes[2].set(xlabel="expert labels so far (thousands)", ylabel="learner success in its DAgger roll-outs",
                    ylim=(0, 1))
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", fontsize=8, ncol=1)
    return fig


if __name__ == "__main__":
    sys.exit(main())
