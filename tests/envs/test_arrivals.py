"""A walker who has just come into view, in closed loop: the back-filled history lets the MPC see it walking."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from envs import CrowdNavConfig, CrowdNavEnv
from envs.crowds.replay import ReplayConfig
from envs.evaluation.episode import run_episode
from envs.history import PedHistory


def _overtaking_walker(tmp_path: Path, x0: float, y0: float) -> tuple[CrowdNavConfig, CrowdNavEnv]:
    """The robot cruises from (0, 0) to (14, 0); 2.4 s into the episode (frame 14, robot near x = 2.4 m at
    1.2 m/s) a replayed walker comes into view behind it at (x0, y0) m, overtaking at 2.5 m/s along +x."""
    path = tmp_path / f"overtake_{x0}_{y0}.txt"
    rows = [f"{10 * t}\t1\t20.0\t20.0" for t in range(60)]
    rows += [f"{10 * t}\t3\t{x0 + 1.0 * (t - 14)}\t{y0}" for t in range(14, 60)]  # 1.0 m per 0.4 s frame
    path.write_text("\n".join(rows) + "\n")
    cfg = CrowdNavConfig(scenario="replay", time_limit_s=15.0, replay=ReplayConfig(path=path, start_mode="fixed"))
    env = CrowdNavEnv(cfg)
    env.crowd.robot_route = lambda rng: (np.array([0.0, 0.0]), np.array([14.0, 0.0]))
    return cfg, env


@pytest.mark.slow
def test_mpc_cv_gives_way_to_an_overtaking_walker_it_has_just_seen(tmp_path, monkeypatch):
    # each scenario twice: as the env sees it now, and with the rows before the walker came into view padded at its
    # first position (early velocity zero: exactly the history before the back-fill, which saw it standing still
    # for 0.4-0.8 s); mpc-cv extrapolates the last two rows, so only the history differs
    scenarios = [(0.5, 0.0), (0.5, 0.1), (0.8, 0.0), (0.8, 0.1)]
    outcomes: dict[str, list[tuple[str, float]]] = {"walking": [], "standing": []}
    for arm in ("walking", "standing"):
        if arm == "standing":
            monkeypatch.setattr(PedHistory, "early_velocity", lambda self, ids: np.zeros((len(ids), 2)))
        for x0, y0 in scenarios:
            cfg, env = _overtaking_walker(tmp_path, x0, y0)
            m = run_episode(cfg, "mpc-cv", 0, env=env).metrics
            outcomes[arm].append((m["outcome"], m["min_distance_m"]))
    walking = [o == "collision" for o, _ in outcomes["walking"]]
    standing = [o == "collision" for o, _ in outcomes["standing"]]
    assert sum(walking) < sum(standing), outcomes  # measured: 1 of 4 against 3 of 4
    for (_, seen_walking), (_, seen_standing) in zip(outcomes["walking"], outcomes["standing"], strict=True):
        assert seen_walking >= seen_standing - 0.02, outcomes  # never closer to the walker
