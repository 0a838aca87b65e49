"""Prediction processing: K-of-20 choice, time interpolation, groups, padding, validation."""

from __future__ import annotations

import numpy as np
import pytest
from planner_helpers import PRED, STEP_S

from planner import (
    MPCConfig,
    PedPrediction,
    constant_velocity_prediction,
    frozen_prediction,
    polygon_to_segments,
    select_modes,
)
from planner.scene import (
    build_scene,
    farthest_point_samples,
    group_capsules,
    resample_in_time,
    validate_obstacles,
)


def test_farthest_point_picks_medoid_then_extremes():
    offsets = np.array([0.0, 0.1, -0.1, 0.05, 3.0, -2.0])  # lateral offsets of 6 samples
    traj = np.zeros((6, 4, 1, 2))
    traj[..., 1] = offsets[:, None, None]
    picks = farthest_point_samples(traj, 3)
    assert picks[0] in (0, 3) and set(picks[1:]) == {4, 5}
    assert list(farthest_point_samples(traj[:2], 3)) == [0, 1, 0]


def test_select_modes_keeps_group_members_jointly_sampled():
    rng = np.random.default_rng(0)
    positions = rng.normal(size=(20, 12, 3, 2))
    group_ids = np.array([0, 0, 1])
    out = select_modes(positions, group_ids, np.ones(3, bool), 3)
    assert out.shape == (3, 12, 3, 2)
    for k in range(3):  # both members of group 0 come from the same input sample
        match0 = [s for s in range(20) if np.array_equal(out[k, :, 0], positions[s, :, 0])]
        match1 = [s for s in range(20) if np.array_equal(out[k, :, 1], positions[s, :, 1])]
        assert match0 == match1 and len(match0) == 1


def test_resample_in_time_interpolates_linearly_and_holds_the_end():
    current = np.array([[0.0, 0.0]])
    positions = (0.4 * np.arange(1, 13))[None, :, None, None] * np.array([1.0, 0.5])  # 1 m/s, 0.5 m/s
    out = resample_in_time(positions, current, 0.4, 0.25, 24)
    times = np.minimum(0.25 * np.arange(1, 25), 4.8)
    assert np.allclose(out[0, :, 0], times[:, None] * [1.0, 0.5])
    same = resample_in_time(positions, current, 0.4, 0.4, 10)
    assert np.allclose(same, positions[:, :10])


def test_capsule_contains_member_discs():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(50, 3, 2))
    radii = np.array([0.2, 0.3, 0.25])
    a, b, rad = group_capsules(pts, radii)
    for i in range(50):
        ab = b[i] - a[i]
        for j in range(3):
            t = np.clip(np.dot(pts[i, j] - a[i], ab) / max(np.dot(ab, ab), 1e-12), 0, 1)
            assert np.linalg.norm(a[i] + t * ab - pts[i, j]) + radii[j] <= rad[i] + 1e-9


def test_build_scene_pads_and_picks_nearest():
    cfg = MPCConfig(max_peds=2, max_groups=1, max_walls=2, n_modes=1)
    hist = np.array([[[1.0, 0.0], [5.0, 0.0], [2.0, 0.0], [9.0, 9.0]]] * 2)
    pred = constant_velocity_prediction(hist, group_ids=np.array([0, 1, 1, 2]),
                                        mask=np.array([True, True, True, False]), **PRED)
    walls = polygon_to_segments(np.array([[0.0, 3.0], [10.0, 3.0], [10.0, 4.0]]), closed=False)
    scene = build_scene(np.zeros(2), pred, walls, cfg)
    assert list(scene.ped_index) == [0, 2] and scene.ped_mask.tolist() == [1.0, 1.0]
    assert scene.grp_mask.tolist() == [1.0]  # group 1 (two members), the only group of >= 2
    assert np.allclose(scene.grp_clear[0, 0, 0], 0.3 + cfg.robot.radius_m + cfg.safety_margin_m)
    assert scene.wall_mask.tolist() == [1.0, 1.0]
    empty = build_scene(np.zeros(2), pred, None, cfg)
    assert empty.wall_mask.tolist() == [0.0, 0.0]


@pytest.mark.parametrize("bad", ["shape", "radii", "mask", "inf"])
def test_invalid_predictions_raise_clear_errors(bad):
    positions, radii, gids, mask = np.zeros((2, 12, 3, 2)), np.full(3, 0.3), np.arange(3), np.ones(3, bool)
    if bad == "shape":
        positions = np.zeros((12, 3, 2))
    elif bad == "radii":
        radii = np.full(2, 0.3)
    elif bad == "mask":
        mask = np.ones(3)
    else:
        positions[1, 5, 2, 0] = np.inf
    with pytest.raises(ValueError, match="invalid PedPrediction"):
        PedPrediction(positions, radii, gids, mask, step_s=STEP_S)


def test_obstacles_accept_segments_or_polygons():
    square = np.array([[3.0, -1.0], [5.0, -1.0], [5.0, 1.0], [3.0, 1.0]])
    segs = validate_obstacles([square])
    assert segs.shape == (4, 4) and np.allclose(segs[0], [3.0, -1.0, 5.0, -1.0])
    assert validate_obstacles(None) is None and validate_obstacles([]).shape == (0, 4)
    with pytest.raises(ValueError, match="segments"):
        validate_obstacles(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="NaN"):
        validate_obstacles(np.array([[0.0, 0.0, np.nan, 1.0]]))


def test_group_spread_wider_than_max_span_is_not_a_region():
    cfg = MPCConfig(max_groups=1, n_modes=1, max_group_span_m=3.0)
    close = frozen_prediction(np.array([[4.0, 0.5], [4.0, -0.5]]), group_ids=np.array([0, 0]), **PRED)
    apart = frozen_prediction(np.array([[4.0, 2.5], [4.0, -2.5]]), group_ids=np.array([0, 0]), **PRED)
    assert np.all(build_scene(np.zeros(2), close, None, cfg).grp_clear > 0)
    assert np.all(build_scene(np.zeros(2), apart, None, cfg).grp_clear < -100)


def test_sample_distances_and_nearest_groups_match_their_plain_definitions():
    """The scene's two per-plan helpers, written for speed (each sample pair once; groups ranked without a loop),
    give exactly the floats and groups of their plain definitions: the MPC's plans did not change."""
    from planner.scene import _nearest_groups, _ped_sample_distances

    rng = np.random.default_rng(3)
    for _ in range(30):
        s, n = int(rng.integers(1, 21)), int(rng.integers(1, 15))
        pos = rng.normal(scale=3.0, size=(s, 12, n, 2))
        diff = pos[:, None] - pos[None, :]
        assert np.array_equal(_ped_sample_distances(pos), np.sqrt((diff * diff).sum(-1)).mean(axis=2))
        ids = rng.integers(0, max(1, n // 2), n)
        mask = rng.random(n) < 0.8
        dist = np.round(rng.uniform(0, 5, n), 1)  # rounded: ties between groups, broken by id
        plain = sorted(((float(dist[(ids == g) & mask].min()), int(g), np.flatnonzero((ids == g) & mask))
                        for g in np.unique(ids[mask]) if ((ids == g) & mask).sum() >= 2), key=lambda t: t[:2])
        fast = _nearest_groups(ids, mask, dist, 3)
        assert [m.tolist() for m in fast] == [m.tolist() for _, _, m in plain[:3]]
