"""``azimut eval --video``: one video per (controller, track) episode of the first seed, listed in
the report; the flag is checked before any episode runs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jobs.cli import main

pytest.importorskip("pygame")
Image = pytest.importorskip("PIL.Image")


def test_eval_video_writes_a_gif_per_episode_listed_in_the_report(tmp_path, capsys):
    out = tmp_path / "eval"
    rc = main(["eval", "--controllers", "icr", "--tracks", "crab", "--max-time", "1", "--no-plots", "--video",
               "--out", str(out)])
    assert rc == 0
    gif = out / "videos" / "icr-crab-s0.gif"
    with Image.open(gif) as im:
        assert im.n_frames >= 20  # 50 steps, one frame every 2
        assert im.size == (480, 480)
        im.seek(im.n_frames - 1)
        frame = np.asarray(im.convert("RGB"))
        assert frame.std() > 1.0  # something drawn on the background
    assert "videos/icr-crab-s0.gif" in (out / "report.md").read_text()
    videos = json.loads((out / "metrics.json").read_text())["campaign"]["videos"]
    assert videos == {"icr on crab": "videos/icr-crab-s0.gif"}


def test_video_format_refused_before_any_work(tmp_path, capsys, monkeypatch):
    import jobs.eval.video as video

    out = tmp_path / "eval"
    assert main(["eval", "--video", "avi", "--out", str(out)]) == 2
    monkeypatch.setattr(video, "ffmpeg_executable", lambda: None)
    assert main(["eval", "--video", "mp4", "--tracks", "crab", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("azimut eval: error: --video mp4 needs an ffmpeg executable")
    assert not out.exists()


def test_mp4_through_ffmpeg(tmp_path):
    from control.rollout import run_episode
    from jobs.eval.video import ffmpeg_executable, write_video

    if ffmpeg_executable() is None:
        pytest.skip("no ffmpeg executable (PATH or imageio-ffmpeg)")
    log = run_episode("twist", "circle", seed=0, max_time=0.5)
    path = write_video(log, tmp_path / "twist.mp4", fmt="mp4")
    assert path.stat().st_size > 1000 and path.read_bytes()[4:8] == b"ftyp"
    with pytest.raises(ValueError, match="even"):
        write_video(log, tmp_path / "odd.gif", size=301)
