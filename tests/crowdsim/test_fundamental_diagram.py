"""Walking speeds with the default configuration: Weidmann's fundamental diagram in a one-way corridor and
free walking in a sparse plaza (the low-density end of the same diagram).

Corridor tolerance: 0.10 m/s, on the mean over seeds 0-9. Empirical fundamental diagrams disagree with each
other by more than that (at 1-2 persons/m^2, Weidmann, SFPE and Predtechenskii–Milinskii differ by 0.2-0.4 m/s,
and Seyfried et al. 2005 single-file data scatter by about ±0.15 m/s), so matching Weidmann's curve more tightly
would be fitting one data set's noise. One seed alone is not enough at 0.5 persons/m^2: the corridor walks at its
40 people's mean desired speed less about 0.1 m/s, and that mean varies by ±0.05 m/s from seed to seed.
The density is measured in the middle of a periodic corridor (interactions reach across the seam), away from the
walls' ends. SocialForceParams was calibrated on other seeds (scripts/calibrate_social_force.py, 1000-1005).
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.config import SimConfig
from crowdsim.sim import CrowdSimulator
from tests.crowdsim.conftest import singles

LENGTH_M, WIDTH_M = 20.0, 4.0
SEEDS = range(10)


def weidmann(rho: float) -> float:
    return 1.34 * (1.0 - np.exp(-1.913 * (1.0 / rho - 1.0 / 5.4)))


def corridor_speed(rho: float, seed: int = 0, steps: int = 100, warmup: int = 35) -> tuple[float, float]:
    """(density in the middle 12 m, mean x speed there), averaged over recorded steps after the warm-up."""
    n = int(round(rho * LENGTH_M * WIDTH_M))
    options = (("periodic", 1.0), ("length_m", LENGTH_M), ("width_m", WIDTH_M), ("density", 1.45 * rho))
    sim = CrowdSimulator(singles(n, scenario="corridor", scenario_options=options))  # default radii
    sim.reset(seed)
    speeds, densities = [], []
    for k in range(steps):
        s = sim.step()
        if k >= warmup:
            zone = s.active & (s.pos[:, 0] > 4.0) & (s.pos[:, 0] < 16.0)
            speeds.append(s.vel[zone, 0].mean())
            densities.append(zone.sum() / (12.0 * WIDTH_M))
    return float(np.mean(densities)), float(np.mean(speeds))


@pytest.mark.parametrize("rho", [0.5, 1.0, 2.0])
def test_corridor_follows_weidmann(rho):
    density, speed = np.mean([corridor_speed(rho, seed) for seed in SEEDS], axis=0)
    assert density == pytest.approx(rho, rel=0.05)  # the ring holds the density we asked for
    assert abs(speed - weidmann(rho)) < 0.10, f"v({rho}) = {speed:.2f} m/s, Weidmann {weidmann(rho):.2f}"


def test_weidmann_reference_values():
    assert [round(weidmann(r), 2) for r in (0.5, 1.0, 2.0)] == [1.3, 1.06, 0.61]


def plaza_median_speed(config: SimConfig, seeds=(0, 1), steps: int = 1000, skip: int = 5) -> float:
    """Median |velocity| (m/s) of the active pedestrians over every recorded step of `steps` (400 s), pooled over
    seeds, leaving out each pedestrian's first `skip` steps (2 s: its acceleration from rest as it walks in)."""
    speeds = []
    for seed in seeds:
        sim = CrowdSimulator(config)
        sim.reset(seed)
        first_seen: dict[int, int] = {}
        for k in range(steps):
            s = sim.step()
            act = np.flatnonzero(s.active)
            age = np.array([k - first_seen.setdefault(int(pid), k) for pid in s.ped_id[act]])
            speeds.extend(np.linalg.norm(s.vel[act[age >= skip]], axis=1))
    return float(np.median(speeds))


def test_free_walking_speed_in_a_sparse_plaza():
    # 8 people on their own in the 20 x 20 m plaza (0.02/m^2). Desired speeds are N(1.34, 0.26) m/s, but slow
    # walkers stay longer, so the median over recorded steps of a lone walker's desired speed is about 1.30 m/s;
    # passing others at the gates and in the middle costs a few cm/s more.
    median = plaza_median_speed(singles(8, scenario="plaza"))
    assert 1.2 <= median <= 1.4, f"median free-walking speed {median:.3f} m/s"


@pytest.mark.xfail(strict=True, reason=(
    "~1.1 m/s: group members walk below their desired speed (the gaze term, GroupForceParams.gaze_strength, brakes "
    "whoever is ahead of the others: pairs at ~0.92, triples ~0.85, groups of 4-5, which look only at their own row, "
    "~0.9 of it), groups are "
    "slower to begin with and slow groups stay longer, so even without the gaze term the median is ~1.18 m/s; "
    "no SocialForceParams value moves it by more than a few cm/s"))
def test_free_walking_speed_in_a_sparse_plaza_with_default_groups():
    median = plaza_median_speed(SimConfig(scenario="plaza", n_pedestrians=16))
    assert 1.2 <= median <= 1.4, f"median walking speed {median:.3f} m/s"
