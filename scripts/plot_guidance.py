"""Draw one plan of the guidance layer: its passing options, the chosen one, and the people's predicted samples.

Runs one benchmark episode of an MPC policy with the guidance layer on (the suite's planner settings plus
`--mpc guidance=default` and any `--mpc` given), keeps the frames, and draws one with the env's renderer
(`envs.drawing.render`): the chosen plan black, the other solved options grey, the predictions faded in their group
colours. The frame: the one at `--at` seconds, else, among those with at least `--min-options` options and a person
within 2 m of the robot, the one whose options end farthest apart. The view: the `--view-m` square centred between
the robot and its plan's end. Writes a PNG (matplotlib).

    .venv/bin/python scripts/plot_guidance.py crowdnav-tune tune-corridor-high-visible 1003 \
        --policy mpc-gpgraph --out docs/img/guidance-options.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from envs.cli import build_parser
from envs.cli_options import policy_configs
from envs.drawing.render import render_rgb
from envs.evaluation.episode import run_episode
from envs.evaluation.suite import load_suite


class _Keep:
    """Observer that keeps every frame."""

    def __init__(self) -> None:
        self.frames: list = []

    def log(self, frame) -> None:
        self.frames.append(frame)


def pick_frame(frames: list, at_s: float | None, min_options: int):
    """The frame at `at_s` s, else, among the frames with >= min_options options (chosen plan included) and someone
    within 2 m of the robot, the one whose options end farthest apart; None when there is none."""
    if at_s is not None:
        return min(frames, key=lambda f: abs(f.time_s - at_s))
    best, spread = None, -1.0
    for f in frames:
        if f.options is None or f.plan is None or len(f.options) + 1 < min_options or not len(f.ped_pos):
            continue
        if np.min(np.linalg.norm(f.ped_pos - f.robot_pos, axis=1)) >= 2.0:
            continue
        ends = np.vstack([f.plan[-1:], np.asarray(f.options)[:, -1]])
        gap = float(np.max(np.linalg.norm(ends[:, None] - ends[None], axis=-1)))
        if gap > spread:
            best, spread = f, gap
    return best


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("suite")
    p.add_argument("cell")
    p.add_argument("seed", type=int)
    p.add_argument("--policy", default="mpc-gpgraph")
    p.add_argument("--mpc", action="append", default=[], metavar="FIELD=VALUE")
    p.add_argument("--at", type=float, default=None, help="time of the frame to draw, s")
    p.add_argument("--min-options", type=int, default=3)
    p.add_argument("--view-m", type=float, default=8.0)
    p.add_argument("--size", type=int, default=720)
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    loaded = load_suite(args.suite)
    cell = loaded.cell(args.cell)
    mpc = ["guidance=default", *args.mpc]
    parsed = build_parser().parse_args(["evaluate", "--policy", args.policy, *(a for m in mpc for a in ("--mpc", m))])
    (pcfg,) = policy_configs(parsed, loaded)
    keep = _Keep()
    result = run_episode(cell.env_config(args.seed), pcfg.for_cell(cell.scene, cell.predictor), args.seed,
                         observer=keep)
    frame = pick_frame(keep.frames, args.at, args.min_options)
    if frame is None:
        print(f"no frame with {args.min_options} options and someone near; try --at", file=sys.stderr)
        return 2
    half = args.view_m / 2
    x, y = 0.5 * (frame.robot_pos + np.asarray(frame.plan)[-1])  # centred between the robot and its plan's end
    view = (x - half, y - half, x + half, y + half)
    import matplotlib.pyplot as plt  # the project's plotting dependency (leaderboard figures)

    plt.imsave(args.out, render_rgb(frame, args.size, view))
    n = 0 if frame.options is None else len(frame.options)
    end = result.metrics
    print(f"{args.out}: t = {frame.time_s:.1f} s, {n + 1} options; episode {end['outcome']} at {end['time_s']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
