"""The encoder runs as configured (issue 17): the thread type reaches the libx264 that opens.

x264 writes the options it ran with into the stream (an SEI: "x264 - core ... threads=2
lookahead_threads=1 sliced_threads=0 ..."), so the tests read them back from the file written,
not from PyAV's codec context, which only echoes what was set on it.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.video.loop import VideoOptions, run_video
from test_video_loop import SideBySide

THREADS = 2  # x264 turns sliced threads off with one thread, whatever it was asked
X264_THREADS = re.compile(rb"threads=(\d+) lookahead_threads=\d+ sliced_threads=([01])")


def x264_threads(path: Path) -> tuple[int, bool]:
    """(threads, sliced threads) as x264 wrote them into the SEI of the video at ``path``."""
    match = X264_THREADS.search(path.read_bytes())
    assert match, f"{path}: no x264 options SEI in the file"
    return int(match[1]), match[2] == b"1"


@pytest.mark.parametrize("thread_type, sliced", [("slice", True), ("frame", False)])
def test_the_thread_type_reaches_the_opened_encoder(bundled_dir, tmp_path, thread_type, sliced):
    clips, out = bundled_dir / "video", tmp_path / "out.mp4"
    cfg = Config(video_encoder_thread_type=thread_type, cpu_threads=THREADS)
    report = run_video(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", out, SideBySide,
                       VideoOptions.from_config(cfg, audio="none"))
    assert x264_threads(out) == (THREADS, sliced)
    assert report["output"]["encoder"]["thread_type"] == thread_type


def test_an_unknown_thread_type_is_refused_before_any_file_opens(tmp_path):
    with pytest.raises(InputError, match='video_encoder_thread_type = "row" is not one of slice, frame'):
        VideoOptions(thread_type="row")
