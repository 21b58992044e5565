"""Probing and threaded decoding of the bundled clips: sizes, rates, exact times, plane layout."""

from __future__ import annotations

import shutil
import threading
from fractions import Fraction

import av
import numpy as np
import pytest

from sena_warp.video.reader import FrameReader, plane_array, probe_video


@pytest.fixture(scope="module")
def clips(bundled_dir):
    return bundled_dir / "video"


def test_probe_reports_size_rate_length_and_audio(clips):
    left = probe_video(clips / "rooftop_left.mp4")
    assert (left.width, left.height, left.fps, left.frame_count) == (270, 480, Fraction(30), 60)
    assert left.start_time_s == 0 and abs(left.duration_s - 2.0) < 1e-6
    assert left.has_audio and left.audio_codec == "aac"
    office = probe_video(clips / "office_cam1.mp4")
    assert (office.width, office.height, office.fps, office.pix_fmt) == (640, 480, Fraction(24), "yuv422p")
    assert not office.has_audio and office.audio_codec is None


def test_probe_follows_a_file_that_is_replaced(clips, tmp_path):
    """Probes are kept per version of a file, so one rewritten under the same name is probed again."""
    path = tmp_path / "clip.mp4"
    shutil.copyfile(clips / "rooftop_left.mp4", path)
    assert probe_video(path).width == 270 and probe_video(path).path == path
    shutil.copyfile(clips / "office_cam1.mp4", path)
    assert probe_video(path).width == 640
    assert probe_video(str(path)).path == path  # the caller's name, not the cached one's


def test_frames_carry_exact_times_and_offset(clips):
    with FrameReader(clips / "rooftop_right.mp4", offset_s=Fraction(1, 4)) as reader:
        times = [f.time_s for f in reader]
    assert len(times) == 63 and reader.log.damaged == 0
    assert list(reader) == []  # exhausted: a second pass ends at once instead of waiting
    assert times == [Fraction(1, 4) + Fraction(k, 30) for k in range(63)]


def test_planes_drop_line_padding_and_match_pyav(clips):
    # 270 px wide: chroma is 135 px in rows of 192 bytes, so the copy must respect the stride.
    with av.open(str(clips / "rooftop_left.mp4")) as c:
        frame = next(c.decode(video=0))
        packed = frame.to_ndarray()  # (H * 3/2, W): Y rows, then U and V planes back to back
        bgr_pyav = frame.to_ndarray(format="bgr24")
    assert frame.planes[1].line_size > frame.planes[1].width
    y, u, v = (plane_array(p) for p in frame.planes)
    assert y.shape == (480, 270) and u.shape == v.shape == (240, 135)
    chroma = packed[480:].ravel()
    assert np.array_equal(y, packed[:480])
    assert np.array_equal(u, chroma[: u.size].reshape(u.shape))
    assert np.array_equal(v, chroma[u.size :].reshape(v.shape))
    with FrameReader(clips / "rooftop_left.mp4") as reader:
        first = next(iter(reader))
    assert np.array_equal(first.y, y) and np.array_equal(first.u, u)
    diff = np.abs(first.to_bgr().astype(np.int16) - bgr_pyav)
    assert first.to_bgr().shape == (480, 270, 3) and diff.mean() < 2.0


def test_yuv422_source_is_converted_to_420(clips):
    with FrameReader(clips / "office_cam1.mp4") as reader:
        frames = list(reader)
    assert reader.log.converted_from == "yuv422p" and len(frames) == 48
    assert frames[0].y.shape == (480, 640) and frames[0].u.shape == (240, 320)
    assert frames[-1].time_s == Fraction(47, 24)


def test_stopping_early_joins_the_decoder_thread(clips):
    with FrameReader(clips / "office_cam1.mp4", queue_frames=2) as reader:
        next(iter(reader))
        assert any(t.name == "decode:office_cam1.mp4" for t in threading.enumerate())
    assert not any(t.name == "decode:office_cam1.mp4" for t in threading.enumerate())
    assert reader.log.decoded < 48  # the bounded queue held the decoder back
