"""Every policy against the reference `mpc-oracle` on the same episodes: whose limit each failure is, and the headroom.

A failure (collision or time-out) of a policy on an episode is "the oracle also fails" when the oracle, with the
true future, fails on that same episode too (the cell or the planner's formulation is the limit), or "the oracle
succeeds" (prediction is the limit). The headroom is the paired difference in success (policy minus oracle) over
the episodes both finished, with a 95% paired-bootstrap interval from `stats.MIN_BOOTSTRAP_PAIRS` pairs on.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from envs.evaluation.records import EpisodeRecord
from envs.evaluation.stats import MIN_BOOTSTRAP_PAIRS, paired_bootstrap

REFERENCE_POLICY = "mpc-oracle"
FAILURES = ("collision", "timeout")


def against_reference(policy: Sequence[EpisodeRecord], reference: Sequence[EpisodeRecord],
                      seed: int = 0) -> dict[str, Any]:
    """The failure classes and success headroom of `policy`'s records against `reference`'s (pairs matched by cell
    and seed; episodes that ended in an error are left out). JSON-ready."""
    ref = {(r.cell, r.seed): r for r in reference if r.outcome != "error"}
    pairs = [(r, ref[(r.cell, r.seed)]) for r in policy if r.outcome != "error" and (r.cell, r.seed) in ref]
    failed = [(r, o) for r, o in pairs if r.outcome in FAILURES]
    also = sum(o.outcome != "success" for _, o in failed)
    diff = np.array([float(r.outcome == "success") - float(o.outcome == "success") for r, o in pairs])
    tested = len(pairs) >= MIN_BOOTSTRAP_PAIRS
    mean, ci = paired_bootstrap(diff, np.random.default_rng(seed)) if tested else (
        float(diff.mean()) if len(diff) else None, None)
    return {"pairs": len(pairs), "failures": len(failed), "reference_also_fails": also,
            "reference_succeeds": len(failed) - also, "success_headroom": mean, "ci95": ci, "tested": tested}


def reference_table(board: dict[str, Any]) -> list[str]:
    """Markdown: per cell and pool, each policy's failures split by the oracle's outcome, and its headroom."""
    ref = board.get("reference")
    if not ref:
        return []
    lines = [f"### Against the reference ({ref['policy']}, the true future)", "",
             "Failures (collision or time-out) where the oracle also fails on the same episode (the cell or the "
             "formulation is the limit) / where it succeeds (the prediction is the limit); headroom: success "
             "rate minus the oracle's on the same episodes [95% paired-bootstrap CI].", "",
             "| cell or pool | policy | pairs | failures | oracle also fails / succeeds | success headroom [95% CI] |",
             "|---|---|---|---|---|---|"]
    for where, by_policy in [*ref["cells"].items(), *((f"**pooled {k}**", v) for k, v in ref["pooled"].items())]:
        for name, c in by_policy.items():
            head = "–" if c["success_headroom"] is None else f"{c['success_headroom']:+.2f}"
            ci = f" [{c['ci95'][0]:+.2f}, {c['ci95'][1]:+.2f}]" if c["ci95"] else " (n.t.)"
            lines.append(f"| {where} | {name} | {c['pairs']} | {c['failures']} | {c['reference_also_fails']} / "
                         f"{c['reference_succeeds']} | {head}{ci if head != '–' else ''} |")
    return [*lines, ""]


def bound_classes(records: Sequence[EpisodeRecord], bounds: dict[tuple[str, int], dict[str, Any]]) -> dict[str, Any]:
    """A policy's failures by the episode's any-robot verdict (`envs.evaluation.bounds`): on episodes no robot
    could succeed in ("infeasible"), undecided ("open"), or where a holonomic robot had a contact-free path
    ("feasible"); `robot_wins`: of the feasible ones, those the benchmark's robot won tracking a witness path;
    `sensing_wins`: failures on episodes it won knowing only the people it had sensed (`envs.evaluation.sensing`);
    `unbounded`: failures on episodes without a bound (people there see the robot).
    `successes_on_infeasible` must be 0: a success there would contradict the bound."""
    out = {"failures": 0, "infeasible": 0, "open": 0, "feasible": 0, "robot_wins": 0, "sensing_wins": 0,
           "unbounded": 0, "successes_on_infeasible": 0}
    for r in records:
        b = bounds.get((r.cell, r.seed))
        if r.outcome == "success" and b is not None and b["verdict"] == "infeasible":
            out["successes_on_infeasible"] += 1
        if r.outcome in FAILURES:
            out["failures"] += 1
            out["unbounded" if b is None else b["verdict"]] += 1
            out["robot_wins"] += b is not None and b.get("robot_witness") == "success"
            out["sensing_wins"] += b is not None and b.get("sensing_witness") == "success"
    return out


def bound_failure_table(board: dict[str, Any]) -> list[str]:
    """Markdown: each policy's failures per pool split by the any-robot verdict."""
    b = board.get("bounds")
    if not b:
        return []
    lines = ["### Failures against what any robot could do", "",
             "A policy's failures (collision or time-out) on episodes no robot could succeed in / undecided / "
             "where a holonomic robot had a contact-free path (of which the benchmark's robot, knowing the future, "
             "won by tracking one) / not bounded (people see the robot); sensing robot won: failures on episodes the "
             "robot won knowing the future only of the people it had sensed.", "",
             "| pool | policy | failures | infeasible | open | feasible (robot won) | sensing robot won | "
             "not bounded |",
             "|---|---|---|---|---|---|---|---|"]
    for pool, by_policy in b["failures"].items():
        for name, c in by_policy.items():
            flag = f" ({c['successes_on_infeasible']} successes on infeasible episodes!)" \
                if c["successes_on_infeasible"] else ""
            lines.append(f"| {pool} | {name} | {c['failures']} | {c['infeasible']} | {c['open']} | {c['feasible']} "
                         f"({c['robot_wins']}) | {c['sensing_wins']} | {c['unbounded']}{flag} |")
    return [*lines, ""]
