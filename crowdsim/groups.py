"""Groups: sizes, shared speeds, spawn formations and placement checks.

Formations are given in a local frame (x forward along the walking direction, y to the left), metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from crowdsim.config import GroupConfig, SocialForceParams
from crowdsim.forces import closest_points_on_segments


def draw_group_sizes(rng: np.random.Generator, n_total: int, cfg: GroupConfig) -> list[int]:
    """Group sizes summing to n_total, each drawn from cfg's size distribution (the last is truncated)."""
    probs = np.asarray(cfg.size_probabilities())
    sizes: list[int] = []
    remaining = n_total
    while remaining > 0:
        size = min(int(rng.choice(len(probs), p=probs)) + 1, remaining)
        sizes.append(size)
        remaining -= size
    return sizes


def step_probability(rate_hz: float, dt_s: float) -> float:
    """Probability that a Poisson process of rate_hz (1/s) fires at least once in dt_s seconds."""
    return float(1.0 - np.exp(-rate_hz * dt_s))


def draw_inflow_size(rng: np.random.Generator, cfg: GroupConfig, mean_stay_s: np.ndarray, limit: int) -> int:
    """The size of the next group to enter a continuous scene, at most `limit`.

    By Little's law the people in a scene in groups of size k number (arrival rate of such groups) x k x
    (their mean stay), and larger groups stay longer (they walk slower). Arrivals drawn from cfg's distribution
    p alone would therefore over-represent large groups in the scene; drawing size k with probability
    proportional to p_k / mean_stay_s[k - 1] keeps the people in the scene at the composition p implies.
    mean_stay_s: (max_size,) seconds, the mean stay of groups of each size so far (`GroupBook.mean_stay_s`).
    """
    probs = np.asarray(cfg.size_probabilities())[:limit] / np.asarray(mean_stay_s, dtype=float)[:limit]
    return int(rng.choice(len(probs), p=probs / probs.sum())) + 1


def group_speed(rng: np.random.Generator, size: int, social: SocialForceParams, cfg: GroupConfig) -> float:
    """Shared desired speed (m/s) of a group of `size`: N(mean - drop (size - 1), std), clipped."""
    mean = social.desired_speed_mean_mps - cfg.speed_drop_per_member_mps * (size - 1)
    speed = rng.normal(mean, social.desired_speed_std_mps)
    return float(np.clip(speed, social.desired_speed_min_mps, social.desired_speed_max_mps))


def formation_offsets(size: int, spacing_m: float) -> np.ndarray:
    """(size, 2) local offsets: up to three abreast in one row; larger groups walk in two rows
    (Moussaïd et al. 2010 observed that groups above three split into sub-groups)."""
    front = size if size <= 3 else (size + 1) // 2
    rows = [front, size - front]
    out = []
    for r, count in enumerate(rows):
        for k in range(count):
            out.append([-0.8 * r, (k - (count - 1) / 2.0) * spacing_m])
    return np.array(out, dtype=float).reshape(size, 2)


def rotate_to(offsets: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Rotate local offsets (n, 2) so that local +x points along direction (2,)."""
    norm = float(np.hypot(*direction))
    c, s = (direction / norm) if norm > 1e-9 else (1.0, 0.0)
    rot = np.array([[c, -s], [s, c]])
    return offsets @ rot.T


def gaze_subgroups(pos: np.ndarray, goal: np.ndarray, label: np.ndarray, max_abreast: int = 3) -> np.ndarray:
    """(n,) dense sub-group labels: groups of up to max_abreast are one sub-group; a larger group splits into
    a front and a back row along its walking direction (towards the mean goal), the front row holding
    ceil(size / 2) members, as groups above three split into sub-groups (Moussaïd et al. 2010).
    pos, goal (n, 2) m; label (n,) dense group labels."""
    sub = label * 2
    counts = np.bincount(label)
    big = np.flatnonzero(counts > max_abreast)
    if len(big) == 0:
        return dense_rank(sub)
    # members of each group in increasing index order (what np.flatnonzero(label == g) gives), found with one
    # stable sort instead of one scan of all n labels per large group
    by_group = np.argsort(label, kind="stable")
    starts = np.concatenate(([0], np.cumsum(counts)))
    headings = _mean_rows(goal, by_group, starts[big], counts[big]) - _mean_rows(pos, by_group, starts[big],
                                                                                counts[big])
    for g, heading in zip(big, headings, strict=True):
        members = by_group[starts[g]:starts[g + 1]]
        order = np.argsort(-(pos[members] @ heading), kind="stable")
        sub[members[order[(len(members) + 1) // 2:]]] += 1
    return dense_rank(sub)


def _mean_rows(x: np.ndarray, by_group: np.ndarray, first: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(G, 2) mean of the rows x[by_group[first[g]:first[g] + count[g]]] of each group g: the rows added one after
    the other in that order and divided by the count, which is what ``x[rows].mean(axis=0)`` computes for up to
    15 rows (a test checks this); larger groups use ``mean`` itself."""
    sums = x[by_group[first]].copy()
    for k in range(1, int(count.max())):
        more = np.flatnonzero(count > k)
        sums[more] += x[by_group[first[more] + k]]
    out = sums / count[:, None]
    for g in np.flatnonzero(count > 15):
        out[g] = x[by_group[first[g]:first[g] + count[g]]].mean(axis=0)
    return out


def dense_rank(values: np.ndarray) -> np.ndarray:
    """(n,) int64 rank of each of values (n,) (non-negative ints) among their distinct values:
    ``np.unique(values, return_inverse=True)[1]`` without the sort."""
    if len(values) == 0:
        return np.zeros(0, np.int64)
    present = np.zeros(int(values.max()) + 1, np.int64)
    present[values] = 1
    return (np.cumsum(present) - 1)[values]


def formation_goals(positions: np.ndarray, destination: np.ndarray, spacing_m: float) -> np.ndarray:
    """(n, 2) goals for a group at positions (n, 2) heading to destination (2,): the destination plus each
    member's lateral offset of the abreast formation, assigned so that members keep the side of the walking
    line they already walk on (both orderings matched across the line)."""
    centre = positions.mean(axis=0)
    direction = destination - centre
    local = formation_offsets(len(positions), spacing_m)
    lateral = rotate_to(local * np.array([0.0, 1.0]), direction)
    perp = np.array([-direction[1], direction[0]])
    goals = np.empty_like(positions)
    goals[np.argsort((positions - centre) @ perp, kind="stable")] = (
        destination + lateral[np.argsort(lateral @ perp, kind="stable")])
    return goals


@dataclass
class GroupBook:
    """The simulator's record of its groups: the next unused label (labels are never reused), the size of
    the group drawn for inflow that waits until the scene has room for all of it (0: none drawn), and how long
    groups of each size stayed in the scene (entry time and size of each group present; summed stays, s), and
    the stops of the groups that are stopping or standing (`crowdsim.behaviours`).

    Events and behaviours take labels from here; only the simulator owns a book.
    """

    max_size: int
    next_label: int = 0
    pending_size: int = 0
    entered: dict[int, tuple[float, int]] = field(default_factory=dict)
    stops: dict[int, Any] = field(default_factory=dict)  # label -> behaviours.Stop of a stopping group
    last_spawned: int = -1  # label of the group that entered last
    following: dict[int, tuple[int, float]] = field(default_factory=dict)  # stranger -> (group, gap at entry m)
    stay_sum_s: np.ndarray = field(init=False)
    stay_count: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.stay_sum_s = np.zeros(self.max_size)
        self.stay_count = np.zeros(self.max_size)

    def new_label(self) -> int:
        self.next_label += 1
        return self.next_label - 1

    def enter(self, label: int, size: int, time_s: float) -> None:
        self.entered[label] = (time_s, size)

    def left(self, label: int, time_s: float) -> None:
        """The last member of group `label` left the scene: record its stay."""
        since, size = self.entered.pop(label, (None, 0))
        if since is not None:
            self.stay_sum_s[size - 1] += time_s - since
            self.stay_count[size - 1] += 1

    def mean_stay_s(self) -> np.ndarray:
        """(max_size,) mean stay of groups of each size, s: each size's observed mean, shrunk towards the
        mean over all sizes with the weight of 3 groups (all ones before any group has left)."""
        if self.stay_count.sum() == 0:
            return np.ones(self.max_size)
        overall = self.stay_sum_s.sum() / self.stay_count.sum()
        return (self.stay_sum_s + 3.0 * overall) / (self.stay_count + 3.0)


def placement_ok(candidates: np.ndarray, cand_radius: np.ndarray, others: np.ndarray,
                 other_radius: np.ndarray, walls: np.ndarray, gap_m: float = 0.05) -> bool:
    """Whether discs (n, 2)/(n,) clear each other, existing discs (m, 2)/(m,) and wall segments (S, 2, 2)."""
    allpos = np.concatenate([others, candidates])
    allrad = np.concatenate([other_radius, cand_radius])
    d = np.linalg.norm(candidates[:, None, :] - allpos[None], axis=2)
    need = cand_radius[:, None] + allrad[None] + gap_m
    own = np.arange(len(candidates)) + len(others)
    d[np.arange(len(candidates)), own] = np.inf
    if np.any(d < need):
        return False
    if len(walls):
        dw = np.linalg.norm(candidates[:, None, :] - closest_points_on_segments(candidates, walls), axis=2)
        if np.any(dw < cand_radius[:, None] + gap_m):
            return False
    return True


def hex_lattice(rect: tuple[float, float, float, float], density_per_m2: float) -> np.ndarray:
    """(M, 2) points of a hexagonal lattice with the given density filling rect, ordered row by row."""
    spacing = np.sqrt(2.0 / (np.sqrt(3.0) * density_per_m2))
    dy = spacing * np.sqrt(3.0) / 2.0
    pts = []
    y, row = rect[1], 0
    while y <= rect[3] + 1e-9:
        x = rect[0] + (spacing / 2.0 if row % 2 else 0.0)
        while x <= rect[2] + 1e-9:
            pts.append((x, y))
            x += spacing
        y += dy
        row += 1
    return np.array(pts, dtype=float).reshape(-1, 2)
