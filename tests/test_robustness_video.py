"""The video path: every bad video input or output through ``sena-warp video`` ends in ONE stderr
line, the right exit code and nothing under the output name (no video, no ``.part`` temp file).

Cases already covered elsewhere are not repeated here: a missing input, a text file, a WAV file,
damaged packets and a crash inside the compositor (``test_video_loop.py``), output == input
(``test_video_stitch.py``). Media are made in ``tmp_path`` from the bundled 2 s clips with PyAV.
Each CLI case runs ``sena_warp.cli.main`` in-process with ``capfd`` (file-descriptor capture, so
anything FFmpeg prints counts too). Decisions taken here (see the README's exit codes):

- inputs of different sizes are stitched (SENA estimates on the frame pair, sizes need not match);
- damaged frames are replaced by the last good one (``reader.py``'s policy) and a truncated input
  (index at the front) is stitched where both inputs have frames; either way ONE warning line on
  stderr says what and when, and ``--strict`` makes it an error (exit 5, nothing written);
- a much shorter clip is stitched where both inputs have frames, without a warning;
- a truncated MP4 whose index (``moov``) was at the end cannot be opened at all: exit 2;
- an image given as a video, like an audio-only file, is refused as having no video: exit 5.
"""

from __future__ import annotations

import json
import threading
from fractions import Fraction

import av
import cv2
import numpy as np
import pytest

from sena_warp.errors import InputError, OutputError, VideoError
from sena_warp.video import reader as video_reader
from sena_warp.video.writer import VideoWriter
from helpers import (assert_one_line_error, damage_the_middle, decoded_frames, index_first, joined_ts_files, run_cli,
                     top_level_box, truncated)

CLIP_FRAMES = {"rooftop_left": 60, "rooftop_right": 63}  # 2.0 s and 2.1 s at 30 fps (see test_video_reader)
FAST = ["--audio", "none", "--crf", "35"]  # the cases are about failures and counts, not quality


@pytest.fixture(scope="module")
def clips(bundled_dir):
    d = bundled_dir / "video"
    return d / "rooftop_left.mp4", d / "rooftop_right.mp4"


def no_decoder_threads() -> bool:
    return not [t for t in threading.enumerate() if t.name.startswith("decode:") and t.is_alive()]


def reencode(src, dst, size=None, max_frames=None):
    """Copy ``src``'s video (no audio) as H.264 at ``size`` (w, h), keeping its first ``max_frames`` and times."""
    with av.open(str(src)) as cin, av.open(str(dst), "w") as cout:
        sin = cin.streams.video[0]
        width, height = size or (sin.codec_context.width, sin.codec_context.height)
        sout = cout.add_stream("libx264", rate=sin.average_rate)
        sout.width, sout.height, sout.pix_fmt = width, height, "yuv420p"
        for i, frame in enumerate(cin.decode(sin)):
            if max_frames is not None and i >= max_frames:
                break
            out = frame.reformat(width=width, height=height, format="yuv420p")
            out.pts, out.time_base = i, 1 / Fraction(sin.average_rate)
            cout.mux(sout.encode(out))
        cout.mux(sout.encode(None))
    return dst


def audio_only(dst, seconds=0.5, rate=48000):
    """A mono AAC tone in an MP4 (``.m4a``) container: a real media file without a video stream."""
    samples_per_frame = 1024
    with av.open(str(dst), "w") as c:
        stream = c.add_stream("aac", rate=rate, layout="mono")
        for i in range(int(seconds * rate) // samples_per_frame):
            t = (np.arange(samples_per_frame) + i * samples_per_frame) / rate
            frame = av.AudioFrame.from_ndarray(0.3 * np.sin(2 * np.pi * 440 * t)[None].astype(np.float32),
                                               format="fltp", layout="mono")
            frame.sample_rate, frame.pts = rate, i * samples_per_frame
            c.mux(stream.encode(frame))
        c.mux(stream.encode(None))
    return dst


def decoded_count(path) -> int:
    with av.open(str(path)) as c:
        return sum(1 for _ in c.decode(video=0))


def stitch_ok(argv, folder_out, capfd, warp_device, *warning_words):
    """Run a stitch that must succeed; return (report, output path). Each note and warning of the
    report was also said on stderr, as one warning line, and nothing else was. With
    ``warning_words``: exactly one warning, holding them all."""
    out, report_path = folder_out / "pano.mp4", folder_out / "report.json"
    rc, err, _ = run_cli(["video", *argv, "-o", out, "--report", report_path, *FAST], capfd, warp_device)
    assert rc == 0, err
    report = json.loads(report_path.read_text())
    assert sorted(err) == sorted(f"sena-warp: warning: {text}" for text in report["notes"] + report["warnings"])
    if warning_words:
        assert len(report["warnings"]) == 1, report["warnings"]
        assert all(word in report["warnings"][0] for word in warning_words), (warning_words, report["warnings"])
    else:
        assert report["warnings"] == []
    return report, out


# --- inputs that are not videos: exit 5, nothing written -------------------------------------------

@pytest.mark.parametrize("case", ["audio_only_aac", "png_image", "jpeg_image"])
def test_input_without_video_is_refused_in_one_line(case, clips, bundled_dir, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    bad = {
        "audio_only_aac": lambda: audio_only(folder_in / "tone.m4a"),
        "png_image": lambda: bundled_dir / "graf_gt" / "a.png",
        "jpeg_image": lambda: bundled_dir / "udisd_test_000001" / "a.jpg",
    }[case]()
    rc, err, _ = run_cli(["video", clips[0], bad, "-o", folder_out / "pano.mp4"], capfd, warp_device)
    assert rc == VideoError.exit_code
    assert_one_line_error(err, str(bad), "give a video file")
    assert ("no video stream" if case == "audio_only_aac" else "is an image") in err[0]
    assert list(folder_out.iterdir()) == []


# --- inputs of different resolutions: stitched ------------------------------------------------------

def test_inputs_of_different_sizes_are_stitched(clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    small = reencode(clips[1], folder_in / "small.mp4", size=(202, 360))
    report, out = stitch_ok([clips[0], small], folder_out, capfd, warp_device)
    sizes = {side: (report["inputs"][side]["width"], report["inputs"][side]["height"]) for side in ("left", "right")}
    assert sizes == {"left": (270, 480), "right": (202, 360)}
    assert report["frames_out"] == CLIP_FRAMES["rooftop_left"] and report["dropped"] == report["repeated"] == 0
    # A real stitch on the canvas of the unwarped (target) input: wider than it, and every frame decodes.
    target = "right" if report["stitch"]["rig"]["source"] == "left" else "left"
    assert report["output"]["width"] > sizes[target][0] and report["output"]["height"] >= sizes[target][1] - 1
    assert decoded_count(out) == report["frames_out"]


# --- inputs damaged or cut short: stitched where both have frames, losses counted ---------------

def test_corruption_in_the_middle_is_replaced_counted_and_warned(clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    bad = damage_the_middle(clips[1], folder_in / "damaged.mp4")
    report, out = stitch_ok([clips[0], bad], folder_out, capfd, warp_device, "right input has", "damaged frames",
                            "replaced by the last good frame", "--strict")
    damaged, decoded = report["damaged"]["right"], report["frames_in"]["right"]
    assert damaged > 0 and report["damaged"]["left"] == 0
    assert decoded + damaged == CLIP_FRAMES["rooftop_right"]
    first, last = report["inputs"]["right"]["damaged_span_s"]
    assert report["warnings"] == [f"right input has {damaged} damaged frames between {first:.2f} s and {last:.2f} s: "
                                  f"each replaced by the last good frame (--strict fails instead)"]
    # Every left frame is output, each right one paired at its own time.
    assert report["frames_out"] == CLIP_FRAMES["rooftop_left"]
    assert decoded_count(out) == report["frames_out"]


@pytest.mark.parametrize("case", ["damaged", "truncated"])
def test_strict_turns_damage_and_truncation_into_exit_5_and_writes_nothing(case, clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    if case == "damaged":
        bad = damage_the_middle(clips[1], folder_in / "damaged.mp4")
        words = ("damaged frame at", "(--strict)")
    else:
        bad = truncated(index_first(clips[1], folder_in / "whole.mp4"), folder_in / "cut.mp4")
        words = ("right input ended after", "truncated?", "(--strict)")
    before = bad.read_bytes()
    rc, err, _ = run_cli(["video", clips[0], bad, "-o", folder_out / "pano.mp4", "--report", folder_out / "r.json",
                          "--strict", *FAST], capfd, warp_device)
    assert rc == VideoError.exit_code
    assert_one_line_error(err, *words)
    assert list(folder_out.iterdir()) == []
    assert bad.read_bytes() == before


def test_truncated_file_with_index_at_the_end_cannot_be_opened(clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    assert top_level_box(clips[1].read_bytes(), b"mdat")[0] < clips[1].read_bytes().find(b"moov")
    cut = truncated(clips[1], folder_in / "cut.mp4")
    rc, err, _ = run_cli(["video", clips[0], cut, "-o", folder_out / "pano.mp4"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, str(cut), "not a readable media file", "may be truncated or corrupt")
    assert list(folder_out.iterdir()) == []


def test_truncated_file_with_index_first_stitches_what_is_there(clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    cut = truncated(index_first(clips[1], folder_in / "whole.mp4"), folder_in / "cut.mp4")
    report, out = stitch_ok([clips[0], cut], folder_out, capfd, warp_device, "right input ended after", "truncated?")
    decoded = report["frames_in"]["right"]
    assert 0.4 * CLIP_FRAMES["rooftop_right"] < decoded < 0.7 * CLIP_FRAMES["rooftop_right"]
    assert report["frames_out"] == decoded
    assert report["pairing"]["leftover_ticks"] == CLIP_FRAMES["rooftop_left"] - decoded
    assert any("right input ended after" in warning and "truncated" in warning for warning in report["warnings"])
    assert decoded_count(out) == report["frames_out"]


@pytest.mark.parametrize("short_side", ["left", "right"])
def test_much_shorter_input_stitches_the_overlap_in_time(short_side, clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    short_frames = 9  # 0.3 s at 30 fps
    long_side = "right" if short_side == "left" else "left"
    paths = {"left": clips[0], "right": clips[1]}
    paths[short_side] = reencode(paths[short_side], folder_in / "short.mp4", max_frames=short_frames)
    report, out = stitch_ok([paths["left"], paths["right"]], folder_out, capfd, warp_device)
    long_frames = CLIP_FRAMES[paths[long_side].stem]
    assert report["frames_in"] == {short_side: short_frames, long_side: long_frames}
    assert report["frames_out"] == short_frames and report["repeated"] == report["dropped"] == 0
    leftover = report["pairing"]["leftover_ticks" if long_side == "left" else "leftover_other"]
    assert leftover == long_frames - short_frames
    assert decoded_count(out) == short_frames


@pytest.mark.parametrize("offset", ["5", "-2.5"])
def test_inputs_that_do_not_overlap_in_time_are_refused(offset, clips, dirs, capfd, warp_device):
    _, folder_out = dirs
    rc, err, _ = run_cli(["video", *clips, "-o", folder_out / "pano.mp4", "--offset", offset], capfd, warp_device)
    assert rc == VideoError.exit_code
    assert_one_line_error(err, "no frames overlap in time", f"offset {float(offset)} s", "--offset")
    assert list(folder_out.iterdir()) == []
    assert no_decoder_threads()


def test_mismatched_frame_rates_are_noted_in_the_report(clips, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    slow = folder_in / "right_15fps.mp4"
    with av.open(str(clips[1])) as cin, av.open(str(slow), "w") as cout:
        sin = cin.streams.video[0]
        sout = cout.add_stream("libx264", rate=15)
        sout.width, sout.height, sout.pix_fmt = sin.codec_context.width, sin.codec_context.height, "yuv420p"
        for i, frame in enumerate(list(cin.decode(sin))[::2]):  # every other frame, same times
            frame.pts, frame.time_base = i, Fraction(1, 15)
            cout.mux(sout.encode(frame))
        cout.mux(sout.encode(None))
    report, _ = stitch_ok([clips[0], slow], folder_out, capfd, warp_device)
    assert report["inputs"]["right"]["fps"] == 15.0
    assert report["frames_out"] == CLIP_FRAMES["rooftop_left"]
    assert report["repeated"] >= 25  # 30 ticks a second against 15 frames: about every other one
    note = [n for n in report["notes"] if "frame rates differ" in n]
    assert len(note) == 1 and "30" in note[0] and "15" in note[0] and f"{report['repeated']} repeated" in note[0]


# --- Ctrl-C or a crash while encoding: exit 130 / an exception, nothing left ------------------------

FRAMES_BEFORE_FAILURE = 5


@pytest.fixture
def encoder_fails(monkeypatch):
    """Make ``VideoWriter.write`` raise ``error`` after ``FRAMES_BEFORE_FAILURE`` frames were encoded."""
    def install(error: type[BaseException]):
        real_write = VideoWriter.write

        def write(self, *planes, pts):
            if self.frames == FRAMES_BEFORE_FAILURE:
                raise error("stopped while encoding")
            real_write(self, *planes, pts=pts)
        monkeypatch.setattr(VideoWriter, "write", write)
    return install


def test_ctrl_c_while_encoding_exits_130_and_leaves_nothing(clips, dirs, capfd, warp_device, encoder_fails):
    _, folder_out = dirs
    encoder_fails(KeyboardInterrupt)
    rc, err, _ = run_cli(["video", *clips, "-o", folder_out / "pano.mp4", "--report", folder_out / "r.json"],
                         capfd, warp_device)
    assert rc == 130
    assert err == ["sena-warp: interrupted"]
    assert list(folder_out.iterdir()) == []
    assert no_decoder_threads()


def test_crash_while_encoding_propagates_and_leaves_nothing(clips, dirs, capfd, warp_device, encoder_fails):
    _, folder_out = dirs
    encoder_fails(RuntimeError)
    with pytest.raises(RuntimeError, match="stopped while encoding"):  # a traceback, exit 1, as an uncaught error
        run_cli(["video", *clips, "-o", folder_out / "pano.mp4"], capfd, warp_device)
    assert list(folder_out.iterdir()) == []
    assert no_decoder_threads()


# --- bad output paths: refused before any input is opened ---------------------------------------------

@pytest.fixture
def no_input_opened(monkeypatch):
    """Fail the test if any input is opened for decoding (every probe and reader goes through open_input;
    the probes kept from earlier tests are dropped)."""
    video_reader._probe_version.cache_clear()

    def refuse(path):
        raise AssertionError(f"{path} was opened before the output paths were checked")
    monkeypatch.setattr(video_reader, "open_input", refuse)


OUTPUT_CASES = {
    # name: (argv after the inputs given the output folder, words in the message)
    "missing_folder": (lambda out: ["-o", out / "nope" / "pano.mp4"], ("does not exist",)),
    "existing_folder": (lambda out: ["-o", (out / "pano.mp4").mkdir() or out / "pano.mp4"], ("is a folder",)),
    "report_in_missing_folder": (lambda out: ["-o", out / "pano.mp4", "--report", out / "nope" / "r.json"],
                                 ("r.json", "does not exist")),
    "report_is_a_folder": (lambda out: ["-o", out / "pano.mp4", "--report", (out / "r.json").mkdir() or out / "r.json"],
                           ("r.json", "is a folder")),
}
@pytest.mark.parametrize("case", list(OUTPUT_CASES))
def test_bad_output_path_is_refused_before_decoding(case, clips, dirs, capfd, warp_device, no_input_opened):
    _, folder_out = dirs
    make_args, words = OUTPUT_CASES[case]
    args = make_args(folder_out)
    before = sorted(p.name for p in folder_out.iterdir())
    inputs_before = [p.read_bytes() for p in clips]
    rc, err, _ = run_cli(["video", *clips, *args], capfd, warp_device)
    assert rc == OutputError.exit_code
    assert_one_line_error(err, *words)
    assert sorted(p.name for p in folder_out.iterdir()) == before  # no video, no temp file
    assert [p.read_bytes() for p in clips] == inputs_before


# --- time stamps that go back or repeat, a resolution that changes: said, never squeezed --------------------

@pytest.fixture(scope="module")
def joined(clips, tmp_path_factory):
    """The joined TS files (``helpers.joined_ts_files``) of the bundled clips."""
    left, right = (decoded_frames(clip) for clip in clips)
    return joined_ts_files(left, right, tmp_path_factory.mktemp("joined"))


def output_times_s(path) -> list[float]:
    with av.open(str(path)) as c:
        stream = c.streams.video[0]
        return sorted(float(p.pts * stream.time_base) for p in c.demux(stream) if p.pts is not None)


@pytest.mark.parametrize("case, dropped, first", [("back", 60, "0.000 s after 1.967 s"),
                                                   ("repeated", 4, "0.300 s after 0.300 s")])
def test_time_stamps_that_go_back_or_repeat_are_dropped_and_said_never_squeezed(case, dropped, first, joined, clips,
                                                                                  dirs, capfd, warp_device):
    _, folder_out = dirs
    bad = joined / f"{case}.ts"
    before = bad.read_bytes()
    report, out = stitch_ok([bad, clips[1]], folder_out, capfd, warp_device, f"left input has {dropped} frames whose "
                            f"time stamps go back or repeat (the first: {first})", "dropped", "--strict")
    assert report["inputs"]["left"]["time_stamps_dropped"] == dropped
    assert report["frames_in"]["left"] == {"back": 60, "repeated": 56}[case]
    times = output_times_s(out)
    assert len(times) == report["frames_out"] and np.diff(times).min() > 1 / 30 - 1e-3  # no frame squeezed in
    assert bad.read_bytes() == before
    rc, err, _ = run_cli(["video", bad, clips[1], "-o", folder_out / "strict.mp4", "--strict", *FAST], capfd,
                         warp_device)
    assert rc == VideoError.exit_code
    assert_one_line_error(err, str(bad), "frame time stamps", "(--strict)")
    assert sorted(p.name for p in folder_out.iterdir()) == ["pano.mp4", "report.json"]


def test_a_resolution_change_mid_stream_is_rescaled_to_the_first_size_and_said(joined, dirs, capfd, warp_device):
    _, folder_out = dirs
    resized, right = joined / "resized.ts", joined / "right_4s.ts"
    # --rig static: the same maps on both halves (a moving rig's alignment differs from frame to frame).
    report, out = stitch_ok([resized, right, "--rig", "static"], folder_out, capfd, warp_device,
                            "left input changes resolution from 270x480 to 540x960 at 2.00 s",
                            "60 frames were rescaled to 270x480", "--strict")
    assert report["inputs"]["left"]["rescaled"] == 60 and report["frames_out"] == 120
    frames = decoded_frames(out)
    # The second half is the first one's content at twice the size: rescaled, it stitches as the first half did
    # (before: a magnified corner of the frame from 2 s on). Not to the pixel: by then the per-frame seam's
    # background models have learnt 2 s of video, and its seam may lie elsewhere (measured 31-33 dB, 27.1 at
    # one frame of ten, whose seam runs elsewhere in a bush).
    psnr = [cv2.PSNR(frames[i].y, frames[i + 60].y) for i in range(0, 60, 6)]
    assert np.median(psnr) > 30 and min(psnr) > 24, [round(p, 1) for p in psnr]
    rc, err, _ = run_cli(["video", resized, right, "-o", folder_out / "strict.mp4", "--strict", *FAST], capfd,
                         warp_device)
    assert rc == VideoError.exit_code
    assert_one_line_error(err, "the resolution changes from 270x480 to 540x960 at 2.00 s (--strict)")
    assert sorted(p.name for p in folder_out.iterdir()) == ["pano.mp4", "report.json"]
