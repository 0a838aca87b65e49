"""Report files of evaluations: markdown tables, PNG plots. Everything is written atomically (`envs.atomic`).

`markdown_table(result)` and `plot_result(result, scenes, path)` describe one policy's evaluation;
`compare(results)`, `compare_png(results, path)` and `compare_json(results)` put several side by side, with
their paired tests on the same episodes (`paired_comparisons`, `paired_table`, shared with the leaderboard). The
benchmark's leaderboard has its own module (`envs.evaluation.leaderboard`).
"""

from __future__ import annotations

from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np

from envs.atomic import write_atomic
from envs.config import REPLAY_SCENARIO
from envs.evaluation.records import EpisodeRecord
from envs.evaluation.stats import paired_comparison
from envs.scoring.social_metrics import ZONES

N_DRAWN = 3  # episodes drawn in the trajectories panel of the PNG
RATE_KEYS = ("success_rate", "collision_rate", "timeout_rate", "group_intrusion_rate")
RATE_LABELS = {"success_rate": "success", "collision_rate": "collision", "timeout_rate": "timeout",
               "group_intrusion_rate": "group intrusion"}


def fmt(value: Any, digits: int = 2) -> str:
    if value is None:
        return "–"
    if isinstance(value, float | np.floating):
        return f"{value:.{digits}f}"
    return str(value)


def intrusion_text(result: dict[str, Any], key: str) -> str:
    """A group intrusion rate (no interval); "n/a" where no episode had group labels (a recording without a group
    file: intrusion was not measured, which is not a rate of 0)."""
    return "n/a" if result.get("labelled") == 0 else fmt(result[key])


def rate_text(result: dict[str, Any], key: str) -> str:
    """A rate with its 95% interval (group intrusion: "n/a" without labels, see `intrusion_text`)."""
    if key.startswith("group_intrusion") and result.get("labelled") == 0:
        return intrusion_text(result, key)
    ci = result.get(f"{key}_ci95")
    text = fmt(result[key])
    return f"{text} [{ci[0]:.2f}, {ci[1]:.2f}]" if ci else text


def na(value: Any, digits: int = 2) -> str:
    """A value that may not have been measured (records written before the metric existed): "n/a" for None."""
    return "n/a" if value is None else fmt(value, digits)


def measured_rate_text(result: dict[str, Any], key: str, measured_key: str) -> str:
    """A rate with its 95% interval, or "n/a" where no episode measured it (`measured_key` 0 or missing)."""
    return rate_text(result, key) if result.get(measured_key) and result.get(key) is not None else "n/a"


def zones_text(result: dict[str, Any]) -> str:
    """Mean seconds in the intimate / personal / social zones, then their mean fractions of episode time."""
    secs = "/".join(na(result.get(f"time_{z}_s")) for z in ZONES)
    return "n/a" if result.get("time_intimate_s") is None else \
        f"{secs} ({'/'.join(na(result.get(f'{z}_fraction'), 3) for z in ZONES)})"


def ttc_text(result: dict[str, Any]) -> str:
    """Mean minimum time to collision over episodes on a collision course, and the share of such episodes."""
    if result.get("collision_course_rate") is None:
        return "n/a"
    return f"{na(result.get('min_ttc_s'))} ({fmt(result['collision_course_rate'])} on a course)"


def itr_text(result: dict[str, Any]) -> str:
    """CrowdNav++'s intrusion ratio in percent, as its rl/evaluation.py prints it ("n/a": not measured)."""
    return "n/a" if result.get("itr") is None else f"{100.0 * result['itr']:.2f}%"


def sd_text(result: dict[str, Any]) -> str:
    """CrowdNav++'s social distance during intrusions, m ("n/a": not measured; "–": measured, no intrusion)."""
    return "n/a" if result.get("itr") is None else fmt(result.get("itr_sd_m"))


SOCIAL_ROWS = (
    ("time in intimate/personal/social zone, mean s (fraction)", zones_text),
    ("group collision rate [95% CI]",
     lambda r: measured_rate_text(r, "group_collision_rate", "group_collision_measured")),
    ("path irregularity (rad)", lambda r: na(r.get("path_irregularity_rad"), 3)),
    ("jerk (m/s^3)", lambda r: na(r.get("jerk_mps3"))),
    ("min time to collision, mean s (share on a collision course)", ttc_text),
    ("SPL", lambda r: na(r.get("spl"), 3)),
    ("ITR, intrusion ratio (CrowdNav++)", itr_text),
    ("SD, social distance in intrusions (m)", sd_text),
)


def describe_config(result: dict[str, Any]) -> str:
    """One line: scenario, crowd, visibility, time limit, dt, seeds."""
    c = result.get("config") or {}
    crowd = (f"replay of {c.get('replay_file')}" if c.get("scenario") == REPLAY_SCENARIO else
             f"{c.get('n_pedestrians')} pedestrians, {'visible' if c.get('robot_visible') else 'invisible'} robot")
    seeds = f"seeds {result['seed']}..{result['seed'] + result['episodes'] - 1}" if result.get("seed") is not None \
        else f"{result['episodes']} episodes"
    view = "" if "fov_deg" not in c else \
        f", field of view {c['fov_deg']:g} deg{', occlusion' if c.get('occlusion') else ''}"  # limited only
    return (f"{c.get('scenario')}: {crowd} ({c.get('robot_model')}){view}, time limit {fmt(c.get('time_limit_s'), 0)} "
            f"s, dt {c.get('dt_s')} s, {seeds}")


def predictor_text(result: dict[str, Any]) -> str:
    """The predictor a result's policy ran ("none" for a policy without one; "?" for results written before
    results named it)."""
    if "predictor" not in result:
        return "?"
    return result["predictor"] or "none"


def markdown_table(result: dict[str, Any]) -> str:
    """A markdown table of one policy's summary."""
    rows = [
        ("predictor", predictor_text(result)),
        ("episodes", str(result["episodes"])),
        ("success rate [95% CI]", rate_text(result, "success_rate")),
        ("collision rate [95% CI]", rate_text(result, "collision_rate")),
        ("avoidable collision rate [95% CI]", rate_text(result, "avoidable_collision_rate")),
        ("collisions, at fault: robot / pedestrian / spawn",
         f"{result['collisions_at_fault_robot']} / {result['collisions_at_fault_pedestrian']} / "
         f"{result['collisions_at_fault_spawn']}"),
        ("time to first collision, mean (s)", fmt(result["time_to_first_collision_s"])),
        ("errors", str(result["errors"])),
        ("timeout rate", fmt(result["timeout_rate"])),
        ("group intrusion rate (all episodes)", intrusion_text(result, "group_intrusion_rate")),
        ("group intrusion rate (successes)", intrusion_text(result, "group_intrusion_rate_success")),
        ("time to goal, mean / median (s)",
         f"{fmt(result['time_to_goal_s'])} / {fmt(result['time_to_goal_median_s'])}"),
        ("path length (m)", fmt(result["path_length_m"])),
        ("min distance, mean / overall (m)",
         f"{fmt(result['min_distance_m'])} / {fmt(result['min_distance_overall_m'])}"),
        ("discomfort frequency", fmt(result["discomfort_frequency"], 3)),
        ("solve time p50 / p95 (ms)",
         f"{fmt(result['solve_time_p50_ms'], 1)} / {fmt(result['solve_time_p95_ms'], 1)}"),
        ("fallback rate", fmt(result["fallback_rate"], 3)),
        *((name, f(result)) for name, f in SOCIAL_ROWS),
    ]
    lines = [f"**{result['policy']}** — {describe_config(result)}", "", "| metric | value |", "|---|---|"]
    lines += [f"| {name} | {value} |" for name, value in rows]
    return "\n".join(lines)


COMPARE_COLUMNS = (
    ("success [95% CI]", lambda r: rate_text(r, "success_rate")),
    ("collision [95% CI]", lambda r: rate_text(r, "collision_rate")),
    ("avoidable coll.", lambda r: fmt(r["avoidable_collision_rate"])),
    ("errors", lambda r: str(r["errors"])),
    ("timeout", lambda r: fmt(r["timeout_rate"])),
    ("intrusion", lambda r: intrusion_text(r, "group_intrusion_rate")),
    ("intrusion (succ.)", lambda r: intrusion_text(r, "group_intrusion_rate_success")),
    ("time to goal (s)", lambda r: fmt(r["time_to_goal_s"])),
    ("path (m)", lambda r: fmt(r["path_length_m"])),
    ("min dist (m)", lambda r: fmt(r["min_distance_m"])),
    ("discomfort", lambda r: fmt(r["discomfort_frequency"], 3)),
    ("solve p50/p95 (ms)", lambda r: f"{fmt(r['solve_time_p50_ms'], 1)}/{fmt(r['solve_time_p95_ms'], 1)}"),
    ("fallback", lambda r: fmt(r["fallback_rate"], 3)),
    ("zones s (frac.)", zones_text),
    ("group coll.", lambda r: measured_rate_text(r, "group_collision_rate", "group_collision_measured")),
    ("path irr. (rad)", lambda r: na(r.get("path_irregularity_rad"), 3)),
    ("jerk (m/s^3)", lambda r: na(r.get("jerk_mps3"))),
    ("min TTC (s)", ttc_text),
    ("SPL", lambda r: na(r.get("spl"), 3)),
    ("ITR", itr_text),
    ("SD (m)", sd_text),
)


def paired_comparisons(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every two of the evaluated policies `results` (each with its `episode_list`) on the episodes both completed,
    matched by seed, so the same crowd and route (`stats.paired_comparison`: exact McNemar, paired bootstrap)."""
    recs = [[EpisodeRecord.from_json(e) for e in r.get("episode_list", [])] for r in results]
    return [paired_comparison(a, b) for a, b in combinations(recs, 2) if a and b]


def compare(results: list[dict[str, Any]]) -> str:
    """One markdown table, a row per policy, the key metrics as columns (config line from the first); with two
    or more policies, then their paired comparisons on the same episodes (`paired_comparisons`, `paired_table`)."""
    if not results:
        raise ValueError("nothing to compare")
    header = "| policy | predictor | episodes | " + " | ".join(name for name, _ in COMPARE_COLUMNS) + " |"
    lines = [describe_config(results[0]), "", header, "|" + "---|" * (len(COMPARE_COLUMNS) + 3)]
    for r in results:
        lines.append(f"| {r['policy']} | {predictor_text(r)} | {r['episodes']} | "
                     + " | ".join(f(r) for _, f in COMPARE_COLUMNS) + " |")
    paired = paired_comparisons(results)
    if paired:
        lines += ["", *paired_table({str(results[0].get("scenario", "all")): paired})]
    return "\n".join(lines)


def _diff(d: dict[str, Any] | None) -> str:
    """A paired mean difference with its 95% interval, `*` when the interval excludes 0; "n.t." (not tested, no
    interval) below `stats.MIN_BOOTSTRAP_PAIRS` pairs."""
    if not d:
        return "–"
    if not d["tested"]:
        return f"{d['mean_diff']:+.2f} ({d['pairs']} pairs) n.t."
    return f"{d['mean_diff']:+.2f} [{d['ci95'][0]:+.2f}, {d['ci95'][1]:+.2f}]{' *' if d['significant'] else ''}"


def _untested(c: dict[str, Any]) -> bool:
    """Whether any test of the comparison `c` was not made (too few pairs)."""
    return any(isinstance(e, dict) and e.get("tested") is False for e in c.values())


def paired_table(paired: dict[str, list[dict[str, Any]]]) -> list[str]:
    """Markdown rows of paired comparisons (`stats.paired_comparison`) per pool: counts, discordant pairs and exact
    McNemar p of collisions, avoidable collisions, successes and group intrusions; paired differences of path
    length and minimum distance; what "*" and "n.t." mean."""
    lines = ["### Paired comparisons (same episodes; exact McNemar, two-sided, alpha 0.05)", "",
             "| pool | A vs B | pairs | collisions A/B (A only, B only) | p | avoidable A/B | p | "
             "successes A/B | p | group intrusions A/B | p | path A-B (m) [95% CI] | min distance A-B (m) [95% CI] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for pool, comps in paired.items():
        for c in comps:
            def cnt(k: str, c: dict[str, Any] = c) -> str:
                e = c[k]
                p = f"{e['p_value']:.3g}{' *' if e['significant'] else ''}" if e["tested"] else "n.t."
                return f"{e['a']}/{e['b']} ({e['a_only']}, {e['b_only']}) | {p}"
            lines.append(f"| {pool} | {c['policy_a']} vs {c['policy_b']} | {c['pairs']} | {cnt('collision')} | "
                         f"{cnt('avoidable_collision')} | {cnt('success')} | {cnt('group_intrusion')} | "
                         f"{_diff(c.get('path_length_m'))} | {_diff(c.get('min_distance_m'))} |")
    lines.append("")
    lines.append("`*`: significant at alpha = 0.05 (no correction for the number of comparisons).")
    untested = [c for comps in paired.values() for c in comps if _untested(c)]
    if untested:
        c = untested[0]
        lines.append(f"n.t.: not tested, too few pairs: a McNemar test needs at least {c['min_discordant_pairs']} "
                     "discordant pairs (with fewer no p below 0.05 is possible), a paired bootstrap at least "
                     f"{c['min_bootstrap_pairs']} pairs (with fewer its interval is too narrow: at 2 pairs it "
                     "excludes 0 for about half of all differences that are really 0).")
    return [*lines, ""]


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path) -> None:
    """A matplotlib figure as PNG, written atomically."""
    write_atomic(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))


def rate_errors(results: list[dict[str, Any]], key: str) -> np.ndarray:
    """(2, P) asymmetric error bars of the rate `key` from its Wilson interval (zeros where there is none)."""
    err = np.zeros((2, len(results)))
    for j, r in enumerate(results):
        ci = r.get(f"{key}_ci95")
        if ci:
            err[:, j] = [max(0.0, r[key] - ci[0]), max(0.0, ci[1] - r[key])]
    return err


def _rates_panel(ax: Any, results: list[dict[str, Any]]) -> None:
    """Grouped bars: the rates (groups) x policies (bars), with the 95% Wilson intervals."""
    width = 0.8 / len(results)
    x = np.arange(len(RATE_KEYS))
    for j, r in enumerate(results):
        rates = [r.get(k) for k in RATE_KEYS]  # None: not measured (group intrusion without labels)
        vals = [0.0 if v is None else v for v in rates]
        err = np.concatenate([rate_errors([r], k) for k in RATE_KEYS], axis=1)
        bars = ax.bar(x + (j - (len(results) - 1) / 2) * width, vals, width, yerr=err, capsize=3,
                      label=r["policy"])
        for b, v, top in zip(bars, rates, err[1], strict=True):
            ax.text(b.get_x() + b.get_width() / 2, (v or 0.0) + top + 0.02, "n/a" if v is None else f"{v:.2f}",
                    ha="center", va="bottom", fontsize=7)
    ax.set_xticks(x, [RATE_LABELS[k] for k in RATE_KEYS])
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("fraction of episodes (95% Wilson CI)")
    ax.grid(axis="y", alpha=0.3)


def _trajectory_panel(ax: Any, scene: dict[str, Any]) -> None:
    from crowdsim.recording import N_COLOURS, palette

    colours = palette(N_COLOURS) / 255.0
    for wall in scene["walls"]:
        ax.plot(wall[:, 0], wall[:, 1], color="0.25", lw=2)
    if scene["ped_xy"]:
        pos = np.concatenate(scene["ped_xy"])
        gid = np.concatenate(scene["ped_groups"]).astype(int)
        if len(pos):
            ax.scatter(pos[:, 0], pos[:, 1], s=2.0, c=colours[gid % N_COLOURS], alpha=0.3, lw=0)
    xy = scene["robot_xy"]
    ax.plot(xy[:, 0], xy[:, 1], color="k", lw=1.8)
    ax.plot(*xy[0], "o", color="tab:green", ms=7, label="start")
    ax.plot(*scene["goal"], "*", color="tab:red", ms=12, label="goal")
    ax.plot(*xy[-1], "o", mfc="none", mec="k", ms=7)
    x0, y0, x1, y1 = scene["bounds"]
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_title(f"seed {scene['seed']}: {scene['outcome']}", fontsize=9)
    ax.tick_params(labelsize=7)


def plot_result(result: dict[str, Any], scenes: list[dict[str, Any]], path: str | Path) -> None:
    """PNG: the rates with their 95% intervals, and one panel per example episode (walls, robot path from start
    to goal, the pedestrians' positions over the episode faint in their group's colour)."""
    plt = pyplot()
    n = len(scenes)
    fig, axes = plt.subplots(1, 1 + n, figsize=(4.8 + 3.6 * n, 4.2), squeeze=False,
                             gridspec_kw={"width_ratios": [1.3] + [1.0] * n})
    _rates_panel(axes[0, 0], [result])
    axes[0, 0].set_title(f"{result['policy']} ({result['episodes']} episodes)", fontsize=10)
    for ax, scene in zip(axes[0, 1:], scenes, strict=True):
        _trajectory_panel(ax, scene)
    if n:
        axes[0, 1].legend(loc="upper right", fontsize=7)
    fig.suptitle(describe_config(result), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def compare_png(results: list[dict[str, Any]], path: str | Path) -> None:
    """PNG: grouped bars of the rates (success, collision, timeout, group intrusion) per policy, with the 95%
    Wilson intervals."""
    if not results:
        raise ValueError("nothing to compare")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(RATE_KEYS) * max(1, len(results)) / 2), 4.2))
    _rates_panel(ax, results)
    ax.legend(fontsize=8)
    ax.set_title(describe_config(results[0]), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def compare_json(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The combined JSON of several policies: one entry per policy keyed by name, the predictor each ran, and the
    paired comparisons of every two (`paired_comparisons`)."""
    return {"policies": [r["policy"] for r in results],
            "predictors": {r["policy"]: r.get("predictor") for r in results},
            "results": {r["policy"]: r for r in results}, "paired": paired_comparisons(results)}
