"""Episode videos: `envs.drawing.video` and `crowdnav evaluate --video N` (MP4: the video extra; GIF: Pillow)."""

from __future__ import annotations

import itertools
import json
import sys

import numpy as np
import pytest
from PIL import Image

from envs.cli import main
from envs.config import CrowdNavConfig
from envs.drawing.render import BACKGROUND, render_rgb
from envs.drawing.video import INSTALL_HINT, content_box, record_video, video_image
from envs.env import CrowdNavEnv
from envs.evaluation.episode import VideoSpec
from envs.evaluation.evaluate import evaluate
from envs.policies import decide, make_policy
from tests.cli_helpers import run_cli

# the CLI's flags below make exactly this env config (a crowd of 6 keeps the default group sizes)
CONFIG = CrowdNavConfig(scenario="corridor", n_pedestrians=6, time_limit_s=2.0)
SMALL = ["--scenario", "corridor", "--pedestrians", "6", "--time-limit", "2", "--workers", "1", "--no-progress"]


def _cli(args, capsys):
    """(exit code, stderr) of `crowdnav ARGS`."""
    return run_cli(main, args, capsys)


def _mp4(path):
    """(metadata, frames (n, h, w, 3) uint8) of an MP4, decoded with imageio-ffmpeg (the encoder's package)."""
    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return meta, np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen])


def _gif(path):
    """(frames (n, h, w, 3) uint8, per-frame duration ms) of a GIF."""
    im = Image.open(path)
    frames = []
    for k in range(im.n_frames):
        im.seek(k)
        frames.append(np.asarray(im.convert("RGB")))
    return np.stack(frames), im.info["duration"]


def _steps(out, policy, seed):
    episodes = json.loads((out / f"{policy}.json").read_text())["episode_list"]
    return next(e["steps"] for e in episodes if e["seed"] == seed)


def _reset_image(config: CrowdNavConfig, seed: int, size: int, policy: str) -> np.ndarray:
    """What the first video frame must show: the env right after `reset(seed)`, with the policy's first plan."""
    env = CrowdNavEnv(config)
    agent = make_policy(policy, env)
    env.reset(seed=seed)
    agent.reset(seed)
    decide(agent, env)
    return video_image(env.frame(), size)


def test_a_video_frame_is_the_rendered_view_without_the_letterbox_bands():
    env = CrowdNavEnv(CONFIG)  # the corridor: 24 x 4 m (26.4 x 6.4 m with the margin)
    env.reset(seed=0)
    frame = env.frame()
    full = render_rgb(frame, 96)
    r0, r1, c0, c1 = content_box(frame.bounds, 96)
    assert (c0, c1) == (0, 96) and (r1 - r0) % 2 == 0 and 96 * 6.4 / 26.4 <= r1 - r0 < 96 * 6.4 / 26.4 + 2
    outside = np.concatenate([full[:r0], full[r1:]]).reshape(-1, 3)
    assert len(outside) > 0 and (outside == BACKGROUND).all()  # only empty bands are cut
    assert np.array_equal(video_image(frame, 96), full[r0:r1])
    assert content_box((0, 0, 10, 10), 96) == (0, 96, 0, 96)  # a square view keeps the whole image
    assert content_box((0, 0, 4, 10), 96)[2:] == (26, 70)  # tall: 5 x 11 m with the margin, 43.6 -> 44 columns


def test_evaluate_video_writes_one_decodable_mp4_per_policy(tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / "o"
    code = main(["evaluate", "--policy", "random", "social-force", "--episodes", "2", "--video", "1",
                 "--video-size", "96", "--out", str(out), *SMALL])
    assert code == 0, capsys.readouterr().err
    videos = sorted(p.name for p in (out / "videos").iterdir())
    assert videos == ["random-corridor-seed0.mp4", "social-force-corridor-seed0.mp4"]  # only the first episode
    config = CONFIG
    for policy in ("random", "social-force"):
        first = _reset_image(config, 0, 96, policy).astype(int)
        other = _reset_image(config, 1, 96, policy).astype(int)  # another episode's start
        meta, frames = _mp4(out / "videos" / f"{policy}-corridor-seed0.mp4")
        assert meta["size"] == (96, first.shape[0]) and meta["fps"] == pytest.approx(1 / config.dt_s)
        assert len(frames) == _steps(out, policy, 0) + 1  # the reset frame, then one per step
        error = np.abs(frames[0] - first).mean()  # lossy H.264 (thin lines, subsampled colour), yet the reset scene
        assert error < 0.5 * np.abs(frames[0] - other).mean()
        assert np.abs(frames[-1].astype(int) - frames[0]).mean() > error  # and the scene moves
        assert f"videos/{policy}-corridor-seed0.mp4" in json.loads((out / f"{policy}.json").read_text())["run"][
            "files"]


def test_gif_works_without_the_mp4_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # `import imageio_ffmpeg` now raises ImportError
    out = tmp_path / "o"
    code, err = _cli(["evaluate", "--policy", "social-force", "--episodes", "1", "--video", "1", "--out", str(out),
                      *SMALL], capsys)
    assert code == 2 and err.strip().splitlines() == [f"crowdnav: error: {INSTALL_HINT}"]
    assert 'pip install -e ".[video]"' in err and not out.exists()

    code = main(["evaluate", "--policy", "social-force", "--episodes", "2", "--video", "1", "--video-format", "gif",
                 "--video-size", "64", "--out", str(out), *SMALL])
    assert code == 0
    assert [p.name for p in (out / "videos").iterdir()] == ["social-force-corridor-seed0.gif"]
    frames, duration_ms = _gif(out / "videos" / "social-force-corridor-seed0.gif")
    first = _reset_image(CONFIG, 0, 64, "social-force")
    assert frames.shape[1:] == first.shape and first.shape[1] == 64 and duration_ms == 100  # dt 0.1 s
    assert len(frames) == _steps(out, "social-force", 0) + 1
    assert np.abs(frames[0].astype(int) - first).mean() < 1.0  # palette quantisation only


@pytest.mark.parametrize("args, words", [
    (["--video", "-1"], ["--video", "-1"]),
    (["--video", "1", "--video-format", "avi"], ["avi", "mp4", "gif"]),
    (["--video", "1", "--video-size", "101"], ["--video-size", "even", "101"]),
    (["--video", "1", "--video-size", "0"], ["--video-size", "0"]),
    (["--video-format", "gif"], ["--video-format", "--video N"]),
    (["--video-size", "200"], ["--video-size", "--video N"]),
    (["--vidoe", "1"], ["--vidoe"]),
])
def test_bad_video_flags_exit_2_with_one_line_and_write_nothing(tmp_path, capsys, args, words):
    out = tmp_path / "o"
    code, err = _cli(["evaluate", "--policy", "random", "--episodes", "1", "--out", str(out), *SMALL, *args], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert all(w in err for w in words), err
    assert not out.exists()


def test_evaluate_video_needs_an_output_folder():
    with pytest.raises(ValueError, match="output folder"):
        evaluate("random", CrowdNavConfig(n_pedestrians=2, time_limit_s=1.0), episodes=1, video=1, progress=False)
    with pytest.raises(ValueError, match="video >= 0"):
        evaluate("random", CrowdNavConfig(n_pedestrians=2, time_limit_s=1.0), episodes=1, video=-1, progress=False)


def _frames(n: int):
    """n successive frames of an episode (the robot stands still; the people walk)."""
    env = CrowdNavEnv(CrowdNavConfig(scenario="corridor", n_pedestrians=6))
    env.reset(seed=1)
    frames = [env.frame()]
    for _ in range(n - 1):
        env.step(np.zeros(2, np.float32))
        frames.append(env.frame())
    return frames


@pytest.mark.parametrize("fmt", ["gif", "mp4"])
@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError])
def test_an_interrupted_video_leaves_no_file(tmp_path, fmt, stop):
    if fmt == "mp4":
        pytest.importorskip("imageio_ffmpeg")
    frames = _frames(3)

    def episode(observer):
        for f in frames:
            observer.log(f)
        raise stop("stopped mid-episode")

    with pytest.raises(stop):
        record_video(tmp_path / "v" / f"ep.{fmt}", episode, fmt=fmt, fps=10, size_px=32)
    assert list((tmp_path / "v").iterdir()) == []  # neither the video nor a .part file


def test_record_video_returns_the_episode_and_counts_frames(tmp_path):
    frames = _frames(4)
    images = [video_image(f, 64) for f in frames]
    assert not any(np.array_equal(a, b) for a, b in itertools.pairwise(images))  # GIF keeps every frame

    def episode(observer):
        for f in frames:
            observer.log(f)
        return observer.frames

    assert record_video(tmp_path / "a.gif", episode, fmt="gif", fps=20, size_px=64) == 4
    decoded, duration_ms = _gif(tmp_path / "a.gif")
    assert decoded.shape == (4, *images[0].shape) and duration_ms == 50  # 20 frames per second
    assert max(np.abs(d.astype(int) - i).mean() for d, i in zip(decoded, images, strict=True)) < 1.0


@pytest.mark.parametrize("fmt, size", [("avi", 64), ("gif", 63), ("gif", 8)])
def test_bad_video_settings_raise_and_write_nothing(tmp_path, fmt, size):
    with pytest.raises(ValueError, match=r"format|size"):
        VideoSpec(str(tmp_path / "x"), fmt, size)
    with pytest.raises(ValueError, match=r"format|size"):
        record_video(tmp_path / "x", lambda obs: None, fmt=fmt, size_px=size)
    assert not list(tmp_path.iterdir())
