"""ORCA (reciprocal collision avoidance, RVO2) through `pyrvo`: the only module that imports it.

`pyrvo` is an optional dependency (the `orca` extra; `make setup` installs it without its declared `ir-sim`
dependency, which it does not import: README, "CrowdNav's settings"). Every call builds a fresh `RVOSimulator` from
the arrays it is given and steps it once, so ORCA holds no state between calls: the caller keeps positions and
velocities (float64), and a fork of a crowd is a copy of its arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

INSTALL_HINT = "pip install --no-deps 'pyrvo==0.4.3'"


def load_pyrvo() -> Any:
    """The `pyrvo` module; ValueError with one line saying how to install it when it is missing."""
    try:
        import pyrvo
    except ImportError as exc:
        raise ValueError(f"the ORCA crowd model and the orca policy need the package pyrvo, which is not installed "
                         f"({INSTALL_HINT})") from exc
    return pyrvo


@dataclass(frozen=True)
class OrcaParams:
    """ORCA's agent parameters (RVO2's names), CrowdNav's values by default.

    neighbor_dist_m: centre distance within which other agents are considered, m.
    max_neighbors: at most this many (the nearest) are considered.
    time_horizon_s: new velocities are collision-free with other agents for at least this long, s.
    time_horizon_obst_s: the same for obstacles (there are none here), s.
    safety_space_m: added to every radius inside ORCA (CrowdNav also adds 0.01 m: `PAD_M`), m.
    time_step_s: ORCA's step: its velocities hold this long; it also sets how fast an overlap is resolved, s.
    """

    neighbor_dist_m: float = 10.0
    max_neighbors: int = 10
    time_horizon_s: float = 5.0
    time_horizon_obst_s: float = 5.0
    safety_space_m: float = 0.0
    time_step_s: float = 0.25

    def __post_init__(self) -> None:
        for name in ("neighbor_dist_m", "time_horizon_s", "time_horizon_obst_s", "time_step_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ValueError(f"OrcaParams.{name} must be a positive finite number, got {value!r}")
        if not (np.isfinite(self.safety_space_m) and self.safety_space_m >= 0):
            raise ValueError(f"OrcaParams.safety_space_m must be finite and >= 0, got {self.safety_space_m!r}")
        if not isinstance(self.max_neighbors, int) or self.max_neighbors < 1:
            raise ValueError(f"OrcaParams.max_neighbors must be an integer >= 1, got {self.max_neighbors!r}")


PAD_M = 0.01  # CrowdNav's ORCA pads every radius by 1 cm on top of the safety space


def pref_velocity(pos: np.ndarray, goal: np.ndarray, v_pref: np.ndarray) -> np.ndarray:
    """CrowdNav's preferred velocity (N, 2) m/s: towards the goal at v_pref, or the remaining vector itself (which
    slows the agent down) once the goal is nearer than one second at v_pref. pos, goal (N, 2) m; v_pref (N,) m/s."""
    d = np.asarray(goal, float) - np.asarray(pos, float)
    dist = np.linalg.norm(d, axis=1)
    v = np.asarray(v_pref, float)
    scale = np.where(dist > v, v / np.maximum(dist, 1e-12), 1.0)
    return d * scale[:, None]


def orca_velocities(pos: np.ndarray, vel: np.ndarray, pref_vel: np.ndarray, radius: np.ndarray,
                    max_speed: np.ndarray, params: OrcaParams) -> np.ndarray:
    """One ORCA step for N agents: the new velocities (N, 2) m/s.

    pos (N, 2) m, vel (N, 2) m/s (current), pref_vel (N, 2) m/s, radius (N,) m (padded by safety_space + PAD_M here),
    max_speed (N,) m/s. Each agent avoids every other agent it is given, assuming they share the avoidance; leave
    out of the arrays whoever an agent must not see. Deterministic: the same arrays give the same velocities.
    """
    n = len(pos)
    if n == 0:
        return np.zeros((0, 2))
    pyrvo = load_pyrvo()
    p = params
    sim = pyrvo.RVOSimulator()
    sim.set_time_step(p.time_step_s)
    sim.set_agent_defaults(p.neighbor_dist_m, p.max_neighbors, p.time_horizon_s, p.time_horizon_obst_s,
                           0.3, 1.0)
    pad = p.safety_space_m + PAD_M
    for i in range(n):
        sim.add_agent((float(pos[i, 0]), float(pos[i, 1])), p.neighbor_dist_m, p.max_neighbors, p.time_horizon_s,
                      p.time_horizon_obst_s, float(radius[i]) + pad, float(max_speed[i]),
                      (float(vel[i, 0]), float(vel[i, 1])))
        sim.set_agent_pref_velocity(i, (float(pref_vel[i, 0]), float(pref_vel[i, 1])))
    sim.do_step()
    return np.array([sim.get_agent_velocity(i).to_tuple() for i in range(n)], dtype=float)
