"""Episode videos: every `SceneFrame` of an episode drawn by `render_rgb` and encoded as MP4 or GIF.

A frame is the `render_rgb` image of side `size_px` cut to the view (`content_box`: the letterbox bands of a long
scene such as the corridor are dropped), so the longer side is `size_px` and both sides are even (H.264 needs it).

MP4 (H.264, yuv420p) needs the optional `video` extra (imageio-ffmpeg, which ships an ffmpeg binary); GIF uses
Pillow (installed with matplotlib). This is the only module of envs that imports the encoder. A video is written
atomically (`crowdsim.files.write_atomic`, which `envs.atomic` re-exports): the file appears complete when the episode
ends, and an episode that raises, or Ctrl-C, leaves no file.

Usage:
    result = record_video("out/videos/mpc-cv-plaza-seed0.mp4", lambda obs: run_episode(..., observer=obs),
                          fmt="mp4", fps=10, size_px=480)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from crowdsim.files import write_atomic
from envs.drawing.frame import SceneFrame
from envs.drawing.render import make_viewport, render_rgb

VIDEO_FORMATS = ("mp4", "gif")
DEFAULT_SIZE_PX = 480
MIN_SIZE_PX = 16
INSTALL_HINT = 'MP4 videos need the video extra: pip install -e ".[video]" (or use --video-format gif)'
T = TypeVar("T")


def check_video_settings(fmt: str, size_px: int) -> None:
    """ValueError (one line) for an unknown format or an odd / too small frame size (H.264 needs even sizes)."""
    if fmt not in VIDEO_FORMATS:
        raise ValueError(f"unknown video format {fmt!r}; valid: {', '.join(VIDEO_FORMATS)}")
    if size_px < MIN_SIZE_PX or size_px % 2:
        raise ValueError(f"video size must be an even number of pixels >= {MIN_SIZE_PX}, got {size_px}")


def check_video_options(fmt: str, size_px: int) -> None:
    """`check_video_settings`, and ValueError naming the extra when the MP4 encoder is not installed. Writes
    nothing."""
    check_video_settings(fmt, size_px)
    if fmt == "mp4":
        _ffmpeg()


def _ffmpeg() -> Any:
    """The imageio_ffmpeg module, or ValueError saying which extra to install."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise ValueError(INSTALL_HINT) from None
    return imageio_ffmpeg


def content_box(bounds: tuple, size_px: int, view: tuple | None = None) -> tuple[int, int, int, int]:
    """(row0, row1, col0, col1) of the part of a `render_rgb(frame, size_px, view)` image that shows the view
    (`frame.bounds` = `bounds`): centred, each side even and at least the view's extent in pixels."""
    vp = make_viewport(bounds, size_px, view)
    h = min(size_px, 2 * math.ceil((size_px - 2 * vp.off_y) / 2 - 1e-9))
    w = min(size_px, 2 * math.ceil((size_px - 2 * vp.off_x) / 2 - 1e-9))
    r0, c0 = (size_px - h) // 2, (size_px - w) // 2
    return r0, r0 + h, c0, c0 + w


def video_image(frame: SceneFrame, size_px: int, view: tuple | None = None) -> np.ndarray:
    """The video frame of `frame`: (H, W, 3) uint8, max(H, W) = size_px, both even (`content_box`)."""
    r0, r1, c0, c1 = content_box(frame.bounds, size_px, view)
    return render_rgb(frame, size_px, view)[r0:r1, c0:c1]


class _Mp4Sink:
    """Streams (H, W, 3) uint8 frames into an H.264 MP4 through imageio-ffmpeg's ffmpeg process."""

    def __init__(self, path: str, fps: float, size: tuple[int, int]) -> None:
        self._gen = _ffmpeg().write_frames(path, size, fps=fps, codec="libx264", quality=6,
                                           macro_block_size=2, output_params=["-f", "mp4"])
        self._gen.send(None)

    def add(self, img: np.ndarray) -> None:
        self._gen.send(np.ascontiguousarray(img))

    def close(self) -> None:
        self._gen.close()


class _GifSink:
    """Collects frames as palette images (one byte per pixel) and writes a looping GIF with Pillow (which merges
    a frame identical to the one before into it, lengthening that one's duration)."""

    def __init__(self, path: str, fps: float, size: tuple[int, int]) -> None:
        self.path, self.duration_ms = path, round(1000.0 / fps)
        self._frames: list[Any] = []

    def add(self, img: np.ndarray) -> None:
        from PIL import Image

        self._frames.append(Image.fromarray(img, "RGB").quantize(colors=256, dither=Image.Dither.NONE))

    def close(self) -> None:
        if self._frames:
            first, *rest = self._frames
            first.save(self.path, format="GIF", save_all=True, append_images=rest, duration=self.duration_ms,
                       loop=0, optimize=False)
        self._frames = []


class VideoObserver:
    """An episode observer (`log(frame)`, as `RerunObserver`): draws each frame (`video_image`; `view`: the world
    rectangle, m, default the scene bounds) and hands it to the encoder, which it opens at the first frame with that
    frame's size (width, height) px. `frames`: how many were logged."""

    def __init__(self, open_sink: Callable[[tuple[int, int]], _Mp4Sink | _GifSink], size_px: int,
                 view: tuple | None = None) -> None:
        self.open_sink, self.size_px, self.view = open_sink, size_px, view
        self.sink: _Mp4Sink | _GifSink | None = None
        self.frames = 0

    def log(self, frame: SceneFrame) -> None:
        img = video_image(frame, self.size_px, self.view)
        if self.sink is None:
            self.sink = self.open_sink((img.shape[1], img.shape[0]))
        self.sink.add(img)
        self.frames += 1

    def close(self) -> None:
        """Finish the file (ffmpeg flushed and stopped; the GIF written). An episode without frames leaves it empty."""
        if self.sink is not None:
            self.sink.close()


def record_video(path: str | Path, episode: Callable[[VideoObserver], T], *, fmt: str = "mp4", fps: float = 10.0,
                 size_px: int = DEFAULT_SIZE_PX, view: tuple | None = None) -> T:
    """Run `episode(observer)` (it calls `observer.log(frame)` per step) and write its frames to `path` as a video
    of `fps` frames per second (the env's `render_fps`), atomically. Returns what `episode` returns; when it raises,
    no file is left and the error propagates."""
    check_video_options(fmt, size_px)
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    out: list[T] = []

    def write(tmp: str) -> None:
        sink = _Mp4Sink if fmt == "mp4" else _GifSink
        observer = VideoObserver(lambda size: sink(tmp, fps, size), size_px, view)
        try:
            out.append(episode(observer))
        except BaseException:
            if fmt == "mp4":
                observer.close()  # stop ffmpeg; write_atomic then removes the partial file
            raise
        observer.close()

    write_atomic(path, write)
    return out[0]


def video_name(policy: str, where: str, seed: int, fmt: str) -> str:
    """`<policy>-<cell or scenario>-seed<k>.<fmt>`, with path separators and colons of plug-in names replaced."""
    clean = [s.replace("/", "_").replace(":", "_").replace(" ", "_") for s in (policy, where)]
    return f"{clean[0]}-{clean[1]}-seed{int(seed)}.{fmt}"
