"""Speed–density relation in a one-way corridor against Weidmann's fundamental diagram.

Tolerance: 0.15 m/s. Empirical fundamental diagrams disagree with each other by more than that
(at 1-2 persons/m^2, Weidmann, SFPE and Predtechenskii–Milinskii differ by 0.2-0.4 m/s, and
Seyfried et al. 2005 single-file data scatter by about ±0.15 m/s), so matching Weidmann's curve
more tightly would be fitting one data set's noise. The density is measured in the middle of a
periodic corridor (interactions reach across the seam), away from the walls' ends.
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.sim import CrowdSimulator
from tests.crowdsim.conftest import singles

LENGTH_M, WIDTH_M = 20.0, 4.0


def weidmann(rho: float) -> float:
    return 1.34 * (1.0 - np.exp(-1.913 * (1.0 / rho - 1.0 / 5.4)))


def corridor_speed(rho: float, seed: int = 0, steps: int = 100, warmup: int = 35) -> tuple[float, float]:
    n = int(round(rho * LENGTH_M * WIDTH_M))
    options = (("periodic", 1.0), ("length_m", LENGTH_M), ("width_m", WIDTH_M), ("density", 1.45 * rho))
    sim = CrowdSimulator(singles(n, scenario="corridor", radius_min_m=0.2, radius_max_m=0.25,
                                 scenario_options=options))
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
    density, speed = corridor_speed(rho)
    assert density == pytest.approx(rho, rel=0.05)  # the ring holds the density we asked for
    assert abs(speed - weidmann(rho)) < 0.15, f"v({rho}) = {speed:.2f} m/s, Weidmann {weidmann(rho):.2f}"


def test_weidmann_reference_values():
    assert [round(weidmann(r), 2) for r in (0.5, 1.0, 2.0)] == [1.3, 1.06, 0.61]
