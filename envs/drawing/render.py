"""`render_rgb`: draw a `SceneFrame` into an RGB array with numpy only (no display, matplotlib or pillow).

Conventions:
    * The image is square, (size_px, size_px, 3) uint8. The view (world rectangle) is scaled uniformly to fit
      and centred (letterbox): its shorter side is widened symmetrically, and whatever lies in the widened
      band is drawn too. x grows to the right; world y up is drawn upwards (larger y = smaller row index).
    * Pixel (row r, column c) covers the continuous pixel coordinates [c, c + 1) x [r, r + 1); its centre is
      (c + 0.5, r + 0.5). `world_to_pixel` returns continuous (column, row) coordinates; `np.floor` gives the
      index of the pixel that contains a point.
    * Colours: pedestrians are filled discs of their true radius in `palette()[group_id % 24]`, the same
      colours as `crowdsim.recording` and `envs.drawing.rerun_observer`. A pedestrian alone (a group of one) keeps its
      own palette colour, so colours agree across the viewers; groups are made visible by thin links in the
      group colour that join the members in angular order around the group centroid (a segment for a pair,
      an outline for three or more). Predictions are thin polylines from each pedestrian's current position,
      in its group colour faded towards the background. The robot is a dark disc with a light heading tick
      (heading = state[2] for the unicycle, the velocity direction for the holonomic (x, y, vx, vy) state);
      its goal is a dark X; its plan a dark 2 px polyline, the planner's other passing options grey 1 px ones.
    * Validation: non-finite values in the robot state, goal, pedestrian positions or radii raise ValueError.
      Non-finite points of the plan or the predictions are skipped (segments touching them are not drawn),
      as are non-finite walls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdsim.recording import N_COLOURS, palette
from envs.drawing.frame import SceneFrame

BACKGROUND = np.array([248, 248, 248], dtype=np.uint8)
WALL = np.array([70, 70, 70], dtype=np.uint8)
ROBOT = np.array([35, 35, 35], dtype=np.uint8)
HEADING = np.array([250, 250, 250], dtype=np.uint8)
PLAN = np.array([20, 20, 20], dtype=np.uint8)
OPTION = np.array([140, 140, 140], dtype=np.uint8)
GOAL = np.array([20, 20, 20], dtype=np.uint8)
PREDICTION_FADE = 0.45  # fraction of the background mixed into a prediction's group colour
VIEW_MARGIN = 0.05  # default view = bounds grown by this fraction of their larger side on every side
_PALETTE = palette(N_COLOURS)


@dataclass(frozen=True)
class Viewport:
    """Uniform world-to-pixel map of a square image.

    Attributes:
        size_px: side of the square image, px.
        scale: pixels per metre.
        x_min: world x drawn at continuous column `off_x`, m.
        y_max: world y drawn at continuous row `off_y`, m.
        off_x: letterbox offset of the view along columns, px.
        off_y: letterbox offset of the view along rows, px.
    """

    size_px: int
    scale: float
    x_min: float
    y_max: float
    off_x: float
    off_y: float


def make_viewport(bounds: tuple[float, float, float, float], size_px: int = 480,
                  view: tuple[float, float, float, float] | None = None, margin: float = VIEW_MARGIN) -> Viewport:
    """The viewport showing `view` (x_min, y_min, x_max, y_max, m), or `bounds` grown by `margin` x their
    larger side when `view` is None, fitted and centred in a (size_px, size_px) image."""
    if size_px < 8:
        raise ValueError(f"size_px must be at least 8, got {size_px}")
    if view is None:
        x0, y0, x1, y1 = (float(b) for b in bounds)
        pad = margin * max(x1 - x0, y1 - y0, 1e-3)
        x0, y0, x1, y1 = x0 - pad, y0 - pad, x1 + pad, y1 + pad
    else:
        x0, y0, x1, y1 = (float(b) for b in view)
    w, h = x1 - x0, y1 - y0
    if not (np.isfinite([x0, y0, x1, y1]).all() and w > 0 and h > 0):
        raise ValueError(f"view must be a finite (x_min, y_min, x_max, y_max) with positive extent, got "
                         f"{(x0, y0, x1, y1)}")
    scale = size_px / max(w, h)
    return Viewport(size_px=int(size_px), scale=scale, x_min=x0, y_max=y1,
                    off_x=(size_px - w * scale) / 2.0, off_y=(size_px - h * scale) / 2.0)


def world_to_pixel(xy: np.ndarray, vp: Viewport) -> np.ndarray:
    """(..., 2) world points (x, y), m -> (..., 2) continuous pixel coordinates (column, row), px."""
    xy = np.asarray(xy, dtype=float)
    col = vp.off_x + (xy[..., 0] - vp.x_min) * vp.scale
    row = vp.off_y + (vp.y_max - xy[..., 1]) * vp.scale
    return np.stack([col, row], axis=-1)


def pixel_to_world(cr: np.ndarray, vp: Viewport) -> np.ndarray:
    """(..., 2) continuous pixel coordinates (column, row), px -> (..., 2) world points (x, y), m.
    Pass `index + 0.5` to get the world position of a pixel centre."""
    cr = np.asarray(cr, dtype=float)
    x = vp.x_min + (cr[..., 0] - vp.off_x) / vp.scale
    y = vp.y_max - (cr[..., 1] - vp.off_y) / vp.scale
    return np.stack([x, y], axis=-1)


def group_colours(group_id: np.ndarray) -> np.ndarray:
    """(N,) group ids -> (N, 3) uint8 palette colours (ids taken modulo 24, as in crowdsim.recording)."""
    return _PALETTE[np.asarray(group_id, dtype=np.int64) % N_COLOURS]


def group_links(pos: np.ndarray, group_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments that make groups visible: each group's members joined in angular order around its centroid,
    closed for three or more members, one segment for a pair, none for a pedestrian alone.

    Args:
        pos: (N, 2) positions, m.
        group_id: (N,) non-negative integer group ids.
    Returns:
        (L, 2, 2) segments, m, and (L,) the group id of each.
    """
    pos = np.asarray(pos, dtype=float)
    gid = np.asarray(group_id, dtype=np.int64)
    if len(pos) < 2:
        return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
    _, inv, counts = np.unique(gid, return_inverse=True, return_counts=True)
    centre = np.stack([np.bincount(inv, pos[:, 0]), np.bincount(inv, pos[:, 1])], axis=1) / counts[:, None]
    rel = pos - centre[inv]
    order = np.lexsort((np.arctan2(rel[:, 1], rel[:, 0]), inv))
    g_sorted = inv[order]
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    k = np.arange(len(order))
    nxt = np.where(k + 1 < len(order), k + 1, 0)
    nxt = np.where((nxt < len(order)) & (g_sorted[nxt] == g_sorted), nxt, start[g_sorted])  # wrap to first
    size = counts[g_sorted]
    keep = (size >= 3) | ((size == 2) & (k == start[g_sorted]))
    a, b = order[keep], order[nxt[keep]]
    return np.stack([pos[a], pos[b]], axis=1), gid[a]


def _check_finite(name: str, value: np.ndarray) -> None:
    if not np.isfinite(value).all():
        raise ValueError(f"SceneFrame.{name} holds non-finite values (NaN or inf): {value!r}")


def _clip_segments(p0: np.ndarray, p1: np.ndarray, lo: float,
                   hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liang–Barsky clipping of (S, 2) segments to the square [lo, hi]^2: the clipped starts and ends of the
    kept segments, and the (S,) mask of the kept ones."""
    d = p1 - p0
    t0, t1 = np.zeros(len(p0)), np.ones(len(p0))
    ok = np.ones(len(p0), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis in (0, 1):
            for p, q in ((-d[:, axis], p0[:, axis] - lo), (d[:, axis], hi - p0[:, axis])):
                parallel = p == 0
                ok &= ~(parallel & (q < 0))
                r = q / p
                t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
                t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
    ok &= t0 <= t1
    return p0[ok] + t0[ok, None] * d[ok], p0[ok] + t1[ok, None] * d[ok], ok


def _draw_segments(img: np.ndarray, p0: np.ndarray, p1: np.ndarray, colour: np.ndarray, thickness: int) -> None:
    """Draw (S, 2) -> (S, 2) pixel-space segments (column, row) with colour (3,) or (S, 3) and a `thickness` px
    square brush, sampled once per pixel step along the longer axis (8-connected, no gaps). Segments are
    clipped to the image first; those with non-finite ends are skipped."""
    size = img.shape[0]
    colour = np.broadcast_to(np.asarray(colour, dtype=np.uint8), (len(p0), 3))
    finite = np.isfinite(p0).all(axis=1) & np.isfinite(p1).all(axis=1)
    p0, p1, colour = p0[finite], p1[finite], colour[finite]
    if not len(p0):
        return
    p0, p1, ok = _clip_segments(p0, p1, -thickness, size + thickness)
    colour = colour[ok]
    if not len(p0):
        return
    d = p1 - p0
    n = np.ceil(np.maximum(np.abs(d[:, 0]), np.abs(d[:, 1]))).astype(np.int64) + 1  # one sample per pixel step
    seg = np.repeat(np.arange(len(p0)), n)
    t = np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)
    t = t / np.maximum(n - 1, 1)[seg]
    shift = thickness + 1  # points are >= -thickness after clipping: shift, truncate, unshift = floor
    col = (p0[seg, 0] + t * d[seg, 0] + shift).astype(np.int64) - shift
    row = (p0[seg, 1] + t * d[seg, 1] + shift).astype(np.int64) - shift
    if thickness > 1:
        o = np.arange(thickness) - (thickness - 1) // 2
        oc, orow = (a.ravel() for a in np.meshgrid(o, o))
        col = (col[:, None] + oc).ravel()
        row = (row[:, None] + orow).ravel()
        seg = np.repeat(seg, len(oc))
    inside = (col >= 0) & (col < size) & (row >= 0) & (row < size)
    img[row[inside], col[inside]] = colour[seg[inside]]


def _draw_discs(img: np.ndarray, centre: np.ndarray, radius_px: np.ndarray, colour: np.ndarray) -> None:
    """Fill discs: (N, 2) pixel centres (column, row), (N,) radii, px, colour (N, 3) or (3,). A pixel is
    filled when its centre lies in the disc; radii are at least 0.75 px so every disc covers its own pixel.
    Later discs are drawn over earlier ones."""
    if not len(centre):
        return
    size = img.shape[0]
    colour = np.broadcast_to(np.asarray(colour, dtype=np.uint8), (len(centre), 3))
    r = np.maximum(radius_px, 0.75)
    box = int(np.ceil(2.0 * r.max())) + 2
    c0 = np.floor(centre[:, 0] - r).astype(np.int64)
    r0 = np.floor(centre[:, 1] - r).astype(np.int64)
    cols = c0[:, None] + np.arange(box)  # (N, B)
    rows = r0[:, None] + np.arange(box)
    dx = cols + 0.5 - centre[:, :1]
    dy = rows + 0.5 - centre[:, 1:]
    inside = dy[:, :, None] ** 2 + dx[:, None, :] ** 2 <= (r**2)[:, None, None]
    inside &= ((rows >= 0) & (rows < size))[:, :, None] & ((cols >= 0) & (cols < size))[:, None, :]
    k, i, j = np.nonzero(inside)
    img[rows[k, i], cols[k, j]] = colour[k]


def _polyline_segments(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., P, 2) polylines -> (M, 2) starts and (M, 2) ends of their consecutive segments."""
    return points[..., :-1, :].reshape(-1, 2), points[..., 1:, :].reshape(-1, 2)


def robot_heading(state: np.ndarray) -> float | None:
    """Heading of the robot, rad: state[2] for (x, y, heading, ...), the velocity direction for the
    holonomic (x, y, vx, vy) state (None when at rest or for a 2-d state)."""
    if len(state) == 4:
        return float(np.arctan2(state[3], state[2])) if np.hypot(state[2], state[3]) > 1e-6 else None
    return float(state[2]) if len(state) >= 3 else None


def validate_frame(frame: SceneFrame) -> None:
    """Raise ValueError when the robot state, goal, pedestrian positions, radii or group ids are unusable."""
    _check_finite("robot_state", np.asarray(frame.robot_state, dtype=float))
    _check_finite("goal", np.asarray(frame.goal, dtype=float))
    if not np.isfinite(frame.robot_radius_m) or frame.robot_radius_m < 0:
        raise ValueError(f"SceneFrame.robot_radius_m must be finite and >= 0, got {frame.robot_radius_m}")
    pos = np.asarray(frame.ped_pos, dtype=float).reshape(-1, 2)
    _check_finite("ped_pos", pos)
    _check_finite("ped_radius", np.asarray(frame.ped_radius, dtype=float))
    n = len(pos)
    if len(frame.ped_radius) != n or len(frame.group_id) != n:
        raise ValueError(f"SceneFrame: ped_pos has {n} rows but ped_radius {len(frame.ped_radius)} and "
                         f"group_id {len(frame.group_id)}")
    if n and np.min(frame.group_id) < 0:
        raise ValueError("SceneFrame.group_id must be non-negative")
    if frame.predictions is not None:
        shape = np.shape(frame.predictions)
        if len(shape) != 4 or shape[2] != n or shape[3] != 2:
            raise ValueError(f"SceneFrame.predictions must be (K, T, {n}, 2), got {shape}")
    if frame.plan is not None and (np.ndim(frame.plan) != 2 or np.shape(frame.plan)[1] != 2):
        raise ValueError(f"SceneFrame.plan must be (H + 1, 2), got {np.shape(frame.plan)}")
    if frame.options is not None and (np.ndim(frame.options) != 3 or np.shape(frame.options)[2] != 2):
        raise ValueError(f"SceneFrame.options must be (O, H + 1, 2), got {np.shape(frame.options)}")


def render_rgb(frame: SceneFrame, size_px: int = 480, view: tuple | None = None) -> np.ndarray:
    """Draw `frame` into a (size_px, size_px, 3) uint8 RGB image.

    Args:
        frame: the scene to draw (world frame, m).
        size_px: side of the square image, px.
        view: (x_min, y_min, x_max, y_max) world rectangle to show, m; default `frame.bounds` grown by 5 % of
            their larger side. Letterboxed to keep the aspect ratio.
    Raises:
        ValueError: non-finite robot state, goal, pedestrian positions or radii; inconsistent shapes.
    """
    validate_frame(frame)
    vp = make_viewport(frame.bounds, size_px, view)
    img = np.empty((vp.size_px, vp.size_px, 3), dtype=np.uint8)
    img.reshape(vp.size_px, -1)[:] = np.tile(BACKGROUND, vp.size_px)  # row-wise copy: ~50x faster than img[:] = rgb
    s = vp.scale

    walls = np.asarray(frame.walls, dtype=float).reshape(-1, 2, 2)
    if len(walls):
        w = world_to_pixel(walls, vp)
        _draw_segments(img, w[:, 0], w[:, 1], WALL, thickness=max(2, round(0.06 * s)))

    pos = np.asarray(frame.ped_pos, dtype=float).reshape(-1, 2)
    gid = np.asarray(frame.group_id, dtype=np.int64)
    colours = group_colours(gid)
    links, link_gid = group_links(pos, gid)
    if len(links):
        lp = world_to_pixel(links, vp)
        _draw_segments(img, lp[:, 0], lp[:, 1], group_colours(link_gid), thickness=1)

    if frame.predictions is not None and len(pos):
        pred = np.asarray(frame.predictions, dtype=float)  # (K, T, N, 2)
        k = pred.shape[0]
        lines = np.concatenate([np.broadcast_to(pos, (k, 1, *pos.shape)), pred], axis=1)  # (K, T+1, N, 2)
        lines = world_to_pixel(np.swapaxes(lines, 1, 2), vp)  # (K, N, T+1, 2)
        a, b = _polyline_segments(lines)
        faded = (colours * (1 - PREDICTION_FADE) + BACKGROUND * PREDICTION_FADE).astype(np.uint8)
        seg_colour = np.repeat(np.tile(faded, (k, 1)), lines.shape[2] - 1, axis=0)
        _draw_segments(img, a, b, seg_colour, thickness=1)

    if len(pos):
        _draw_discs(img, world_to_pixel(pos, vp), np.asarray(frame.ped_radius, dtype=float) * s, colours)

    goal = world_to_pixel(np.asarray(frame.goal, dtype=float)[:2], vp)
    arm = max(4.0, 0.25 * s)
    cross = np.array([[-arm, -arm], [arm, arm], [-arm, arm], [arm, -arm]]) + goal
    _draw_segments(img, cross[[0, 2]], cross[[1, 3]], GOAL, thickness=2)

    for option in () if frame.options is None else np.asarray(frame.options, dtype=float):
        a, b = _polyline_segments(world_to_pixel(option, vp))
        _draw_segments(img, a, b, OPTION, thickness=1)
    if frame.plan is not None and len(frame.plan) >= 2:
        a, b = _polyline_segments(world_to_pixel(np.asarray(frame.plan, dtype=float), vp))
        _draw_segments(img, a, b, PLAN, thickness=2)

    state = np.asarray(frame.robot_state, dtype=float)
    centre = world_to_pixel(state[:2], vp)
    r_px = max(float(frame.robot_radius_m) * s, 2.0)
    _draw_discs(img, centre[None], np.array([r_px]), ROBOT)
    heading = robot_heading(state)
    if heading is not None:
        tip = centre + 0.9 * r_px * np.array([np.cos(heading), -np.sin(heading)])  # rows grow downwards
        _draw_segments(img, centre[None], tip[None], HEADING, thickness=2 if r_px >= 6 else 1)
    return img
