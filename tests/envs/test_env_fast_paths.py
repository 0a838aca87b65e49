"""The env's and the simulator's fast paths give the same results as the straightforward numpy code."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from crowdsim.groups import dense_rank, gaze_subgroups
from crowdsim.kernels import _gaze_subgroups
from crowdsim.kernels import gaze_subgroups as fast_gaze_subgroups
from crowdsim.state import Slots
from envs.scoring.geometry import (
    WallIndex,
    convex_hull,
    distance_to_hull,
    intruded_groups,
    point_segment_distances,
    swept_distances,
)


def _hull_reference(points: np.ndarray) -> np.ndarray:
    pts = np.unique(np.asarray(points, float), axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def chain(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2 and cross(out[-2], out[-1], p) <= 1e-12:
                out.pop()
            out.append(p)
        return out

    lower, upper = chain(pts), chain(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _segment_distances_reference(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances (S,) from p (2,) to segs (S, 2, 2) with the operations the env's intrusion test has always used
    (closest = a + t ab; |p - closest|): the scalar and compiled fast paths must equal it bit for bit, so that
    episodes stay identical. (The planner's vectorised version rounds |(p - a) - t ab| and may differ by an ulp.)"""
    a, ab = segs[:, 0], segs[:, 1] - segs[:, 0]
    t = np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    return np.linalg.norm(p - (a + np.clip(t, 0.0, 1.0)[:, None] * ab), axis=1)


def _hull_distance_reference(p: np.ndarray, hull: np.ndarray) -> float:
    edges = np.stack([hull, np.roll(hull, -1, axis=0)], axis=1)
    if len(hull) == 2:
        edges = edges[:1]
    if len(hull) >= 3:
        e, rel = edges[:, 1] - edges[:, 0], p - edges[:, 0]
        if np.all(e[:, 0] * rel[:, 1] - e[:, 1] * rel[:, 0] >= 0.0):
            return 0.0
    return float(_segment_distances_reference(p, edges).min())


def test_convex_hull_and_distance_match_reference() -> None:
    rng = np.random.default_rng(0)
    for _ in range(500):
        pts = rng.normal(0.0, 1.0, (int(rng.integers(1, 7)), 2))
        if rng.random() < 0.2:
            pts[-1] = pts[0]  # a duplicate
        hull = convex_hull(pts)
        assert np.array_equal(hull, _hull_reference(pts))
        if len(hull) >= 2:
            p = rng.normal(0.0, 1.5, 2)
            assert distance_to_hull(p, hull) == _hull_distance_reference(p, hull)


def test_intruded_groups_matches_reference() -> None:
    rng = np.random.default_rng(1)
    hits = 0
    for _ in range(300):
        n = int(rng.integers(0, 12))
        pos, radius = rng.uniform(-3.0, 3.0, (n, 2)), rng.uniform(0.2, 0.3, n)
        group = rng.integers(0, 4, n)
        robot = rng.uniform(-3.0, 3.0, 2)
        got = intruded_groups(robot, 0.6, pos, radius, group, 2.5)
        want = []
        for g in sorted(set(group.tolist())):
            sel = group == g
            members = pos[sel]
            if len(members) < 2 or np.hypot(*(members - robot).T).min() > 2.5 + 0.6 + 0.5:
                continue
            diff = members[:, None] - members[None]
            if np.einsum("ijk,ijk->ij", diff, diff).max() > 2.5**2:
                continue
            hull = _hull_reference(members)
            d = float(np.linalg.norm(robot - hull[0])) if len(hull) == 1 else _hull_distance_reference(robot, hull)
            if d < 0.6 + radius[sel].max():
                want.append(int(g))
        assert got == want
        hits += bool(got)
    assert hits > 10


def test_wall_index_and_swept_distances() -> None:
    rng = np.random.default_rng(2)
    walls = rng.uniform(-5.0, 5.0, (12, 2, 2))
    index = WallIndex(walls)
    for _ in range(2000):
        p, r = rng.uniform(-6.0, 6.0, 2), float(rng.uniform(0.05, 1.0))
        assert index.within(p, r) == (float(point_segment_distances(p, walls).min()) < r)
    assert not WallIndex(np.zeros((0, 2, 2))).within(np.zeros(2), 1.0)
    r0, r1 = rng.normal(0, 1, 2), rng.normal(0, 1, 2)
    p0, p1 = rng.normal(0, 2, (50, 2)), rng.normal(0, 2, (50, 2))
    d0, dv = p0 - r0, (p1 - p0) - (r1 - r0)
    denom = np.einsum("ij,ij->i", dv, dv)
    t = np.clip(np.where(denom > 1e-12, -np.einsum("ij,ij->i", d0, dv) / np.maximum(denom, 1e-12), 0.0), 0.0, 1.0)
    assert np.array_equal(swept_distances(r0, r1, p0, p1), np.linalg.norm(d0 + t[:, None] * dv, axis=1))


def test_dense_labels_match_unique() -> None:
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(0, 15))
        ids = rng.integers(0, 40, n)
        assert np.array_equal(dense_rank(ids), np.unique(ids, return_inverse=True)[1])
        slots = Slots.empty(n)
        slots.label[:] = ids
        assert np.array_equal(slots.dense_labels(np.arange(n)), np.unique(ids, return_inverse=True)[1])
        if n:
            dense = np.unique(ids, return_inverse=True)[1]
            sub = gaze_subgroups(rng.normal(0, 1, (n, 2)), rng.normal(0, 1, (n, 2)), dense)
            assert sub.dtype == np.int64 and set(sub.tolist()) == set(range(int(sub.max()) + 1))


def _gaze_reference(pos: np.ndarray, goal: np.ndarray, label: np.ndarray) -> np.ndarray:
    """Front and back rows of groups above three, found by scanning all labels once per large group."""
    sub = label * 2
    for g in np.flatnonzero(np.bincount(label) > 3):
        members = np.flatnonzero(label == g)
        heading = goal[members].mean(axis=0) - pos[members].mean(axis=0)
        order = np.argsort(-(pos[members] @ heading), kind="stable")
        sub[members[order[(len(members) + 1) // 2:]]] += 1
    return np.unique(sub, return_inverse=True)[1]


def _gaze_cases(trials: int) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Random crowds (pos, goal (n, 2) m, dense labels (n,)) of 1-119 people, every third with ties in the
    projection (positions rounded to 0.1 m), where the stable order decides."""
    rng = np.random.default_rng(5)
    for trial in range(trials):
        n = int(rng.integers(1, 120))
        label = np.unique(rng.integers(0, int(rng.integers(1, n + 1)), n), return_inverse=True)[1]
        pos, goal = rng.normal(0, 1, (n, 2)), rng.normal(0, 10, (n, 2))
        yield (np.round(pos, 1) if trial % 3 == 0 else pos), goal, label


def test_gaze_subgroups_matches_the_per_group_scan_bit_for_bit() -> None:
    for pos, goal, label in _gaze_cases(300):
        assert np.array_equal(gaze_subgroups(pos, goal, label), _gaze_reference(pos, goal, label))


def test_gaze_kernel_matches_the_numpy_function() -> None:
    left = 0
    for pos, goal, label in _gaze_cases(1500):
        got, compiled = _gaze_subgroups(pos, goal, label, 3)
        if not compiled:  # a group of more than 15 splits: numpy's mean sums pairwise, the numpy path does it
            left += 1
            assert np.bincount(label).max() > 15
        else:
            assert got.dtype == np.int64 and np.array_equal(got, gaze_subgroups(pos, goal, label))
        assert np.array_equal(fast_gaze_subgroups(pos, goal, label), gaze_subgroups(pos, goal, label))
    assert 0 < left < 500


def test_group_means_add_rows_in_order_as_numpy_mean_does() -> None:
    """`crowdsim.groups._mean_rows` (one vectorised pass per member rank) equals `.mean(axis=0)` of each group's
    rows bit for bit, for groups of 1 to 20 rows (above 15 it calls `mean` itself)."""
    from crowdsim.groups import _mean_rows

    rng = np.random.default_rng(11)
    count = rng.integers(1, 21, 400)
    first = np.concatenate(([0], np.cumsum(count)[:-1]))
    x = rng.normal(0, 1, (int(count.sum()), 2)) * 10 + rng.normal(0, 100, 2)
    by_group = rng.permutation(len(x))
    want = np.array([x[by_group[f:f + c]].mean(axis=0) for f, c in zip(first, count, strict=True)])
    assert np.array_equal(_mean_rows(x, by_group, first, count), want)
