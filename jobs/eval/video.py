"""Videos of evaluated episodes (``azimut eval --video``): the env's top-down view, redrawn from an
:class:`~control.episode.EpisodeLog`, so any controller (the built-ins and trained policies) on any
track gets one without running the episode again.

Each frame is :class:`azimut_env.rendering.Renderer`'s ``rgb_array`` drawing (pygame, the
``render`` extra) of the logged true pose, true steering angles, estimated ICR λ̂ and trail; the
true ICR comes from the chassis twist, a finite difference of the logged poses. A frame is taken
every ``stride`` control steps (at most :data:`MAX_FRAMES` per video) and the video plays at
``speed`` × real time.

Formats: ``gif`` (Pillow, installed with matplotlib) or ``mp4`` (H.264 through an ``ffmpeg``
executable: the one on the PATH, else the one ``imageio-ffmpeg`` ships, which the ``render``
extra's moviepy installs); :func:`check_video_format` says which are usable before any work.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np

__all__ = ["VIDEO_FORMATS", "MAX_FRAMES", "ffmpeg_executable", "check_video_format", "episode_frames", "write_video"]

VIDEO_FORMATS = ("gif", "mp4")
#: most frames per video (the frame stride grows with the episode's length)
MAX_FRAMES = 400


def ffmpeg_executable() -> str | None:
    """An ``ffmpeg`` executable: on the PATH, else ``imageio_ffmpeg``'s; None if neither."""
    exe = shutil.which("ffmpeg")
    if exe:
        return exe
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    try:
        return imageio_ffmpeg.get_ffmpeg_exe()
    except (RuntimeError, OSError):
        return None


def check_video_format(fmt: str) -> None:
    """``ValueError`` (one line) unless videos of format ``fmt`` can be written here: pygame for
    the drawing, Pillow for ``gif``, an ffmpeg executable for ``mp4``."""
    from jobs.args import require_module

    if fmt not in VIDEO_FORMATS:
        raise ValueError(f"--video must be one of {', '.join(VIDEO_FORMATS)}, got {fmt!r}")
    require_module("pygame", "--video (drawing the frames; the render extra)")
    if fmt == "gif":
        require_module("PIL", "--video gif")
    elif ffmpeg_executable() is None:
        raise ValueError("--video mp4 needs an ffmpeg executable (none on the PATH, no imageio-ffmpeg); "
                         "use --video gif")


def _body_twists(pose: np.ndarray, dt: float) -> np.ndarray:
    """(T, 3) chassis-frame twists (ẋ, ẏ, θ̇) from (T, 3) world poses by backward differences (the
    first row repeats the second)."""
    d = np.diff(pose, axis=0, prepend=pose[:1])
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    tw = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1) / dt
    if len(tw) > 1:
        tw[0] = tw[1]
    return tw


def episode_frames(log, params=None, size: int = 480, max_frames: int = MAX_FRAMES):
    """Yield the (size, size, 3) uint8 frames of an episode log, one every :func:`frame_stride`
    control steps and the last one. ``params``: the robot's :class:`~azimut_env.params.RobotParams`
    (default: the env's)."""
    from azimut_env.params import RobotParams
    from azimut_env.rendering import Renderer, Trail

    params = params or RobotParams()
    steps = len(log.pose)
    stride = frame_stride(steps, max_frames)
    renderer = Renderer("rgb_array", size=size)
    try:
        twist = _body_twists(np.asarray(log.pose, dtype=np.float64), log.dt)
        trail = Trail()
        if steps:
            trail.start(*log.pose[0, :2])
        for k in range(steps):
            if k:
                trail.add(*log.pose[k, :2])
            if k % stride and k != steps - 1:
                continue
            lam = log.lam_hat[k] if len(log.lam_hat) == steps else np.array([0.0, 0.0, 1.0])
            yield renderer.draw(track=log.track, pose=log.pose[k], twist=twist[k], beta=log.beta_true[k], lam_hat=lam,
                                trail=trail.points, obstacles=(), chassis=params.chassis, geometry=params.geometry)
    finally:
        renderer.close()


def frame_stride(steps: int, max_frames: int = MAX_FRAMES) -> int:
    """Control steps per frame: 2 (25 frames per simulated second at the default 20 ms period), more
    for long episodes so that a video has at most ``max_frames`` frames."""
    return max(2, math.ceil(steps / max(1, max_frames)))


def write_video(log, path: str | Path, fmt: str = "gif", speed: float = 2.0, size: int = 480, params=None) -> Path:
    """Write the video of ``log`` (an :class:`~control.episode.EpisodeLog`) to ``path`` (format
    ``fmt``, ``speed`` × real time) and return the path. Raises ``ValueError`` on an empty log."""
    check_video_format(fmt)
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be > 0, got {speed!r}")
    if len(log.pose) == 0:
        raise ValueError("the episode log has no steps")
    if size < 16 or size % 2:
        raise ValueError(f"size must be an even number of pixels >= 16, got {size!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stride = frame_stride(len(log.pose))
    fps = speed / (stride * log.dt)  # frames per second of playback
    frames = episode_frames(log, params=params, size=size)
    if fmt == "gif":
        from PIL import Image

        images = [Image.fromarray(f) for f in frames]
        # GIF frame delays are whole centiseconds, and viewers slow delays below 20 ms down
        duration = max(20, int(round(1000.0 / fps / 10.0)) * 10)
        images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0, optimize=False)
        return path
    cmd = [ffmpeg_executable(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
           "-s", f"{size}x{size}", "-r", f"{fps:.6g}", "-i", "-", "-an", "-vcodec", "libx264",
           "-pix_fmt", "yuv420p", str(path)]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for f in frames:
            proc.stdin.write(np.ascontiguousarray(f).tobytes())
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace")
    finally:
        rc = proc.wait()
    if rc != 0:
        raise RuntimeError(f"ffmpeg failed ({rc}): {err.strip()[:200]}")
    return path
