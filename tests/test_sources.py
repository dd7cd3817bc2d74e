"""The frame iterator: video files, image sequences, live sources that drop frames, rig pairing."""

import threading
import time

import cv2
import numpy as np
import pytest

from aicalib_tf.sources import ImageSequence, LiveSource, VideoFile, is_video, open_source, pair_frames


def _write_video(path, n=12, size=(96, 64)):
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, size)
    for k in range(n):
        img = np.full((size[1], size[0], 3), 20 * k % 255, np.uint8)
        w.write(img)
    w.release()


def test_video_file_yields_every_frame_with_times(tmp_path):
    _write_video(tmp_path / "a.avi")
    assert is_video(tmp_path / "a.avi")
    with open_source(str(tmp_path / "a.avi")) as src:
        frames = list(src)
    assert isinstance(src, VideoFile) and [f.index for f in frames] == list(range(12))
    assert frames[3].time_s == pytest.approx(0.1) and frames[0].gray.shape == (64, 96) and frames[0].gray.dtype == np.uint8


def test_missing_and_garbage_videos_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError) as exc:
        VideoFile(tmp_path / "missing.mp4")
    assert exc.value.filename.endswith("missing.mp4")
    (tmp_path / "junk.mp4").write_bytes(b"not a video at all" * 50)
    with pytest.raises(ValueError, match="junk.mp4: not a readable video"):
        open_source(str(tmp_path / "junk.mp4"))


def test_image_sequence_from_a_folder_counts_unreadable_files(tmp_path):
    for k in range(3):
        cv2.imwrite(str(tmp_path / f"f{k}.png"), np.full((20, 30), 50 * k, np.uint8))
    (tmp_path / "f9.png").write_bytes(b"broken")
    src = open_source(str(tmp_path), fps=10)
    frames = list(src)
    assert isinstance(src, ImageSequence) and [f.index for f in frames] == [0, 1, 2]
    assert frames[2].time_s == pytest.approx(0.2) and src.skipped == 1 and frames[1].gray[0, 0] == 50
    with pytest.raises(ValueError, match="no images found"):
        ImageSequence(str(tmp_path / "*.jpg"))


class _FakeCamera:
    """Frames as fast as a 500 fps camera; ``stop_after`` frames, then read() fails."""

    def __init__(self, stop_after=None, opened=True):
        self.k, self.stop_after, self.opened = 0, stop_after, opened

    def isOpened(self):
        return self.opened

    def read(self):
        time.sleep(0.002)
        if self.stop_after is not None and self.k >= self.stop_after:
            return False, None
        self.k += 1
        return True, np.full((8, 8), self.k % 256, np.uint8)

    def release(self):
        pass


def test_a_live_source_drops_frames_instead_of_queueing_them():
    cam = _FakeCamera()
    src = LiveSource("fake", open_capture=lambda: cam)
    got, lag = [], []
    for frame in src:
        lag.append(src.read_count - 1 - frame.index)  # frames read since this one: a few at most, never a backlog
        got.append(frame.index)
        time.sleep(0.03)  # a slow consumer: many frames arrive per frame taken
        if len(got) == 6:
            break
    src.close()
    assert np.all(np.diff(got) >= 2), got  # gaps, not every frame
    assert src.dropped >= got[-1] - got[0] - 5 > 0 and max(lag) <= 5, (src.dropped, got, lag)


def test_live_source_errors_name_it():
    with pytest.raises(OSError, match="camera 7: cannot open"):
        LiveSource(7, open_capture=lambda: _FakeCamera(opened=False))
    src = LiveSource("rtsp://cam", open_capture=lambda: _FakeCamera(stop_after=3))
    with pytest.raises(OSError, match="rtsp://cam: the stream stopped after 3 frames"):
        for _ in src:
            time.sleep(0.001)
    src.close()
    assert not any(t.name.startswith("reader") and t.is_alive() for t in threading.enumerate())


def test_pairing_by_time_reports_unpaired_and_refuses_drift():
    a = np.arange(60) / 30.0
    b = np.delete(a + 0.004, [10, 11])
    p = pair_frames(a, b, tolerance_s=0.010)
    assert len(p.pairs) == 58 and p.unpaired_a == [10, 11] and p.offset_s == pytest.approx(0.004)
    assert pair_frames(a, b, by="index").unpaired_a == [58, 59]
    with pytest.raises(ValueError, match=r"cam0 and cam1 are out of sync: .* \+0\.012 s apart"):
        pair_frames(a, a + 0.012, tolerance_s=0.010)
    drift = a + np.linspace(0.0, 0.03, 60)  # fine at the start, 30 ms off at the end
    with pytest.raises(ValueError, match="out of sync: from frame"):
        pair_frames(a, drift, tolerance_s=0.010)


def test_a_streams_password_is_never_printed(tmp_path, capsys):
    from aicalib_tf.calibrate import main

    url = "http://user:secret@127.0.0.1:1/cam.mjpg"  # nothing listens on port 1
    with pytest.raises(OSError) as exc:
        LiveSource(url, open_capture=lambda: _FakeCamera(opened=False))
    assert "secret" not in str(exc.value) and "http://user:***@127.0.0.1:1/cam.mjpg" in str(exc.value)
    assert main([url, "--pattern", "9x6", "--out", str(tmp_path / "c"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "secret" not in err and "user:***@127.0.0.1" in err and not (tmp_path / "c").exists()


def _y4m(path, fps_ratio="1:1000", n=3, size=(32, 24)):
    """A tiny y4m video whose header claims the frame rate ``fps_ratio`` (1:1000 is 0.001 fps)."""
    w, h = size
    head = f"YUV4MPEG2 W{w} H{h} F{fps_ratio} Ip A1:1 C420jpeg\n".encode()
    path.write_bytes(head + b"".join(b"FRAME\n" + bytes([40 * k]) * (w * h) + bytes([128]) * (w * h // 2)
                                     for k in range(n)))
    return path


def test_a_frame_rate_out_of_range_is_unknown_and_never_paces_the_live_loop(tmp_path):
    from aicalib_tf.live.server import _paced
    from aicalib_tf.sources import plausible_fps

    assert [plausible_fps(x) for x in (0.001, 0.5, 1, 30, 240, 1000, float("nan"), None, "x")] == \
        [None, None, 1.0, 30.0, 240.0, None, None, None, None]
    with open_source(str(_y4m(tmp_path / "slow.y4m"))) as src:
        assert src.fps is None
        t0 = time.monotonic()
        frames = list(_paced(src, threading.Event()))
    assert len(frames) == 3 and time.monotonic() - t0 < 1.0 and [f.time_s for f in frames] == [0.0, 1.0, 2.0]
    with open_source(str(_y4m(tmp_path / "ok.y4m", "20:1"))) as src:
        t0 = time.monotonic()
        assert src.fps == 20 and len(list(_paced(src, threading.Event()))) == 3
    assert 0.08 < time.monotonic() - t0 < 1.0  # 3 frames at 20 fps: paced, 0.1 s
