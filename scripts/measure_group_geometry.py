"""How far apart and how coherently crowdsim's group members walk, against real groups (issue 30, sim-to-real).

Same-group pairs in every 8-step observed window (0.4 s frames, the 20-frame windows of `predictor.windows`), the
pair's mean distance and mean relative speed |v_i - v_j| (`crowdsim.walking.group_pair_geometry`), percentiles
10/50/90 pooled over the realistic-v1 preset's four scenarios (48 s recorded after 10 s of warm-up per seed).
Real UCY groups (students003, zara01, zara02 pooled; validation data only): distance 0.49/0.74/1.41 m, relative
speed 0.01/0.14/0.37 m/s. Also the median per-window speed of people alone (m/s).

Seeds 1000-1003 to choose settings (`--seeds`); the tests use seeds 0-2 (tests/crowdsim/test_group_geometry.py).
About 30 s per setting. Settings as overrides of GroupForceParams, e.g.

    .venv/bin/python scripts/measure_group_geometry.py --set member_ped_repulsion_scale=1 --set catch_up_strength=4
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from crowdsim.generate import RunSpec, simulate
from crowdsim.presets import get_preset, sample_config
from crowdsim.walking import group_pair_geometry
from predictor.data import Recording
from predictor.windows import recording_windows

SCENARIOS = ("corridor", "crossing", "plaza", "circle_crossing")
UCY = {"distance": (0.49, 0.74, 1.41), "relative_speed": (0.01, 0.14, 0.37)}


def geometry(seeds, overrides: dict[str, float] | None = None, scenarios=SCENARIOS, duration_s: float = 48.0,
             warmup_s: float = 10.0) -> dict[str, np.ndarray]:
    """Same-group pair distances and relative speeds (m, m/s) and speeds of people alone, pooled over
    realistic-v1 recordings of `scenarios` x `seeds` with GroupForceParams `overrides`."""
    preset = get_preset("realistic-v1")
    dist, rel, alone = [], [], []
    for scenario in scenarios:
        for seed in seeds:
            config = sample_config(preset, scenario, seed)
            if overrides:
                config = replace(config, group_forces=replace(config.group_forces, **overrides))
            log, _ = simulate(config, RunSpec(duration_s=duration_s, warmup_s=warmup_s, seed=seed))
            t = log.table()
            rec = Recording(path=Path(f"{scenario}_{seed}.txt"), rows=t[:, :4].copy(),
                            frame_labels=t[:, [0, 1, 4]].copy())
            for w in recording_windows(rec):
                d, r = group_pair_geometry(w.obs, w.group_id)
                dist.append(d)
                rel.append(r)
                single = np.bincount(w.group_id)[w.group_id] == 1
                alone.append(np.linalg.norm(np.diff(w.obs, axis=0) / 0.4, axis=-1).mean(axis=0)[single])
    return {"distance": np.concatenate(dist), "relative_speed": np.concatenate(rel), "alone": np.concatenate(alone)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1000-1003", help="first-last")
    ap.add_argument("--set", action="append", default=[], help="GroupForceParams field=value")
    args = ap.parse_args()
    lo, hi = (int(x) for x in args.seeds.split("-"))
    overrides = {k: float(v) for k, v in (s.split("=") for s in args.set)}
    g = geometry(range(lo, hi + 1), overrides)
    print(f"seeds {args.seeds} {overrides or 'defaults'}: {len(g['distance'])} pair-windows")
    for key in ("distance", "relative_speed"):
        print(f"  {key:15s} p10/50/90 {np.percentile(g[key], [10, 50, 90]).round(2).tolist()}   UCY {list(UCY[key])}")
    print(f"  alone speed median {np.median(g['alone']):.2f} m/s")


if __name__ == "__main__":
    main()
