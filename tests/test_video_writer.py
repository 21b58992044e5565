"""The encoder runs as configured: the thread type and the rate control reach the encoder that opens.

x264 writes the options it ran with into the stream (an SEI: "x264 - core ... threads=2
lookahead_threads=1 sliced_threads=0 ..."), so the tests read them back from the file written,
not from PyAV's codec context, which only echoes what was set on it.
"""

from __future__ import annotations

import re
from fractions import Fraction
from pathlib import Path

import av
import pytest

from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.video.loop import VideoOptions, run_video
from sena_warp.video.writer import choose_codec
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


# What each encoder wrote into its options SEI for a rate control (x264 with "_", x265 with "-").
RATE_SEI = {"crf": [rb"rc=crf", rb"crf=26\.0"], "bitrate": [rb"rc=abr", rb"bitrate=300"]}
PEAK_SEI = [rb"vbv.maxrate=400", rb"vbv.bufsize=800"]


@pytest.mark.parametrize("codec", ["libx264", "libx265"])
@pytest.mark.parametrize("rate", [dict(crf=26), dict(crf=26, maxrate_kbps=400), dict(bitrate_kbps=300, maxrate_kbps=400)])
def test_the_rate_control_reaches_the_encoder_and_the_report(bundled_dir, tmp_path, codec, rate):
    clips, out = bundled_dir / "video", tmp_path / "out.mp4"
    report = run_video(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", out, SideBySide,
                       VideoOptions(codec=codec, audio="none", **rate))
    data = out.read_bytes()
    mode = "bitrate" if "bitrate_kbps" in rate else "crf"
    peak = PEAK_SEI if "maxrate_kbps" in rate else []
    assert all(re.search(pattern, data) for pattern in RATE_SEI[mode] + peak)
    assert not re.search(rb"vbv.maxrate=[1-9]", data) or peak  # no cap unless asked
    encoder = report["output"]["encoder"]
    assert (encoder["codec"], encoder["rate_control"], encoder["crf"], encoder["bitrate_kbps"],
            encoder["maxrate_kbps"]) == (codec, mode, rate.get("crf"), rate.get("bitrate_kbps"),
                                         rate.get("maxrate_kbps"))
    with av.open(str(out)) as container:  # HEVC in MP4 under the tag players look for
        stream = container.streams.video[0]
        assert (stream.codec_context.name, stream.codec_tag) == (
            {"libx264": ("h264", "avc1"), "libx265": ("hevc", "hvc1")}[codec])


def test_an_average_bit_rate_sets_the_file_s_size(bundled_dir, tmp_path):
    clips, sizes = bundled_dir / "video", {}
    for kbps in (150, 1200):
        out = tmp_path / f"{kbps}.mp4"
        run_video(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", out, SideBySide,
                  VideoOptions(bitrate_kbps=kbps, audio="none"))
        sizes[kbps] = out.stat().st_size * 8 / 1000 / 2.0  # kbit per second of the 2 s clip
    assert sizes[1200] > 3 * sizes[150] and 0.5 * 1200 < sizes[1200] < 1.5 * 1200


def test_hevc_nvenc_falls_back_to_libx265_where_it_cannot_open():
    codec, note = choose_codec("hevc_nvenc", 640, 480, Fraction(30))
    # On a machine whose NVENC opens, it is used; elsewhere its software counterpart, said in a note.
    assert (codec, note) == ("hevc_nvenc", None) or (codec == "libx265" and note.endswith("used libx265"))


def test_a_bad_rate_or_codec_is_refused_before_any_file_opens():
    with pytest.raises(InputError, match=r"video_bitrate_kbps = -5 is out of range \[0, 1000000\]"):
        VideoOptions(bitrate_kbps=-5)
    with pytest.raises(InputError, match='video_codec = "libvpx" is not one of'):
        VideoOptions(codec="libvpx")
