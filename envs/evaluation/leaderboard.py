"""The benchmark leaderboard: policies x cells with Wilson intervals, pooled real and synthetic columns, and
paired comparisons of every two policies on the same episodes (exact McNemar; paired bootstrap for path length
and minimum distance).

Files in the output folder: `leaderboard.json`, `leaderboard.md`, `leaderboard.png`.
"""

from __future__ import annotations

from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np

from envs.atomic import write_json_atomic, write_text_atomic
from envs.evaluation.bounds import bounds_summary, bounds_table
from envs.evaluation.records import EpisodeRecord
from envs.evaluation.reference import (
    REFERENCE_POLICY,
    against_reference,
    bound_classes,
    bound_failure_table,
    reference_table,
)
from envs.evaluation.report import (
    SOCIAL_ROWS,
    fmt,
    intrusion_text,
    na,
    paired_table,
    pyplot,
    rate_errors,
    rate_text,
    save_figure,
)
from envs.evaluation.stats import aggregate, paired_comparison
from envs.evaluation.suite import Cell, Suite
from envs.policies import PolicyConfig
from envs.policies.identity import agent_observation

POOLS = ("real", "synthetic", "all")


def _pool(cells: list[Cell], pool: str) -> set[str]:
    return {c.name for c in cells if pool == "all" or c.is_real == (pool == "real")}


def leaderboard(suite: Suite, cells: list[Cell], policies: list[PolicyConfig], records: list[EpisodeRecord],
                bounds: dict[tuple[str, int], dict[str, Any]] | None = None) -> dict[str, Any]:
    """JSON-ready: per cell and pool, each policy's `stats.aggregate` (without per-episode data), and the
    paired comparisons of every policy pair per pool (pairs matched by cell and seed). With `bounds` (the
    any-robot verdicts by (cell, seed), `envs.evaluation.bounds`): their summary and each policy's failures by
    verdict, per pool."""
    by: dict[tuple[str, str], list[EpisodeRecord]] = {}
    for r in records:
        by.setdefault((r.cell, r.policy), []).append(r)
    names = [p.name for p in policies]
    observed = {p.name: pred for p in policies if (pred := observed_predictor(p))}
    board: dict[str, Any] = {
        "suite": suite.name, "version": suite.version, "description": suite.description,
        "policies": {p.name: p.to_json() for p in policies},
        "cells": {c.name: {"spec": c.spec, "seeds": [c.seeds[0], c.seeds[-1]], "results": {},
                           "predictors": {p.name: pred for p in policies
                                          if (pred := observed.get(p.name)
                                              or p.for_cell(c.scene, c.predictor).predictor_used())}}
                  for c in cells},
        "observed_predictions": sorted(observed),
        "pooled": {}, "paired": {},
    }
    for c in cells:
        for name in names:
            recs = by.get((c.name, name), [])
            board["cells"][c.name]["results"][name] = aggregate(recs) if recs else None
    for pool in POOLS:
        members = _pool(cells, pool)
        if not members:
            continue
        pooled = {n: [r for (cell, pol), rs in by.items() if cell in members and pol == n for r in rs] for n in names}
        board["pooled"][pool] = {n: aggregate(rs) if rs else None for n, rs in pooled.items()}
        board["paired"][pool] = [paired_comparison(pooled[a], pooled[b]) for a, b in combinations(names, 2)
                                 if pooled[a] and pooled[b]]
    if REFERENCE_POLICY in names:
        board["reference"] = _reference(cells, names, by)
    if bounds:
        failures = {pool: {n: bound_classes([r for c in members for r in by.get((c, n), [])], bounds)
                           for n in names}
                    for pool in POOLS if (members := _pool(cells, pool))}
        board["bounds"] = {"summary": bounds_summary(suite, cells, bounds), "failures": failures}
    return board


def _reference(cells: list[Cell], names: list[str], by: dict[tuple[str, str], list[EpisodeRecord]]) -> dict[str, Any]:
    """Each other policy against `REFERENCE_POLICY`, per cell and per pool (`envs.evaluation.reference`)."""
    others = [n for n in names if n != REFERENCE_POLICY]

    def compare(members: set[str]) -> dict[str, Any]:
        ref = [r for c in members for r in by.get((c, REFERENCE_POLICY), [])]
        return {n: against_reference([r for c in members for r in by.get((c, n), [])], ref) for n in others}

    pooled = {pool: compare(members) for pool in POOLS if (members := _pool(cells, pool))}
    return {"policy": REFERENCE_POLICY, "cells": {c.name: compare({c.name}) for c in cells}, "pooled": pooled}


def _cell_rate(res: dict[str, Any] | None, key: str) -> str:
    return "–" if res is None else rate_text(res, key)


def _matrix(board: dict[str, Any], key: str, title: str) -> list[str]:
    names = list(board["policies"])
    lines = [f"### {title}", "", "| cell | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for cell, entry in board["cells"].items():
        lines.append(f"| {cell} | " + " | ".join(_cell_rate(entry["results"][n], key) for n in names) + " |")
    for pool, res in board["pooled"].items():
        lines.append(f"| **pooled {pool}** | " + " | ".join(_cell_rate(res[n], key) for n in names) + " |")
    return [*lines, ""]


def _summary(board: dict[str, Any]) -> list[str]:
    lines = ["### Pooled summary", "", "| pool | policy | episodes | errors | success | collision | avoidable coll. "
             "| at fault robot/ped/spawn (+ non-terminal spawn contacts) | timeout | group intrusion "
             "| time to goal (s) | plan p50/p95 (ms) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for pool, res in board["pooled"].items():
        for name, r in res.items():
            if r is None:
                continue
            lines.append(
                f"| {pool} | {name} | {r['episodes']} | {r['errors']} | {_cell_rate(r, 'success_rate')} | "
                f"{_cell_rate(r, 'collision_rate')} | {_cell_rate(r, 'avoidable_collision_rate')} | "
                f"{r['collisions_at_fault_robot']}/{r['collisions_at_fault_pedestrian']}/{r['collisions_at_fault_spawn']}"
                f"{' (+' + str(r['spawn_contacts']) + ')' if r.get('spawn_contacts') else ''} | "
                f"{fmt(r['timeout_rate'])} | {intrusion_text(r, 'group_intrusion_rate')} | "
                f"{fmt(r['time_to_goal_s'])} | "
                f"{fmt(r['solve_time_p50_ms'], 1)}/{fmt(r['solve_time_p95_ms'], 1)} |")
    return [*lines, ""]


def _social(board: dict[str, Any]) -> list[str]:
    """The social-navigation metrics per pool and policy (`report.SOCIAL_ROWS`; "n/a" where not measured, e.g.
    records written before these metrics), then SPL per cell."""
    lines = ["### Social-navigation metrics (all completed episodes; definitions: docs/envs.md)", "",
             "| pool | policy | " + " | ".join(name for name, _ in SOCIAL_ROWS) + " |",
             "|---|---|" + "---|" * len(SOCIAL_ROWS)]
    for pool, res in board["pooled"].items():
        lines += [f"| {pool} | {name} | " + " | ".join(f(r) for _, f in SOCIAL_ROWS) + " |"
                  for name, r in res.items() if r is not None]
    names = list(board["policies"])
    lines += ["", "### SPL (success weighted by path length)", "", "| cell | " + " | ".join(names) + " |",
              "|---|" + "---|" * len(names)]
    for cell, entry in board["cells"].items():
        lines.append(f"| {cell} | " + " | ".join("–" if (r := entry["results"][n]) is None else na(r.get("spl"), 3)
                                                 for n in names) + " |")
    return [*lines, ""]


def leaderboard_markdown(board: dict[str, Any]) -> str:
    """The leaderboard as markdown: pooled summary, collision and success matrices, social-navigation metrics,
    paired comparisons."""
    head = [f"## Leaderboard: suite {board['suite']} v{board['version']}", "", board["description"], "",
            *_predictors(board)]
    body = (_summary(board) + _matrix(board, "collision_rate", "Collision rate [95% Wilson CI]")
            + _matrix(board, "avoidable_collision_rate", "Avoidable collision rate (robot or pedestrian at fault)")
            + _matrix(board, "success_rate", "Success rate [95% Wilson CI]") + _social(board) + reference_table(board)
            + _bounds(board) + paired_table(board["paired"]))
    return "\n".join(head + body)


def observed_predictor(policy: PolicyConfig) -> str | None:
    """The predictions an SB3 agent observes (`envs.policies.identity.agent_observation`: its training run's
    predictor, or `oracle` for the true future), which the env runs for it in every episode; None without."""
    seen = agent_observation(policy)
    if not seen.get("predictions"):
        return None
    return "oracle" if seen.get("prediction_source") == "oracle" else seen.get("predictor")


def _predictors(board: dict[str, Any]) -> list[str]:
    """One line naming the predictor of each policy that runs one, with the cells where it ran it (an agent's
    observed predictions said so)."""
    used: dict[str, dict[str, list[str]]] = {}
    for cell, entry in board["cells"].items():
        for name, pred in entry.get("predictors", {}).items():
            used.setdefault(name, {}).setdefault(pred, []).append(cell)
    if not used:
        return ["Predictors: none of these policies runs one.", ""]
    every = set(board["cells"])
    seen = set(board.get("observed_predictions", ()))
    parts = [f"{name}: " + "; ".join(f"`{pred}`" + ("" if set(cells) == every else f" ({', '.join(cells)})")
                                     for pred, cells in by.items())
             + (" (in the agent's observation)" if name in seen else "") for name, by in used.items()]
    return ["Predictors: " + " · ".join(parts) + ".", ""]


def _bounds(board: dict[str, Any]) -> list[str]:
    return [*bounds_table(board["bounds"]["summary"]), "", *bound_failure_table(board)] if "bounds" in board else []


def leaderboard_png(board: dict[str, Any], path: str | Path) -> None:
    """Two panels (success, collision): one group of bars per cell and pool, a bar per policy, Wilson CIs."""
    plt = pyplot()
    names = list(board["policies"])
    rows = [(c, e["results"]) for c, e in board["cells"].items()] + \
        [(f"pooled {p}", r) for p, r in board["pooled"].items()]
    fig, axes = plt.subplots(2, 1, figsize=(max(8.0, 0.55 * len(rows) * max(1, len(names)) / 2), 7.5), sharex=True)
    width = 0.8 / len(names)
    x = np.arange(len(rows))
    for ax, key in zip(axes, ("success_rate", "collision_rate"), strict=True):
        for j, name in enumerate(names):
            results = [res.get(name) or {key: None} for _, res in rows]
            vals = np.array([r[key] or 0.0 for r in results])
            ax.bar(x + (j - (len(names) - 1) / 2) * width, vals, width, yerr=rate_errors(results, key), capsize=2,
                   label=name)
        ax.set_ylabel(key.replace("_", " ") + " (95% CI)")
        ax.set_ylim(0, 1.05)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8, ncol=len(names))
    axes[1].set_xticks(x, [r[0] for r in rows], rotation=60, ha="right", fontsize=7)
    fig.suptitle(f"suite {board['suite']} v{board['version']}", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def write_leaderboard(board: dict[str, Any], out: Path) -> None:
    write_json_atomic(Path(out) / "leaderboard.json", board)
    write_text_atomic(Path(out) / "leaderboard.md", leaderboard_markdown(board) + "\n")
    leaderboard_png(board, Path(out) / "leaderboard.png")
