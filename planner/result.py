"""Planner outputs: :class:`PlanResult` per call and :class:`PlanStats` over calls."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

# Outcome of one plan() call. "solved" is the only one that uses the solver's plan.
STATUSES = ("solved", "solver_failed", "timeout", "nan", "infeasible", "solver_error", "reactive")
FALLBACKS = ("previous_plan", "brake")


@dataclass(frozen=True)
class PlanResult:
    """One planning step.

    control: (2,) first control to apply for dt_s (unicycle v m/s, omega rad/s; holonomic vx, vy m/s).
    states: (H+1, state_dim) planned states, row 0 = the measured state.
    controls: (H, 2) planned controls.
    status: one of ``STATUSES``; solver_status: the solver's own return status string.
    solve_time_s: wall time of the solver call, plus the route's subgoal and the safety shield's check when on
    (0 for reactive controllers).
    plan_time_s: wall time of the whole ``plan()`` call: input checks, route, the NLP's scene arrays and initial
    guess, the solver call and the shield (0 for reactive controllers). This is the planner's latency; before
    2026-11-27 the benchmark's plan times were ``solve_time_s``, 7-15 ms less in dense crowds.
    iterations: solver iterations (0 when no solver ran).
    max_slack_m: largest violation of a soft clearance constraint by the planned states, m (for a start
    in collision, how deep the robot overlaps).
    fallback: None, or how the control was made instead (``"previous_plan"`` or ``"brake"``).
    shield_risk: the fraction of predicted samples the plan's first control came too close to (0 without a
    shield); shielded: True when the safety shield replaced that control (``planner/shield.py``).
    subgoal: the point (2,) m the solve headed for: the goal, or the global route's subgoal (``planner/route.py``);
    None when no solve ran.
    options: with guidance (``MPCConfig.guidance``), the planned states (H+1, state_dim) of every solved passing
    option, the chosen one first (planner/guidance.py); empty otherwise.
    """

    control: np.ndarray
    states: np.ndarray
    controls: np.ndarray
    status: str
    solver_status: str = ""
    solve_time_s: float = 0.0
    iterations: int = 0
    max_slack_m: float = 0.0
    fallback: str | None = None
    shield_risk: float = 0.0
    shielded: bool = False
    subgoal: np.ndarray | None = None
    plan_time_s: float = 0.0
    options: tuple[np.ndarray, ...] = ()

    @property
    def fallback_used(self) -> bool:
        """True when the control does not come from a fresh plan."""
        return self.fallback is not None


@dataclass
class PlanStats:
    """Counts of every outcome and the plan times (s, `PlanResult.plan_time_s`: whole ``plan()`` calls) of every
    call that ran the solver. (The field keeps its old name, ``solve_times_s``, as the benchmark records keep
    ``solve_times_ms``.)"""

    counts: Counter = field(default_factory=Counter)
    solve_times_s: list[float] = field(default_factory=list)

    def record(self, result: PlanResult) -> None:
        """Count ``result``'s status and fallback, and keep its plan time if the solver ran."""
        self.counts["calls"] += 1
        self.counts[result.status] += 1
        if result.fallback is not None:
            self.counts[f"fallback_{result.fallback}"] += 1
        if result.shielded:
            self.counts["shielded"] += 1
        if result.iterations > 0 or result.solve_time_s > 0:
            self.solve_times_s.append(result.plan_time_s)

    def summary(self) -> dict[str, float]:
        """calls, plan-time p50/p95/max in ms, fallback rate (fraction of calls)."""
        times = np.asarray(self.solve_times_s) * 1e3
        calls = max(self.counts["calls"], 1)
        fallbacks = sum(self.counts[f"fallback_{name}"] for name in FALLBACKS)
        out = {"calls": float(self.counts["calls"]), "fallback_rate": fallbacks / calls}
        if times.size:
            out.update(p50_ms=float(np.percentile(times, 50)), p95_ms=float(np.percentile(times, 95)),
                       max_ms=float(times.max()))
        return out
