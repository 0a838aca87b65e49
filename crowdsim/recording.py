"""Rerun (.rrd) recordings of a crowd, colour-coded by group.

rerun-sdk is an optional dependency (extra `viz`) and is imported only when a recorder is created.
Rerun's 2D views are y-down, so positions are logged as (x, -y) to show the y-up world upright.
"""

from __future__ import annotations

import colorsys
import uuid
from pathlib import Path

import numpy as np

from crowdsim.state import CrowdState

N_COLOURS = 24


def palette(n: int = N_COLOURS) -> np.ndarray:
    """(n, 3) uint8 well-separated colours (golden-ratio hues)."""
    hues = (np.arange(n) * 0.618033988749895) % 1.0
    rgb = [colorsys.hsv_to_rgb(h, 0.75, 0.95) for h in hues]
    return (np.array(rgb) * 255).astype(np.uint8)


def _flip(xy: np.ndarray) -> np.ndarray:
    return np.asarray(xy, dtype=np.float32) * np.array([1.0, -1.0], dtype=np.float32)


class RrdRecorder:
    """Streams crowd frames into a .rrd file.

    `log_frame(state)` logs the active pedestrians as points (radius = body radius) with
    class ids `label % 24`, so every group keeps one colour for its lifetime, plus their goals' lines
    when `show_goals` is set. `close()` flushes the file.
    """

    def __init__(self, path: Path, walls: np.ndarray, application_id: str = "crowdsim") -> None:
        import rerun as rr  # lazy: only the visualisation path needs rerun

        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        self.rec.save(str(self.path))
        colours = palette()
        infos = [rr.AnnotationInfo(id=k, label=f"group%{k}", color=tuple(int(c) for c in colours[k]))
                 for k in range(N_COLOURS)]
        self.rec.log("world", rr.AnnotationContext(infos), static=True)
        if len(walls):
            strips = [_flip(seg) for seg in np.asarray(walls)]
            self.rec.log("world/walls", rr.LineStrips2D(strips, colors=[(200, 200, 200)]), static=True)

    def log_frame(self, state: CrowdState) -> None:
        rr = self.rr
        act = state.active
        self.rec.set_time("frame", sequence=int(state.frame))
        self.rec.set_time("sim_time", duration=float(state.time_s))
        self.rec.log(
            "world/pedestrians",
            rr.Points2D(
                _flip(state.pos[act]),
                radii=state.radius[act].astype(np.float32),
                class_ids=(state.label[act] % N_COLOURS).astype(np.uint16),
                labels=[str(int(p)) for p in state.ped_id[act]],
                show_labels=False,
            ),
        )
        self.rec.log("metrics/active", rr.Scalars(float(act.sum())))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
