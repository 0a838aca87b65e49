"""Statistics of episode records: Wilson intervals, the per-policy summary, and paired tests between policies.

Rates are over the episodes that completed (outcome other than "error"); errors are counted apart. A paired
comparison uses only the episodes both policies completed (same cell and seed, so the same crowd and route).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from envs.evaluation.records import AT_FAULT, EpisodeRecord, finite_or_none
from envs.scoring.social_metrics import ZONES

Z95 = 1.959963984540054  # two-sided 95% normal quantile
ALPHA = 0.05
# Significance needs enough pairs; below these minimums a comparison is not tested (`tested` False, never
# `significant`) and the tables say so. The paired bootstrap (path length, min distance) needs MIN_BOOTSTRAP_PAIRS:
# its percentile interval is the spread of resampled means, too narrow for few pairs. Simulated on zero-mean
# differences (normal, Student t3 and skewed exponential; 4000 trials each) its 95% interval excluded 0 in 49% of
# trials at 2 pairs (the smoke suite's cells), 16-22% at 5, 9-15% at 10, 7-11% at 20 and 7-8% at 30: the rate
# falls steeply up to about 20 pairs and slowly after, so 20 is the floor (the shipped suites' pools have 100+).
MIN_BOOTSTRAP_PAIRS = 20


def wilson_interval(k: int, n: int, z: float = Z95) -> list[float] | None:
    """The Wilson score interval [lo, hi] for k successes in n trials (None when n == 0)."""
    if n <= 0:
        return None
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return [max(0.0, centre - half), min(1.0, centre + half)]


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar p-value for b and c discordant pairs (a binomial test of b against
    Binomial(b + c, 1/2)); 1.0 when there are no discordant pairs."""
    n = b + c
    if n == 0:
        return 1.0
    k = min(b, c)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def min_discordant_pairs(alpha: float = ALPHA) -> int:
    """The fewest discordant pairs with which the two-sided exact McNemar test can reach p < alpha (all of them on
    one side): 6 at alpha 0.05 (5 give p = 2 / 2**5 = 0.0625). With fewer the test is not made."""
    d = 1
    while mcnemar_exact(d, 0) >= alpha:
        d += 1
    return d


def paired_bootstrap(diff: np.ndarray, rng: np.random.Generator, n_boot: int = 10_000) -> tuple[float, list[float]]:
    """Mean of paired differences (n,) and its 95% percentile bootstrap interval (resampling pairs)."""
    diff = np.asarray(diff, float)
    if diff.size == 0:
        raise ValueError("no pairs to bootstrap")
    idx = rng.integers(0, diff.size, (n_boot, diff.size))
    means = diff[idx].mean(axis=1)
    return float(diff.mean()), [float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))]


def _mean(values: Sequence[float]) -> float | None:
    return float(np.mean(values)) if len(values) else None


def _rate(out: dict[str, Any], key: str, k: int, n: int) -> None:
    out[key] = k / n if n else None
    out[f"{key}_ci95"] = wilson_interval(k, n)


def aggregate(records: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """The summary of one policy's episodes (JSON-ready).

    Rates (with 95% Wilson intervals) are over completed episodes; the group intrusion rates only over those with
    group labels (`labelled` of them; None without any), `group_intrusion_rate_success` over the successful ones.
    Collisions split by who was at fault (`collisions_at_fault_<robot|pedestrian|spawn>`);
    `avoidable_collision_rate` counts robot and pedestrian faults, not tracks that began in contact;
    `spawn_contacts` counts the spawn contacts that did not end their episode
    (`CrowdNavConfig.spawn_contact_ends_episode` False). Time to goal and path length are over successes;
    min distance is the mean of the per-episode minima (episodes without pedestrians left out);
    solve-time percentiles are over every solver call (None without any); fallback rate = fallbacks / plans.
    """
    if not records:
        raise ValueError("no episodes to aggregate")
    # a fixed order (cell, policy, seed): float sums must not depend on which worker finished first
    records = sorted(records, key=lambda r: (str(r.cell), r.policy, r.seed))
    done = [r for r in records if r.outcome != "error"]
    n = len(done)
    count = {o: sum(r.outcome == o for r in done) for o in ("success", "collision", "timeout")}
    succ = [r for r in done if r.outcome == "success"]
    coll = [r for r in done if r.outcome == "collision"]
    out: dict[str, Any] = {"episodes": len(records), "completed": n, "errors": len(records) - n}
    for o in ("success", "collision", "timeout"):
        _rate(out, f"{o}_rate", count[o], n)
    _rate(out, "avoidable_collision_rate", sum(r.avoidable_collision for r in done), n)
    labelled = [r for r in done if r.group_intrusion is not None]
    out["labelled"] = len(labelled)
    _rate(out, "group_intrusion_rate", sum(r.group_intrusion for r in labelled), len(labelled))
    succ_labelled = [r for r in succ if r.group_intrusion is not None]
    out["group_intrusion_rate_success"] = (sum(r.group_intrusion for r in succ_labelled) / len(succ_labelled)
                                           if succ_labelled else None)
    out["collisions"] = len(coll)
    for who in AT_FAULT:
        out[f"collisions_at_fault_{who}"] = sum(r.at_fault == who for r in coll)
    out["wall_collisions"] = sum(r.collision_with == "wall" for r in coll)
    out["spawn_contacts"] = int(sum(r.spawn_contacts for r in done))  # non-terminal ones (kept out of the episode)
    out["time_to_first_collision_s"] = _mean([r.collision_time_s for r in coll if r.collision_time_s is not None])
    ttg = [r.time_to_goal_s for r in succ if r.time_to_goal_s is not None]
    out["time_to_goal_s"] = _mean(ttg)
    out["time_to_goal_median_s"] = float(np.median(ttg)) if ttg else None
    out["path_length_m"] = _mean([r.path_length_m for r in succ])
    mind = [r.min_distance_m for r in done if r.min_distance_m is not None]
    out["min_distance_m"] = _mean(mind)
    out["min_distance_overall_m"] = min(mind) if mind else None
    out["discomfort_frequency"] = _mean([r.discomfort_frequency for r in done])
    times = np.concatenate([np.asarray(r.solve_times_ms, float) for r in done]) if done else np.zeros(0)
    out["solve_time_p50_ms"] = float(np.percentile(times, 50)) if times.size else None
    out["solve_time_p95_ms"] = float(np.percentile(times, 95)) if times.size else None
    out["solver_calls"] = int(times.size)
    out["plans"] = int(sum(r.plans for r in done))
    out["fallbacks"] = int(sum(r.fallbacks for r in done))
    out["fallback_rate"] = out["fallbacks"] / out["plans"] if out["plans"] else None
    out["mean_return"] = _mean([r.ret for r in done])
    out.update(social_summary(done))
    return out


def social_summary(done: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """The social-navigation metrics of completed episodes (`envs.scoring.social_metrics`), each over the episodes that
    measured it (records written before these metrics hold None and are left out; None when none measured):
    mean seconds and mean fraction of episode time per Hall zone; `group_collision_rate` with its Wilson interval
    over episodes with group labels (`group_collision_measured` of them); mean path irregularity (rad) and jerk
    (m/s^3); `collision_course_rate` (Wilson) and `min_ttc_s`, the mean of the per-episode minimum time to
    collision over the episodes that were on a collision course; mean SPL (failures count 0); CrowdNav++'s `itr`,
    the mean of the per-episode intrusion ratios (every outcome, each episode weighing the same, as its
    rl/evaluation.py averages them), over `itr_measured` episodes, `itr_states` their intruding states, and
    `itr_sd_m`, the social distance pooled over those states (each state weighing the same; None without any)."""
    def mean(key: str) -> float | None:
        return _mean([v for r in done if (v := getattr(r, key)) is not None])

    out: dict[str, Any] = {}
    for zone in ZONES:
        out[f"time_{zone}_s"], out[f"{zone}_fraction"] = mean(f"time_{zone}_s"), mean(f"{zone}_fraction")
    measured = [r for r in done if r.group_collision is not None]
    out["group_collision_measured"] = len(measured)
    _rate(out, "group_collision_rate", sum(bool(r.group_collision) for r in measured), len(measured))
    out["path_irregularity_rad"], out["jerk_mps3"] = mean("path_irregularity_rad"), mean("jerk_mps3")
    course = [r for r in done if r.collision_course is not None]
    _rate(out, "collision_course_rate", sum(bool(r.collision_course) for r in course), len(course))
    out["min_ttc_s"] = _mean([r.min_ttc_s for r in course if r.collision_course and r.min_ttc_s is not None])
    out["spl"] = mean("spl")
    itr = [r for r in done if r.itr is not None]
    states = [(r.itr_states, r.itr_sd_m) for r in itr if r.itr_states and r.itr_sd_m is not None]
    out["itr_measured"], out["itr"] = len(itr), _mean([r.itr for r in itr])
    out["itr_states"] = int(sum(n for n, _ in states))
    out["itr_sd_m"] = sum(n * sd for n, sd in states) / out["itr_states"] if states else None
    return out


PAIRED_EVENTS: dict[str, Callable[[EpisodeRecord], bool]] = {
    "success": lambda r: r.outcome == "success",
    "collision": lambda r: r.outcome == "collision",
    "avoidable_collision": lambda r: r.avoidable_collision,
    "group_intrusion": lambda r: bool(r.group_intrusion),
}


def both_labelled(a: EpisodeRecord, b: EpisodeRecord) -> bool:
    """Whether both episodes of a pair measured group intrusion (their crowd had group labels)."""
    return a.group_intrusion is not None and b.group_intrusion is not None


def paired_comparison(a: Sequence[EpisodeRecord], b: Sequence[EpisodeRecord], alpha: float = ALPHA,
                      seed: int = 0) -> dict[str, Any]:
    """Policy a against policy b on the episodes both completed (matched by cell and seed).

    For each binary event (success, collision, avoidable collision, group intrusion, the last only on pairs where
    both episodes had group labels; `pairs` says how many): counts, the discordant
    pairs (a only, b only), the exact McNemar p-value, `tested` (at least `min_discordant_pairs(alpha)` discordant
    pairs) and `significant` (tested and p < alpha). For the path length of episodes both succeeded, and for the
    smallest robot-pedestrian surface distance of episodes where both met somebody (`min_distance_m`: a graded
    safety margin, more sensitive than the collision count): the mean paired difference a - b and, from
    `MIN_BOOTSTRAP_PAIRS` pairs on (`tested`), its 95% paired-bootstrap interval (seeded by `seed`; `ci95` None
    below), `significant` when it excludes 0.
    """
    bkeys = {(r.cell, r.seed): r for r in b if r.outcome != "error"}
    pairs = [(r, bkeys[(r.cell, r.seed)]) for r in a if r.outcome != "error" and (r.cell, r.seed) in bkeys]
    min_discordant = min_discordant_pairs(alpha)
    out: dict[str, Any] = {"policy_a": a[0].policy if a else None, "policy_b": b[0].policy if b else None,
                           "pairs": len(pairs), "alpha": alpha, "test": "exact McNemar (two-sided)",
                           "min_discordant_pairs": min_discordant, "min_bootstrap_pairs": MIN_BOOTSTRAP_PAIRS}
    for name, event in PAIRED_EVENTS.items():
        on = [(x, y) for x, y in pairs if name != "group_intrusion" or both_labelled(x, y)]
        only_a = sum(event(x) and not event(y) for x, y in on)
        only_b = sum(event(y) and not event(x) for x, y in on)
        p = mcnemar_exact(only_a, only_b)
        tested = only_a + only_b >= min_discordant
        out[name] = {"pairs": len(on), "a": sum(event(x) for x, _ in on), "b": sum(event(y) for _, y in on),
                     "a_only": only_a, "b_only": only_b, "p_value": p, "tested": tested,
                     "significant": tested and p < alpha}
    graded = {"path_length_m": [(x.path_length_m, y.path_length_m) for x, y in pairs
                                if x.outcome == y.outcome == "success"],
              "min_distance_m": [(x.min_distance_m, y.min_distance_m) for x, y in pairs
                                 if x.min_distance_m is not None and y.min_distance_m is not None]}
    for name, both in graded.items():
        if len(both) >= MIN_BOOTSTRAP_PAIRS:
            mean, ci = paired_bootstrap(np.subtract(*np.array(both, float).T), np.random.default_rng(seed))
            out[name] = {"pairs": len(both), "mean_diff": mean, "ci95": ci, "tested": True,
                         "significant": not ci[0] <= 0.0 <= ci[1]}
        elif both:
            out[name] = {"pairs": len(both), "mean_diff": float(np.mean(np.subtract(*np.array(both, float).T))),
                         "ci95": None, "tested": False, "significant": False}
    return out


__all__ = ["MIN_BOOTSTRAP_PAIRS", "aggregate", "finite_or_none", "mcnemar_exact", "min_discordant_pairs",
           "paired_bootstrap", "paired_comparison", "social_summary", "wilson_interval"]
