"""`NAME+shield`: any policy's decision checked by the MPC's safety shield before the env applies it.

A learned agent decides in about a millisecond but has no notion of a hard constraint: where its training did not
cover a situation, it drives into people. The shield (`planner.shield`, the one `mpc-gpgraph` and `mpc-cv` run
after their solve) is a cheap check of that decision, every env step:

1. the wrapped policy decides (`Decision.action`, mapped to its command by `envs.view.action_command`, or
   `Decision.control`);
2. the command, held over ``shield_horizon_s``, is rolled out with the robot's limits and checked against the
   pedestrians' constant-velocity future (from the last two 0.4 s rows of `view.history`, the future `mpc-cv`
   plans with), which counts as certain, and the walls;
3. if it comes closer than ``shield_margin_m`` to someone (the constant-velocity future counts as certain) or
   touches a wall, the shield replaces it by the constant command (a grid of speed x yaw rate) with the least
   time-discounted violation; otherwise the wrapped policy's decision goes to the env unchanged (its action,
   bit for bit).

The settings are `PolicyConfig.mpc`'s shield fields (`CROWD_MPC` by default: 1.6 s look-ahead, 0.15 m margin,
checked every 0.1 s), with the env's robot. `stats` counts the decisions (`calls`) and the replaced ones
(`shielded`), and times each whole decision (the wrapped policy and the shield). A policy whose own planner
already shields (the registry's MPC policies) is refused (`envs.policies.wrappers`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from envs.policies.wrappers import SHIELD_SUFFIX
from envs.view import Decision, PolicyView, action_command
from planner import MPCConfig, PlanStats
from planner.shield import cv_futures, horizon_steps, shield_futures


class ShieldedPolicy:
    """`inner` with every decision checked by the safety shield of `config` (see the module docstring)."""

    def __init__(self, inner: Any, config: MPCConfig) -> None:
        if config.shield_horizon_s <= 0:
            raise ValueError("the shield needs MPCConfig.shield_horizon_s > 0 (0 turns it off)")
        self.inner, self.config = inner, config
        # the constant-velocity future needs the window's last two rows; more if the wrapped policy reads more
        reads = getattr(inner, "reads_history", True)
        self.reads_history: bool | int = True if reads is True else max(2, int(reads))
        self.reads_track = getattr(inner, "reads_track", False)
        self.name = f"{inner.name}{SHIELD_SUFFIX}"
        self.stats = PlanStats()

    def reset(self, seed: int | None = None) -> None:
        self.inner.reset(seed)

    def act(self, view: PolicyView) -> Decision:
        start = time.perf_counter()
        decision = self.inner.act(view)
        command = decision.control if decision.control is not None else action_command(*decision.action, view.robot)
        futures, radii = self._futures(view)
        verdict = shield_futures(view.robot_state, np.asarray(command, float)[None], futures, radii, view.walls,
                                 self.config, certain_last=True)
        self.stats.counts["calls"] += 1
        self.stats.counts["shielded"] += int(verdict.replaced)
        self.stats.solve_times_s.append(time.perf_counter() - start)
        if not verdict.replaced:
            return decision
        return Decision(control=verdict.control, plan=decision.plan, predictions=decision.predictions,
                        predicted_group_id=decision.predicted_group_id)


    def _futures(self, view: PolicyView) -> tuple[np.ndarray, np.ndarray]:
        """The pedestrians' constant-velocity future (1, T, N, 2) at the shield's times, from the last two rows of
        `view.history` (`view.timing.step_s` apart), and their radii (N,)."""
        p, cfg = view.pedestrians, self.config
        if len(p.pos) == 0 or view.history is None:
            return np.zeros((1, horizon_steps(cfg), 0, 2)), np.zeros(0)
        hist = np.asarray(view.history, float)
        velocity = (hist[-1] - hist[-2]) / view.timing.step_s if len(hist) >= 2 else np.zeros_like(hist[-1])
        return cv_futures(hist[-1], velocity, cfg.shield_dt_s, horizon_steps(cfg)), np.asarray(p.radius, float)
