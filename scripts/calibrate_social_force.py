"""Calibrate the pedestrian repulsion of `SocialForceParams` against two realism targets, on seeds the tests do not use.

Fitted: A (`ped_strength_mps2`), B (`ped_range_m`) and the anisotropy lam (`anisotropy`), on a grid; everything
else (tau = 0.5 s, desired speeds N(1.34, 0.26) m/s, walls, group terms, the default radii 0.22-0.28 m) stays
at its default.

(a) Weidmann (1993) fundamental diagram, v = 1.34 [1 - exp(-1.913 (1/rho - 1/5.4))] = 1.30, 1.06, 0.61 m/s at
    rho = 0.5, 1, 2 persons/m^2, in the periodic one-way corridor (20 x 4 m, people on their own): the mean
    walking speed (x velocity) in the middle 12 m from 14 s to 40 s, averaged over the seeds, exactly as
    tests/crowdsim/test_fundamental_diagram.py measures it. Error: the largest |v - v_Weidmann| of the three.
(b) Free walking in a sparse plaza (20 x 20 m, 16 pedestrians, default groups): the median |velocity| of the
    active pedestrians at every recorded step (0.4 s) over 400 s, pooled over the seeds, leaving out each
    pedestrian's first 2 s (its acceleration from rest when it walks in). Target 1.2-1.4 m/s.

Selection: (a) is the requirement and must keep a margin inside the tests' 0.10 m/s tolerance (the seed-averaged
error at most MAX_CORRIDOR_ERROR_MPS); among the points that meet it, the one that slows (b) least. The chosen
point is then also measured with nobody in groups (8 people alone in the plaza: free walking proper).

Seeds: corridor and plaza 1000-1005 (`--seeds`); the tests use seeds 0-9, so the fit never sees them. One
simulation runs at a time (about 5 minutes in all; `--quick` takes 2 seeds and a coarser grid).

    .venv/bin/python scripts/calibrate_social_force.py
"""

from __future__ import annotations

import argparse
import itertools
import time
from dataclasses import dataclass, replace

import numpy as np

from crowdsim.config import GroupConfig, SimConfig, SocialForceParams
from crowdsim.sim import CrowdSimulator
from crowdsim.walking import walking_speeds

DENSITIES = (0.5, 1.0, 2.0)  # persons/m^2
LENGTH_M, WIDTH_M = 20.0, 4.0  # the periodic corridor of the tests
CORRIDOR_STEPS, CORRIDOR_WARMUP = 100, 35  # recorded steps of 0.4 s: 40 s, the first 14 s left out
PLAZA_PEOPLE, PLAZA_STEPS, PLAZA_SKIP = 16, 1000, 5  # 400 s; each pedestrian's first 5 steps (2 s) left out
PLAZA_TARGET = (1.2, 1.4)  # m/s
MAX_CORRIDOR_ERROR_MPS = 0.07  # (a) must stay this far inside the tests' 0.10 m/s tolerance
SINGLES = GroupConfig(size_poisson_rate=0.0, max_size=1)

GRID = {  # the previous defaults (2.2, 0.32, 0.3) are a grid point
    "ped_strength_mps2": (2.2, 2.6, 3.0, 3.4, 3.8, 4.2, 4.6, 5.0),
    "ped_range_m": (0.2, 0.24, 0.28, 0.32),
    "anisotropy": (0.3, 0.4, 0.5, 0.6),
}
QUICK_GRID = {"ped_strength_mps2": (2.2, 3.0, 3.8), "ped_range_m": (0.24, 0.32), "anisotropy": (0.3, 0.5)}


def weidmann(rho: float) -> float:
    """Weidmann's (1993) walking speed (m/s) at density rho (persons/m^2)."""
    return 1.34 * (1.0 - np.exp(-1.913 * (1.0 / rho - 1.0 / 5.4)))


def corridor_speed(rho: float, social: SocialForceParams, seed: int) -> float:
    """Mean x speed (m/s) in the middle of the periodic corridor at density rho, default radii, no groups."""
    n = int(round(rho * LENGTH_M * WIDTH_M))
    options = (("periodic", 1.0), ("length_m", LENGTH_M), ("width_m", WIDTH_M), ("density", 1.45 * rho))
    sim = CrowdSimulator(SimConfig(scenario="corridor", n_pedestrians=n, groups=SINGLES, social=social,
                                   scenario_options=options))
    sim.reset(seed)
    speeds = []
    for k in range(CORRIDOR_STEPS):
        s = sim.step()
        if k >= CORRIDOR_WARMUP:
            zone = s.active & (s.pos[:, 0] > 4.0) & (s.pos[:, 0] < LENGTH_M - 4.0)
            speeds.append(s.vel[zone, 0].mean())
    return float(np.mean(speeds))


def plaza_speeds(social: SocialForceParams, seed: int, n: int = PLAZA_PEOPLE,
                 groups: GroupConfig | None = None) -> np.ndarray:
    """|velocity| (m/s) of every active pedestrian at every recorded step, each one's first PLAZA_SKIP left out."""
    config = SimConfig(scenario="plaza", n_pedestrians=n, social=social, groups=groups or GroupConfig())
    return walking_speeds(config, [seed], PLAZA_STEPS, PLAZA_SKIP).samples


@dataclass
class Point:
    params: dict[str, float]
    corridor: np.ndarray  # (3,) seed-averaged speeds at DENSITIES, m/s
    corridor_sd: np.ndarray  # (3,) their standard deviation over seeds
    plaza: float = float("nan")  # (b) median, m/s

    @property
    def deviation(self) -> np.ndarray:
        return self.corridor - np.array([weidmann(r) for r in DENSITIES])

    @property
    def error(self) -> float:
        return float(np.abs(self.deviation).max())

    def row(self) -> str:
        a, b, lam = self.params.values()
        dev = " ".join(f"{d:+.3f}" for d in self.deviation)
        plaza = "   -  " if np.isnan(self.plaza) else f"{self.plaza:.3f}"
        return f"{a:5.2f} {b:5.2f} {lam:5.2f} | {dev} | {self.error:.3f} | {plaza}"


def social_of(params: dict[str, float]) -> SocialForceParams:
    return replace(SocialForceParams(), **params)


def evaluate_corridor(params: dict[str, float], seeds: list[int]) -> Point:
    v = np.array([[corridor_speed(rho, social_of(params), s) for s in seeds] for rho in DENSITIES])
    return Point(params, v.mean(axis=1), v.std(axis=1))


def plaza_median(params: dict[str, float], seeds: list[int], **kw) -> float:
    return float(np.median(np.concatenate([plaza_speeds(social_of(params), s, **kw) for s in seeds])))


HEADER = "    A     B   lam | dev at " + " ".join(f"{r:g}/m2".rjust(6) for r in DENSITIES) + " | error | plaza"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(1000, 1006)))
    parser.add_argument("--quick", action="store_true", help="2 seeds, a coarser grid (a smoke run)")
    args = parser.parse_args()
    seeds = args.seeds[:2] if args.quick else args.seeds
    if min(seeds) < 1000:
        parser.error("calibrate on seeds >= 1000: the tests use the small ones")
    grid = QUICK_GRID if args.quick else GRID
    start = time.time()
    print("Weidmann: " + ", ".join(f"{weidmann(r):.2f} m/s at {r:g}/m2" for r in DENSITIES))
    print(f"(a) corridor, seeds {seeds}: speed minus Weidmann (m/s), error = the largest |deviation|")
    print(HEADER)
    points = []
    for values in itertools.product(*grid.values()):
        point = evaluate_corridor(dict(zip(grid.keys(), values, strict=True)), seeds)
        points.append(point)
        print(point.row(), flush=True)
    feasible = sorted((p for p in points if p.error <= MAX_CORRIDOR_ERROR_MPS), key=lambda p: p.error)
    if not feasible:
        raise SystemExit(f"no grid point meets (a) within {MAX_CORRIDOR_ERROR_MPS} m/s; widen the grid")
    baseline = next((p for p in points if list(p.params.values()) == [2.2, 0.32, 0.3]), None)
    print(f"\n(b) sparse plaza ({PLAZA_PEOPLE} people, default groups), median |v| (m/s) pooled over seeds {seeds},"
          f" for the {len(feasible)} points with (a) error <= {MAX_CORRIDOR_ERROR_MPS}")
    print(HEADER)
    for p in feasible + ([baseline] if baseline is not None and baseline not in feasible else []):
        p.plaza = plaza_median(p.params, seeds)
        print(p.row(), flush=True)
    best = max(feasible, key=lambda p: (round(p.plaza, 2), -p.error))  # ties (within 0.005 m/s): smaller (a) error
    alone = plaza_median(best.params, seeds, n=8, groups=SINGLES)
    lo, hi = PLAZA_TARGET
    print(f"\nchosen (ran {time.time() - start:.0f} s):")
    for key, value in best.params.items():
        print(f"    {key}: float = {value}")
    rows = zip(best.corridor, best.corridor_sd, DENSITIES, strict=True)
    print("(a) corridor speeds: " + ", ".join(f"{v:.2f}±{sd:.2f} vs {weidmann(r):.2f} at {r:g}/m2" for v, sd, r in rows)
          + f" (± is the sd over seeds); error {best.error:.3f} m/s")
    print(f"(b) sparse plaza median |v|: {best.plaza:.3f} m/s with default groups "
          f"({'inside' if lo <= best.plaza <= hi else 'OUTSIDE'} {lo}-{hi}); "
          f"{alone:.3f} m/s with 8 people on their own ({'inside' if lo <= alone <= hi else 'OUTSIDE'})")


if __name__ == "__main__":
    main()
