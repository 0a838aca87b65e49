"""Episode videos: every `SceneFrame` of an episode drawn by `render_rgb` and encoded as MP4 or GIF.

MP4 (H.264, yuv420p) needs the optional `video` extra (imageio-ffmpeg, which ships an ffmpeg binary); GIF uses
Pillow (installed with matplotlib). This is the only module of envs that imports the encoder. A video is written
atomically (`crowdsim.files.write_atomic`, which `envs.atomic` re-exports): the file appears complete when the episode
ends, and an episode that raises, or Ctrl-C, leaves no file.

Usage:
    result = record_video("out/videos/mpc-cv-plaza-seed0.mp4", lambda obs: run_episode(..., observer=obs),
                          fmt="mp4", fps=10, size_px=480)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from crowdsim.files import write_atomic
from envs.drawing.frame import SceneFrame
from envs.drawing.render import render_rgb

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


class _Mp4Sink:
    """Streams (H, W, 3) uint8 frames into an H.264 MP4 through imageio-ffmpeg's ffmpeg process."""

    def __init__(self, path: str, fps: float, size_px: int) -> None:
        self._gen = _ffmpeg().write_frames(path, (size_px, size_px), fps=fps, codec="libx264", quality=6,
                                           macro_block_size=2, output_params=["-f", "mp4"])
        self._gen.send(None)

    def add(self, img: np.ndarray) -> None:
        self._gen.send(np.ascontiguousarray(img))

    def close(self) -> None:
        self._gen.close()


class _GifSink:
    """Collects frames as palette images (about size_px² bytes each) and writes a looping GIF with Pillow."""

    def __init__(self, path: str, fps: float, size_px: int) -> None:
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
    """An episode observer (`log(frame)`, as `RerunObserver`): draws each frame at `size_px` x `size_px` px
    (`view`: the world rectangle, m; default the scene bounds) and hands it to the encoder. `frames`: count."""

    def __init__(self, sink: _Mp4Sink | _GifSink, size_px: int, view: tuple | None = None) -> None:
        self.sink, self.size_px, self.view = sink, size_px, view
        self.frames = 0

    def log(self, frame: SceneFrame) -> None:
        self.sink.add(render_rgb(frame, self.size_px, self.view))
        self.frames += 1


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
        sink = (_Mp4Sink if fmt == "mp4" else _GifSink)(tmp, fps, size_px)
        try:
            out.append(episode(VideoObserver(sink, size_px, view)))
        except BaseException:
            if isinstance(sink, _Mp4Sink):
                sink.close()  # stop ffmpeg; write_atomic removes the partial file
            raise
        sink.close()

    write_atomic(path, write)
    return out[0]


def video_name(policy: str, where: str, seed: int, fmt: str) -> str:
    """`<policy>-<cell or scenario>-seed<k>.<fmt>`, with path separators and colons of plug-in names replaced."""
    clean = [s.replace("/", "_").replace(":", "_").replace(" ", "_") for s in (policy, where)]
    return f"{clean[0]}-{clean[1]}-seed{int(seed)}.{fmt}"
