"""`envs.drawing.render`: what the numpy renderer draws, and where."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from crowdsim.recording import palette
from envs.drawing.frame import SceneFrame
from envs.drawing.render import (
    BACKGROUND,
    GOAL,
    HEADING,
    OPTION,
    PLAN,
    PREDICTION_FADE,
    ROBOT,
    WALL,
    group_links,
    make_viewport,
    pixel_to_world,
    render_rgb,
    world_to_pixel,
)

PALETTE = palette()


def _frame(**overrides) -> SceneFrame:
    """A 10 m x 10 m scene: a pair (group 0), a single (group 1), a triple (group 2); robot at (2, 2)."""
    pos = np.array([[3.0, 7.0], [4.0, 7.0], [8.0, 8.0], [7.0, 3.0], [8.0, 3.0], [7.5, 4.0]])
    base = dict(
        step=0, time_s=0.0, robot_state=np.array([2.0, 2.0, 0.0, 0.5, 0.0]), robot_radius_m=0.3,
        goal=np.array([9.0, 1.0]), ped_pos=pos, ped_vel=np.zeros_like(pos), ped_radius=np.full(len(pos), 0.3),
        group_id=np.array([0, 0, 1, 2, 2, 2]), ped_id=np.arange(10, 16), walls=np.zeros((0, 2, 2)),
        bounds=(0.0, 0.0, 10.0, 10.0),
    )
    base.update(overrides)
    return SceneFrame(**base)


def _pixel(xy, frame: SceneFrame, size: int = 200) -> tuple[int, int]:
    """(row, column) index of the pixel that contains world point xy."""
    c, r = np.floor(world_to_pixel(np.asarray(xy, float), make_viewport(frame.bounds, size))).astype(int)
    return int(r), int(c)


def _pixel_centres(frame: SceneFrame, size: int) -> np.ndarray:
    """(size, size, 2) world positions of every pixel centre."""
    rows, cols = np.mgrid[0:size, 0:size] + 0.5
    return pixel_to_world(np.stack([cols, rows], axis=-1), make_viewport(frame.bounds, size))


def test_image_shape_and_dtype():
    frame = _frame()
    assert render_rgb(frame).shape == (480, 480, 3)
    img = render_rgb(frame, size_px=200)
    assert img.shape == (200, 200, 3) and img.dtype == np.uint8
    assert render_rgb(frame, size_px=120, view=(0.0, 0.0, 20.0, 5.0)).shape == (120, 120, 3)


def test_discs_have_their_group_colour_and_everything_else_is_background():
    frame = _frame(group_id=np.arange(6))  # everyone alone: no group links
    size = 200
    img = render_rgb(frame, size_px=size)
    px = 1.0 / make_viewport(frame.bounds, size).scale  # one pixel, m
    centres = _pixel_centres(frame, size)
    bodies = np.vstack([frame.ped_pos, frame.robot_pos, frame.goal])
    goal_reach = np.sqrt(2.0) * (max(0.25, 4 * px) + 2 * px)  # the goal's X: diagonal arms of max(0.25 m, 4 px)
    radii = np.append(frame.ped_radius, [frame.robot_radius_m, goal_reach])
    dist = np.linalg.norm(centres[:, :, None, :] - bodies, axis=-1) - radii  # (H, W, N + 1) surface distance
    outside = (dist > 1.5 * px).all(axis=-1)
    assert (img[outside] == BACKGROUND).all()
    for n, gid in enumerate(frame.group_id):
        inside = dist[:, :, n] < -1.5 * px
        assert inside.sum() > 20
        assert (img[inside] == PALETTE[gid]).all()
    assert tuple(img[_pixel(frame.goal, frame)]) == tuple(GOAL)


def test_group_members_share_a_colour_and_groups_differ():
    frame = _frame()
    img = render_rgb(frame, size_px=200)
    colours = [tuple(img[_pixel(p, frame)]) for p in frame.ped_pos]
    assert colours[0] == colours[1] == tuple(PALETTE[0])
    assert colours[3] == colours[4] == colours[5] == tuple(PALETTE[2])
    assert colours[2] == tuple(PALETTE[1])  # a pedestrian alone keeps its own palette colour
    assert len({colours[0], colours[2], colours[3]}) == 3


def test_groups_are_linked():
    frame = _frame()
    img = render_rgb(frame, size_px=200)
    assert tuple(img[_pixel([3.5, 7.0], frame)]) == tuple(PALETTE[0])  # midway between the pair
    segs, gid = group_links(frame.ped_pos, frame.group_id)
    assert segs.shape == (4, 2, 2)
    assert sorted(gid.tolist()) == [0, 2, 2, 2]  # a pair: one segment, a triple: a closed outline, single: none
    alone = _frame(group_id=np.arange(6))
    assert tuple(render_rgb(alone, size_px=200)[_pixel([3.5, 7.0], alone)]) == tuple(BACKGROUND)


def test_world_to_pixel_round_trip_and_robot_position():
    vp = make_viewport((-3.0, 1.0, 12.0, 5.0), 300)
    xy = np.random.default_rng(0).uniform(-5, 15, (100, 2))
    np.testing.assert_allclose(pixel_to_world(world_to_pixel(xy, vp), vp), xy, atol=1e-9)
    np.testing.assert_allclose(world_to_pixel(np.array([4.5, 3.0]), vp), [150.0, 150.0])  # view centre
    frame = _frame()
    img = render_rgb(frame, size_px=200)
    behind = frame.robot_pos - 0.6 * frame.robot_radius_m * np.array([1.0, 0.0])  # heading 0 -> tick points +x
    ahead = frame.robot_pos + 0.6 * frame.robot_radius_m * np.array([1.0, 0.0])
    assert tuple(img[_pixel(behind, frame)]) == tuple(ROBOT)
    assert tuple(img[_pixel(ahead, frame)]) == tuple(HEADING)


def test_y_up_is_drawn_upright():
    frame = _frame(ped_pos=np.array([[5.0, 2.0], [5.0, 8.0]]), ped_vel=np.zeros((2, 2)), ped_radius=np.full(2, 0.3),
                   group_id=np.array([0, 1]), ped_id=np.arange(2))
    img = render_rgb(frame, size_px=200)
    rows_low = np.nonzero((img == PALETTE[0]).all(axis=-1))[0]
    rows_high = np.nonzero((img == PALETTE[1]).all(axis=-1))[0]
    assert rows_high.max() < rows_low.min()


def test_plan_is_drawn_only_when_given():
    plan = np.stack([np.linspace(2.0, 2.0, 6), np.linspace(2.0, 9.0, 6)], axis=1)
    probe = [2.0, 5.5]
    with_plan = _frame(plan=plan)
    assert tuple(render_rgb(with_plan, size_px=200)[_pixel(probe, with_plan)]) == tuple(PLAN)
    assert tuple(render_rgb(_frame(), size_px=200)[_pixel(probe, with_plan)]) == tuple(BACKGROUND)


def test_passing_options_are_drawn_grey_under_the_plan():
    plan = np.stack([np.linspace(2.0, 2.0, 6), np.linspace(2.0, 9.0, 6)], axis=1)
    option = plan + np.array([4.0, 0.0])
    frame = _frame(plan=plan, options=option[None])
    img = render_rgb(frame, size_px=200)
    assert tuple(img[_pixel([6.0, 5.5], frame)]) == tuple(OPTION)
    assert tuple(img[_pixel([2.0, 5.5], frame)]) == tuple(PLAN)
    with pytest.raises(ValueError, match="options"):
        render_rgb(_frame(options=option), size_px=200)


def test_predictions_are_drawn_only_when_given_in_a_faded_group_colour():
    frame = _frame()
    k, t = 2, 4
    pred = np.broadcast_to(frame.ped_pos, (k, t, 6, 2)).copy()
    pred[..., 1] -= 0.4 * np.arange(1, t + 1)[None, :, None]  # everyone walks down (-y)
    probe = frame.ped_pos[2] - [0.0, 1.2]  # single pedestrian (group 1), 1.2 m below
    faded = (PALETTE[1] * (1 - PREDICTION_FADE) + BACKGROUND * PREDICTION_FADE).astype(np.uint8)
    with_pred = dataclasses.replace(frame, predictions=pred)
    assert tuple(render_rgb(with_pred, size_px=200)[_pixel(probe, frame)]) == tuple(faded)
    assert tuple(render_rgb(frame, size_px=200)[_pixel(probe, frame)]) == tuple(BACKGROUND)
    pred[0, 1, 2] = np.nan  # non-finite prediction points are skipped, not fatal
    render_rgb(dataclasses.replace(frame, predictions=pred), size_px=200)


def test_walls_are_drawn():
    frame = _frame(walls=np.array([[[0.5, 5.0], [5.5, 5.0]]]))
    assert tuple(render_rgb(frame, size_px=200)[_pixel([3.0, 5.0], frame)]) == tuple(WALL)


@pytest.mark.parametrize("field, value", [
    ("robot_state", np.array([np.nan, 2.0, 0.0, 0.0, 0.0])),
    ("ped_pos", np.array([[3.0, 7.0], [np.nan, 7.0], [8.0, 8.0], [7.0, 3.0], [8.0, 3.0], [7.5, 4.0]])),
    ("goal", np.array([np.inf, 1.0])),
])
def test_non_finite_state_raises(field, value):
    with pytest.raises(ValueError, match=field):
        render_rgb(_frame(**{field: value}))


def test_inconsistent_predictions_shape_raises():
    with pytest.raises(ValueError, match="predictions"):
        render_rgb(_frame(predictions=np.zeros((3, 4, 5, 2))))


def test_empty_scene_and_holonomic_robot():
    frame = _frame(ped_pos=np.zeros((0, 2)), ped_vel=np.zeros((0, 2)), ped_radius=np.zeros(0),
                   group_id=np.zeros(0, dtype=int), ped_id=np.zeros(0, dtype=int),
                   robot_state=np.array([2.0, 2.0, 0.0, -0.5]))  # (x, y, vx, vy): heading down
    img = render_rgb(frame, size_px=200)
    assert tuple(img[_pixel([2.0, 2.0 - 0.6 * 0.3], frame)]) == tuple(HEADING)
    assert tuple(img[_pixel([2.0, 2.0 + 0.6 * 0.3], frame)]) == tuple(ROBOT)
