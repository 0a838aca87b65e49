"""Groups: sizes, shared speeds, spawn formations and placement checks.

Formations are given in a local frame (x forward along the walking direction, y to the left), metres.
"""

from __future__ import annotations

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


def draw_group_size(rng: np.random.Generator, cfg: GroupConfig, limit: int) -> int:
    """One group size from cfg's distribution, at most `limit`."""
    probs = np.asarray(cfg.size_probabilities())
    return min(int(rng.choice(len(probs), p=probs)) + 1, limit)


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
