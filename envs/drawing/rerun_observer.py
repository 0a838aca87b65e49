"""`RerunObserver`: log a whole episode of `SceneFrame`s to a rerun `.rrd` file.

rerun-sdk (extra `viz`, pinned to 0.41) is imported only in the constructor, so importing this module does not
need it. Rerun's 2D views are y-down: every position is logged as (x, -y) so the y-up world shows upright.

Entities (timelines `step`, a sequence, and `sim_time`, a duration in s):
    world                   static AnnotationContext: class id k = group k, colour `palette()[k % 24]` (the
                            colours of `crowdsim.recording` and `envs.drawing.render`); extended when a larger group id
                            appears.
    world/walls             static LineStrips2D, one strip per wall segment.
    world/pedestrians       Points2D, radius = body radius (m), class id = group id, label = ped id (hidden).
    world/groups            LineStrips2D linking the members of each group (`envs.drawing.render.group_links`), class id
                            = group id.
    world/robot             Points2D with the robot radius; world/robot/heading an Arrows2D (heading = state[2],
                            or the velocity for the holonomic (x, y, vx, vy) state).
    world/goal              Points2D.
    world/plan              LineStrips2D, one strip: the planned positions (non-finite points dropped).
    world/options           LineStrips2D, one strip per other passing option of the planner (the guidance layer's
                            solved plans not chosen; options with a non-finite point dropped).
    world/predictions       LineStrips2D, one strip per (sample k, pedestrian n), in the order k * N + n: the
                            pedestrian's current position followed by its T predicted positions; class id = its
                            ground-truth group id. Strips with a non-finite point are dropped.
    world/predicted_groups  LineStrips2D linking the members of each *predicted* group, in one neutral colour.
    metrics/<name>          Scalars, one per key of `frame.scalars` (the name escaped as one path part).

Optional data that is absent at a step is not logged; when it was shown before, a single `rr.Clear` hides it so
the viewer does not keep showing a stale plan.

Atomic write: the stream goes to a hidden temporary file next to `path` and is renamed to `path` when the observer
is finalised: by `close()`, on leaving a `with` block (also through an exception), when the observer is garbage
collected, or at interpreter exit, whichever comes first (so `RerunObserver(path).log(frame)` writes `path`). A
process killed by a signal before that leaves only the temporary `.<name>.<hex>.part` file, never a truncated
`path`.
"""

from __future__ import annotations

import os
import uuid
import weakref
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from crowdsim.recording import N_COLOURS, palette
from envs.drawing.frame import SceneFrame
from envs.drawing.render import group_links, robot_heading, validate_frame

WALL_COLOUR = (200, 200, 200)
ROBOT_COLOUR = (240, 240, 240)
GOAL_COLOUR = (255, 255, 255)
PLAN_COLOUR = (255, 255, 255)
OPTION_COLOUR = (150, 150, 150)
PREDICTED_GROUP_COLOUR = (160, 160, 160)
MAX_CLASS_ID = 65535  # rerun class ids are uint16


def _finalise(rec: Any, tmp: Path, path: Path) -> None:
    """Flush a recording stream and move its temporary file into place at `path`."""
    rec.flush()
    rec.disconnect()
    if tmp.exists():
        os.replace(tmp, path)


def _flip(xy: np.ndarray) -> np.ndarray:
    """(..., 2) world points, m -> float32 (x, -y) for rerun's y-down 2D views."""
    return np.asarray(xy, dtype=np.float32) * np.array([1.0, -1.0], dtype=np.float32)


class RerunObserver:
    """Writes an episode of `SceneFrame`s to `path` (.rrd).

    Usage:
        with RerunObserver("runs/ep0.rrd") as obs:
            for frame in frames:
                obs.log(frame)

    Args:
        path: the .rrd file to write; its parent folders are created.
        application_id: the rerun application id shown in the viewer.
    """

    def __init__(self, path: str | Path, application_id: str = "crowdnav") -> None:
        import rerun as rr  # lazy: only the visualisation path needs rerun

        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.{uuid.uuid4().hex[:8]}.part")
        self.rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        self.rec.save(str(self._tmp))
        # Runs once: on close(), garbage collection or interpreter exit (it must not refer to self).
        self._finalizer = weakref.finalize(self, _finalise, self.rec, self._tmp, self.path)
        self._n_classes = 0  # class ids covered by the logged annotation context
        self._started = False
        self._closed = False
        self._shown: set[str] = set()  # entities currently holding data (cleared when the data goes away)

    # -- public API ---------------------------------------------------------------------------------------

    def log(self, frame: SceneFrame) -> None:
        """Log one step. The first call also logs the static walls and the annotation context.

        Raises:
            ValueError: non-finite robot state, goal, pedestrian positions or radii; group ids outside
                0..65535; inconsistent shapes (see `envs.drawing.render.validate_frame`).
            RuntimeError: after `close()`.
        """
        if self._closed:
            raise RuntimeError("RerunObserver.log() after close()")
        validate_frame(frame)
        rr, rec = self.rr, self.rec
        gid = np.asarray(frame.group_id, dtype=np.int64)
        if len(gid) and gid.max() > MAX_CLASS_ID:
            raise ValueError(f"group ids must fit rerun's uint16 class ids (<= {MAX_CLASS_ID}), got {gid.max()}")
        if not self._started:
            self._log_static(frame)
            self._started = True
        self._cover_classes(int(gid.max()) + 1 if len(gid) else 0)

        rec.set_time("step", sequence=int(frame.step))
        rec.set_time("sim_time", duration=float(frame.time_s))

        pos = np.asarray(frame.ped_pos, dtype=float).reshape(-1, 2)
        class_ids = gid.astype(np.uint16)
        self._put("world/pedestrians", len(pos) > 0, lambda: rr.Points2D(
            _flip(pos), radii=np.asarray(frame.ped_radius, dtype=np.float32), class_ids=class_ids,
            labels=[str(int(p)) for p in np.asarray(frame.ped_id)], show_labels=False))
        links, link_gid = group_links(pos, gid)
        self._put("world/groups", len(links) > 0, lambda: rr.LineStrips2D(
            _flip(links), radii=0.02, class_ids=link_gid.astype(np.uint16)))

        state = np.asarray(frame.robot_state, dtype=float)
        radius = float(frame.robot_radius_m)
        rec.log("world/robot", rr.Points2D(_flip(state[:2])[None], radii=[radius], colors=[ROBOT_COLOUR],
                                           labels=["robot"], show_labels=False))
        heading = robot_heading(state)
        self._put("world/robot/heading", heading is not None, lambda: rr.Arrows2D(
            origins=_flip(state[:2])[None],
            vectors=_flip(max(2.0 * radius, 0.3) * np.array([np.cos(heading), np.sin(heading)]))[None],
            colors=[ROBOT_COLOUR], radii=0.03))
        rec.log("world/goal", rr.Points2D(_flip(np.asarray(frame.goal, dtype=float)[:2])[None],
                                          radii=[max(0.5 * radius, 0.1)], colors=[GOAL_COLOUR],
                                          labels=["goal"], show_labels=False))

        plan = None if frame.plan is None else np.asarray(frame.plan, dtype=float)
        if plan is not None:
            plan = plan[np.isfinite(plan).all(axis=1)]
        self._put("world/plan", plan is not None and len(plan) >= 2, lambda: rr.LineStrips2D(
            [_flip(plan)], radii=0.04, colors=[PLAN_COLOUR]))

        options = [] if frame.options is None else [o for o in np.asarray(frame.options, dtype=float)
                                                     if len(o) >= 2 and np.isfinite(o).all()]
        self._put("world/options", len(options) > 0, lambda: rr.LineStrips2D(
            [_flip(o) for o in options], radii=0.02, colors=[OPTION_COLOUR]))

        strips, strip_gid = self._prediction_strips(frame, pos, gid)
        self._put("world/predictions", len(strips) > 0, lambda: rr.LineStrips2D(
            _flip(strips), radii=0.015, class_ids=strip_gid.astype(np.uint16)))

        pred_links = np.zeros((0, 2, 2))
        if frame.predicted_group_id is not None and len(pos):
            pred_links, _ = group_links(pos, np.asarray(frame.predicted_group_id, dtype=np.int64))
        self._put("world/predicted_groups", len(pred_links) > 0, lambda: rr.LineStrips2D(
            _flip(pred_links), radii=0.03, colors=[PREDICTED_GROUP_COLOUR]))

        for name, value in frame.scalars.items():
            rec.log(f"metrics/{rr.escape_entity_path_part(str(name))}", rr.Scalars(float(value)))

    def close(self) -> None:
        """Flush the stream and move the file into place at `path`. Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._finalizer()

    def __enter__(self) -> RerunObserver:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- helpers ------------------------------------------------------------------------------------------

    def _put(self, entity: str, present: bool, make: Any) -> None:
        """Log `make()` at `entity` when `present`; otherwise clear the entity once if it holds data."""
        if present:
            self.rec.log(entity, make())
            self._shown.add(entity)
        elif entity in self._shown:
            self.rec.log(entity, self.rr.Clear(recursive=False))
            self._shown.discard(entity)

    def _log_static(self, frame: SceneFrame) -> None:
        walls = np.asarray(frame.walls, dtype=float).reshape(-1, 2, 2)
        walls = walls[np.isfinite(walls).all(axis=(1, 2))]
        if len(walls):
            self.rec.log("world/walls", self.rr.LineStrips2D(_flip(walls), radii=0.05, colors=[WALL_COLOUR]),
                         static=True)

    def _cover_classes(self, n: int) -> None:
        """(Re)log the static annotation context so that class ids 0..n-1 (at least 0..23) have colours."""
        if n <= self._n_classes and self._n_classes:
            return
        rr = self.rr
        size = max(N_COLOURS, n, 2 * self._n_classes)
        size = min(size, MAX_CLASS_ID + 1)
        colours = palette(N_COLOURS)
        infos = [rr.AnnotationInfo(id=k, label=f"group {k}", color=tuple(int(c) for c in colours[k % N_COLOURS]))
                 for k in range(size)]
        self.rec.log("world", rr.AnnotationContext(infos), static=True)
        self._n_classes = size

    @staticmethod
    def _prediction_strips(frame: SceneFrame, pos: np.ndarray, gid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S, T + 1, 2) finite prediction strips (current position first), m, and their (S,) group ids."""
        if frame.predictions is None or not len(pos):
            return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
        pred = np.asarray(frame.predictions, dtype=float)  # (K, T, N, 2)
        k = pred.shape[0]
        lines = np.concatenate([np.broadcast_to(pos, (k, 1, *pos.shape)), pred], axis=1)  # (K, T+1, N, 2)
        lines = np.swapaxes(lines, 1, 2).reshape(k * len(pos), -1, 2)  # strip k * N + n
        ok = np.isfinite(lines).all(axis=(1, 2))
        return lines[ok], np.tile(gid, k)[ok]
