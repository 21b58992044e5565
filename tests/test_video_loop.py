"""The video path end to end on the bundled 2 s clips, with a side-by-side compositor of our own.

Checks what a viewer would notice: the frame count, evenly spaced pts at the input rate, audio as
long as the video, frames paired by time (also across frame rates), nothing left behind on failure.
"""

from __future__ import annotations

import json
import logging
import threading
import wave
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest

from sena_warp.errors import InputError, VideoError
from sena_warp.report import write_json
from sena_warp.video.loop import VideoOptions, run_video
from sena_warp.video.pairing import pair_times
from sena_warp.video.reader import FrameReader, YuvFrame, probe_video
from sena_warp.video.writer import VideoWriter, choose_codec
from helpers import decoded_frames, shortened, stream_spans, without_key_frames


class SideBySide:
    """Left frame on the left, right frame on its right, on a black canvas (a real, if simple, stitch)."""

    def __init__(self, pairs: Iterator[tuple[YuvFrame, YuvFrame]]):
        first_l, first_r = next(pairs)
        (self.h_l, self.w_l), (self.h_r, self.w_r) = first_l.y.shape, first_r.y.shape
        self.output_size = (self.w_l + self.w_r, max(self.h_l, self.h_r))

    def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r):
        width, height = self.output_size
        y = np.zeros((height, width), np.uint8)
        y[: self.h_l, : self.w_l] = y_l
        y[: self.h_r, self.w_l :] = y_r
        chroma = []
        for c_l, c_r in ((u_l, u_r), (v_l, v_r)):
            c = np.full(((height + 1) // 2, (width + 1) // 2), 128, np.uint8)
            c[: c_l.shape[0], : c_l.shape[1]] = c_l
            c[: c_r.shape[0], c_l.shape[1] : c_l.shape[1] + c_r.shape[1]] = c_r
            chroma.append(c)
        return y, chroma[0], chroma[1]


class FailsAt(SideBySide):
    """Raises ``error`` on the ``n``-th frame pair, like a crash or Ctrl-C mid-video."""

    n = 10
    error: type[BaseException] = RuntimeError

    def __init__(self, pairs):
        super().__init__(pairs)
        self.calls = 0

    def composite_yuv(self, *planes):
        self.calls += 1
        if self.calls == self.n:
            raise self.error("stop")
        return super().composite_yuv(*planes)


QUIET = VideoOptions()
# Lossless x264 (crf 0): decoding gives back exactly the planes the compositor returned, so two runs'
# frames can be compared bit for bit whatever the encoder's threads did (lossy encodes are not).
LOSSLESS = VideoOptions(crf=0)


@pytest.fixture(scope="module")
def clips(bundled_dir) -> Path:
    return bundled_dir / "video"


def mean_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(a.astype(np.int16) - b.astype(np.int16))))


def test_rooftop_side_by_side_frames_pts_audio_and_pairing(clips, tmp_path):
    left, right, out = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "out.mp4"
    report = run_video(left, right, out, SideBySide, QUIET)

    assert report["frames_in"] == {"left": 60, "right": 63}
    assert report["frames_out"] == 60
    assert report["pairing"]["leftover_other"] == 3  # the right clip is 3 frames longer
    assert report["dropped"] == 0 and report["repeated"] == 0
    assert report["damaged"] == {"left": 0, "right": 0}
    assert report["output"]["audio_mode"] == "copy"
    assert set(report["timing_s"]) == {"decode_wait", "compositor_setup", "composite", "encode", "total", "first_frame"}
    timing = report["timing_s"]
    assert timing["compositor_setup"] < timing["first_frame"] < timing["total"]

    spans = stream_spans(out)
    n_video, t_video, end_video = spans["video"]
    assert n_video == 60
    assert set(np.diff(t_video)) == {Fraction(1, 30)} and t_video[0] == 0
    n_audio, t_audio, end_audio = spans["audio"]
    assert n_audio > 0
    assert abs(float(end_audio - t_audio[0]) - float(end_video)) < 0.1

    # Content: the output's halves are the inputs' frames with the same time (not a neighbour).
    out_frames, in_l, in_r = decoded_frames(out), decoded_frames(left), decoded_frames(right)
    assert out_frames[0].y.shape == (480, 540)
    for k in (5, 30, 59):
        half_l, half_r = out_frames[k].y[:, :270], out_frames[k].y[:, 270:]
        assert mean_abs_diff(half_l, in_l[k].y) < 3.0
        assert mean_abs_diff(half_r, in_r[k].y) < min(mean_abs_diff(half_r, in_r[j].y) for j in (k - 1, k + 1) if j < 63)


class TakesFive(SideBySide):
    """Builds itself from the first five pairs, as an estimate on a few of the first pairs would."""

    def __init__(self, pairs):
        super().__init__(pairs)
        self.taken = [next(pairs) for _ in range(4)]


class TakesNone(SideBySide):
    """Builds itself from what it knows of the rooftop clips, without a frame."""

    def __init__(self, pairs):
        (self.h_l, self.w_l), (self.h_r, self.w_r) = (480, 270), (480, 270)
        self.output_size = (540, 480)


@pytest.mark.parametrize("factory", [TakesFive, TakesNone])
def test_every_pair_is_composited_in_order_whatever_the_factory_took(clips, tmp_path, factory):
    left, right = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4"
    report = run_video(left, right, tmp_path / "taken.mp4", factory, LOSSLESS)
    assert report["frames_in"] == {"left": 60, "right": 63} and report["frames_out"] == 60
    run_video(left, right, tmp_path / "one.mp4", SideBySide, LOSSLESS)
    taken, one = decoded_frames(tmp_path / "taken.mp4"), decoded_frames(tmp_path / "one.mp4")
    assert len(taken) == len(one) == 60
    assert all(np.array_equal(a.y, b.y) and np.array_equal(a.u, b.u) for a, b in zip(taken, one))
    assert not np.array_equal(taken[0].y, taken[4].y)  # the rig moves: a wrong order would show


class FailsBuilding(TakesFive):
    """Takes five pairs, then fails, as an estimate that finds no stitch does."""

    def __init__(self, pairs):
        super().__init__(pairs)
        raise RuntimeError("no estimate")


def test_a_factory_that_fails_after_taking_pairs_leaves_no_output_and_no_decoder(clips, tmp_path):
    with pytest.raises(RuntimeError, match="no estimate"):
        run_video(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "out.mp4", FailsBuilding,
                  QUIET)
    assert list(tmp_path.iterdir()) == []
    assert not [t for t in threading.enumerate() if t.name.startswith("decode:")]


def test_office_yuv422_is_converted_and_missing_audio_is_noted(clips, tmp_path):
    out = tmp_path / "office.mp4"
    report = run_video(clips / "office_cam1.mp4", clips / "office_cam2.mp4", out, SideBySide, QUIET)
    assert report["inputs"]["left"]["converted_from"] == "yuv422p"
    assert report["frames_out"] == 48 and report["output"]["width"] == 1280
    assert report["output"]["audio"] == "none" and "no audio" in report["notes"][0]
    spans = stream_spans(out)
    assert set(spans) == {"video"} and spans["video"][0] == 48
    assert set(np.diff(spans["video"][1])) == {Fraction(1, 24)}


def test_offset_shifts_the_second_input(clips, tmp_path):
    # Right camera "started" 0.25 s late = 6 frames at 24 fps: the first 6 left frames have no partner.
    report = run_video(clips / "office_cam1.mp4", clips / "office_cam2.mp4", tmp_path / "o.mp4", SideBySide,
                       VideoOptions(offset_s=0.25))
    assert report["frames_out"] == 42
    assert report["pairing"]["unpaired_ticks_start"] == 6 and report["pairing"]["leftover_other"] == 6


@pytest.fixture(scope="module")
def right_24fps(clips, tmp_path_factory) -> Path:
    """rooftop_right re-encoded at 24 fps: frame j (at j/24 s) is the 30 fps frame nearest in time."""
    path = tmp_path_factory.mktemp("rate") / "right_24fps.mp4"
    frames = decoded_frames(clips / "rooftop_right.mp4")
    ticks = [Fraction(j, 24) for j in range(int(frames[-1].time_s * 24) + 1)]
    pairs, _ = pair_times(ticks, [f.time_s for f in frames], Fraction(1, 30))
    with VideoWriter(path, 270, 480, Fraction(24)) as writer:
        for j, i in pairs:
            writer.write(frames[i].y, frames[i].u, frames[i].v, pts=j)
    return path


def test_30fps_against_24fps_copy_is_paired_by_time(clips, right_24fps, tmp_path):
    assert probe_video(right_24fps).fps == 24 and probe_video(right_24fps).frame_count == 50
    report = run_video(clips / "rooftop_left.mp4", right_24fps, tmp_path / "mix.mp4", SideBySide, QUIET)
    # ticks k/30 (k < 60) take frame round(0.8 k): 0..47 each used, 12 of them twice; 48, 49 left over.
    assert report["frames_out"] == 60
    assert (report["repeated"], report["dropped"], report["pairing"]["leftover_other"]) == (12, 0, 2)


def test_24fps_ticks_against_30fps_drop_frames_and_copy_the_right_audio(clips, right_24fps, tmp_path):
    out = tmp_path / "mix.mp4"
    options = VideoOptions(audio="right")
    report = run_video(right_24fps, clips / "rooftop_left.mp4", out, SideBySide, options)
    # ticks j/24 pair up to the 30 fps clip's end (59/30 s + half a frame): j <= 47, then 2 left over.
    assert report["frames_out"] == 48 and report["pairing"]["leftover_ticks"] == 2
    assert (report["dropped"], report["repeated"]) == (12, 0)
    spans = stream_spans(out)
    assert set(np.diff(spans["video"][1])) == {Fraction(1, 24)}
    n_audio, t_audio, end_audio = spans["audio"]
    assert abs(float(end_audio - t_audio[0]) - float(spans["video"][2])) < 0.1


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_interrupt_leaves_no_output_and_no_temp_file(clips, tmp_path, error):
    out = tmp_path / "out.mp4"
    failing = type("Failing", (FailsAt,), {"error": error})
    with pytest.raises(error):
        run_video(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", out, failing, QUIET)
    assert list(tmp_path.iterdir()) == []
    assert not [t for t in threading.enumerate() if t.name.startswith("decode:")]


def test_missing_and_non_video_inputs_give_one_line_errors(clips, tmp_path):
    with pytest.raises(InputError, match="file not found") as missing:
        run_video(tmp_path / "nope.mp4", clips / "rooftop_right.mp4", tmp_path / "o.mp4", SideBySide, QUIET)
    text = tmp_path / "notes.mp4"
    text.write_text("not a video at all\n" * 50)
    with pytest.raises(InputError, match="not a readable media file") as garbage:
        run_video(clips / "rooftop_left.mp4", text, tmp_path / "o.mp4", SideBySide, QUIET)
    sound = tmp_path / "tone.wav"
    with wave.open(str(sound), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(8000)
        w.writeframes((np.sin(np.arange(8000) * 0.1) * 8000).astype("<i2").tobytes())
    with pytest.raises(VideoError, match="no video stream") as audio_only:
        run_video(sound, clips / "rooftop_right.mp4", tmp_path / "o.mp4", SideBySide, QUIET)
    for exc in (missing, garbage, audio_only):
        assert "\n" not in str(exc.value)
    assert not (tmp_path / "o.mp4").exists()


def test_odd_output_size_is_cropped_even_and_nvenc_falls_back_with_a_note(clips, tmp_path):
    path = tmp_path / "odd.mp4"
    frames = decoded_frames(clips / "rooftop_left.mp4")[:3]
    with VideoWriter(path, 269, 479, Fraction(30)) as writer:
        for k, f in enumerate(frames):
            writer.write(f.y, f.u, f.v, pts=k)
    assert probe_video(path).width == 268 and probe_video(path).height == 478
    with pytest.raises(VideoError, match="does not increase"):
        with VideoWriter(tmp_path / "bad.mp4", 270, 480, Fraction(30)) as writer:
            writer.write(frames[0].y, frames[0].u, frames[0].v, pts=1)
            writer.write(frames[1].y, frames[1].u, frames[1].v, pts=1)
    codec, note = choose_codec("no_such_encoder", 270, 480, Fraction(30))
    assert codec == "libx264" and "no_such_encoder" in note


def test_library_is_silent_and_counts_frames_on_the_logger(clips, tmp_path, capsys, caplog):
    with caplog.at_level(logging.INFO, logger="sena_warp"):
        run_video(clips / "office_cam1.mp4", clips / "office_cam2.mp4", tmp_path / "a.mp4", SideBySide, QUIET)
    assert capsys.readouterr().err == ""  # no handler configured: nothing on stderr
    stages = [r.stage for r in caplog.records if hasattr(r, "stage")]
    assert stages == ["opening videos", "estimating maps", "stitching frames"]
    last = [r for r in caplog.records if hasattr(r, "count")][-1]
    assert (last.done, last.count.total, last.final) == (48, 48, True)


def test_report_json_round_trips(clips, tmp_path):
    report = run_video(clips / "office_cam1.mp4", clips / "office_cam2.mp4", tmp_path / "o.mp4", SideBySide,
                       VideoOptions(audio="none"))
    write_json(tmp_path / "report.json", report)
    assert json.loads((tmp_path / "report.json").read_text()) == report
    assert report["output_fps"] > 0 and report["notes"] == []


def test_audio_the_output_cannot_hold_is_reencoded_to_aac(clips, tmp_path):
    # Source: rooftop_left's video packets with its audio as pcm_u8 in Matroska (MP4 cannot carry pcm_u8).
    source = tmp_path / "pcm.mkv"
    with av.open(str(clips / "rooftop_left.mp4")) as inp, av.open(str(source), "w") as out:
        a_in = inp.streams.audio[0]
        v_out = out.add_stream_from_template(inp.streams.video[0])
        a_out = out.add_stream("pcm_u8", rate=a_in.codec_context.sample_rate, layout="mono")
        resampler = av.AudioResampler(format="u8", layout="mono", rate=a_in.codec_context.sample_rate)
        for packet in inp.demux():
            if packet.pts is None:
                continue
            if packet.stream.type == "video":
                packet.stream = v_out
                out.mux(packet)
                continue
            for frame in packet.decode():
                for pcm in resampler.resample(frame):
                    out.mux(a_out.encode(pcm))
        out.mux(a_out.encode(None))
    output = tmp_path / "out.mp4"
    report = run_video(source, clips / "rooftop_right.mp4", output, SideBySide, QUIET)
    assert report["output"]["audio_mode"] == "aac" and report["frames_out"] == 60
    with av.open(str(output)) as c:
        assert c.streams.audio[0].codec_context.name == "aac"
    spans = stream_spans(output)
    n_audio, t_audio, end_audio = spans["audio"]
    assert abs(float(end_audio - t_audio[0]) - float(spans["video"][2])) < 0.1


def test_damaged_frames_are_replaced_by_the_last_good_one_up_to_the_next_key_frame(clips, tmp_path):
    """reader.py's policy: a lost packet taints every later frame up to a key frame (the clip has one,
    at frame 0), and each damaged frame is shown as the last good one at its own time."""
    # Overwrite the payload of 3 video packets with noise (the 4-byte NAL length is kept).
    left = clips / "rooftop_left.mp4"
    data = bytearray(left.read_bytes())
    with av.open(str(left)) as c:
        packets = [(p.pos, p.size, p.pts) for p in c.demux(video=0) if p.pts is not None]
    rng = np.random.default_rng(0)
    for pos, size, _ in (packets[10], packets[20], packets[30]):
        data[pos + 4 : pos + size] = rng.integers(0, 256, size - 4, dtype=np.uint8).tobytes()
    damaged = tmp_path / "damaged.mp4"
    damaged.write_bytes(bytes(data))
    first_lost = sorted(p[2] for p in packets).index(min(packets[10][2], packets[20][2], packets[30][2]))
    report = run_video(damaged, clips / "rooftop_right.mp4", tmp_path / "out.mp4", SideBySide, QUIET)
    assert report["damaged"] == {"left": 60 - first_lost, "right": 0}
    assert report["frames_in"]["left"] == first_lost
    # Every tick is kept (the timing holds) and paired as usual.
    assert report["frames_out"] == 60 and report["dropped"] == report["repeated"] == 0
    assert report["warnings"] == [f"left input has {60 - first_lost} damaged frames between "
                                  f"{first_lost / 30:.2f} s and {59 / 30:.2f} s: each replaced by the last good "
                                  f"frame (--strict fails instead)"]
    out = decoded_frames(tmp_path / "out.mp4")
    in_l = decoded_frames(left)
    width = in_l[0].y.shape[1]
    frozen = out[first_lost - 1].y[:, :width]
    assert all(mean_abs_diff(f.y[:, :width], frozen) < 1.0 for f in out[first_lost:])
    assert mean_abs_diff(in_l[-1].y, in_l[first_lost - 1].y) > 5.0  # the camera moved meanwhile


def test_strict_stops_at_the_first_damaged_frame_and_leaves_nothing(clips, tmp_path):
    left = clips / "rooftop_left.mp4"
    data = bytearray(left.read_bytes())
    with av.open(str(left)) as c:
        pos, size = next((p.pos, p.size) for i, p in enumerate(c.demux(video=0)) if i == 20)
    data[pos + 4 : pos + size] = np.random.default_rng(0).integers(0, 256, size - 4, dtype=np.uint8).tobytes()
    damaged = tmp_path / "in" / "damaged.mp4"
    damaged.parent.mkdir()
    damaged.write_bytes(bytes(data))
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(VideoError, match=r"damaged frame at \d+\.\d\d s after \d+ good frames \(--strict\)"):
        run_video(damaged, clips / "rooftop_right.mp4", out / "out.mp4", SideBySide,
                  VideoOptions(strict=True))
    assert list(out.iterdir()) == []


def test_variable_frame_rate_keeps_the_input_frame_times(clips, tmp_path):
    """Frames 20 ms and 50 ms apart in turn: the output's frames sit at the left input's times exactly."""
    gaps_ms = [20, 50] * 15
    times_ms = np.concatenate([[0], np.cumsum(gaps_ms)])
    paths = []
    for name in ("rooftop_left", "rooftop_right"):
        frames = decoded_frames(clips / f"{name}.mp4")[: len(times_ms)]
        path = tmp_path / f"{name}_vfr.mp4"
        with VideoWriter(path, 270, 480, Fraction(30), time_base=Fraction(1, 1000)) as writer:
            for t, f in zip(times_ms, frames):
                writer.write(f.y, f.u, f.v, pts=int(t))
        paths.append(path)
    report = run_video(*paths, tmp_path / "out.mp4", SideBySide, VideoOptions(audio="none"))
    with av.open(str(tmp_path / "out.mp4")) as c:
        stream = c.streams.video[0]
        out_ms = sorted(float(f.pts * stream.time_base) * 1000 for f in c.decode(stream))
    in_ms = [float(f.time_s) * 1000 for f in decoded_frames(paths[0])]
    assert len(out_ms) == len(in_ms) == len(times_ms)
    assert np.abs(np.array(out_ms) - (np.array(in_ms) - in_ms[0])).max() < 0.5
    assert report["dropped"] == report["repeated"] == 0
    assert any("variable frame rate" in note and "20 to 50 ms" in note for note in report["notes"])


@pytest.mark.parametrize("case", ["right ends first", "right starts later"])
def test_left_frames_without_a_right_frame_are_said_not_dropped_silently(clips, tmp_path, caplog, case):
    if case == "right ends first":  # as futsal_night_static: 245 left frames, 239 right
        right, options, count, where = shortened(clips / "rooftop_right.mp4", tmp_path / "r.mp4", 51), QUIET, 9, "last"
    else:
        right, options, count, where = clips / "rooftop_right.mp4", VideoOptions(offset_s=0.2), 6, "first"
    with caplog.at_level(logging.WARNING, logger="sena_warp"):
        report = run_video(clips / "rooftop_left.mp4", right, tmp_path / "o.mp4", SideBySide, options)
    said = (f"the right input {'ends before' if where == 'last' else 'starts after'} the left one: the {where} "
            f"{count} left frames have no right frame and are not in the output")
    assert report["frames_out"] == 60 - count and said in report["notes"]
    assert [r.getMessage() for r in caplog.records].count(said) == 1


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_video_without_key_frames_is_named_not_blamed_on_the_offset(clips, tmp_path, side):
    broken = without_key_frames(clips / f"rooftop_{side}.mp4", tmp_path / "cut.mp4")
    inputs = {"left": clips / "rooftop_left.mp4", "right": clips / "rooftop_right.mp4", side: broken}
    with pytest.raises(VideoError, match=f"{broken}: no frame could be decoded: it holds no key frame") as caught:
        run_video(inputs["left"], inputs["right"], tmp_path / "o.mp4", SideBySide, QUIET)
    assert "offset" not in str(caught.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut.mp4"]


def test_a_trimmed_span_keeps_its_frames_their_pairs_and_its_audio(clips, tmp_path):
    left, right, out = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "out.mp4"
    report = run_video(left, right, out, SideBySide, VideoOptions(start_s=0.5, end_s=1.5))
    assert report["frames_out"] == 30 and report["span_s"] == {"start": 0.5, "end": 1.5}
    assert report["inputs"]["left"]["frames_decoded"] == 30 and report["dropped"] == report["repeated"] == 0
    spans = stream_spans(out)
    n_video, t_video, end_video = spans["video"]
    assert n_video == 30 and t_video[0] == 0 and set(np.diff(t_video)) == {Fraction(1, 30)}
    n_audio, t_audio, end_audio = spans["audio"]
    assert abs(float(end_audio - t_audio[0]) - float(end_video)) < 0.1  # the audio of the span, not of the start
    # The first output frame is the left input's frame at 0.5 s, paired with the right one at that time.
    out_frames, in_l, in_r = decoded_frames(out), decoded_frames(left), decoded_frames(right)
    half_l, half_r = out_frames[0].y[:, :270], out_frames[0].y[:, 270:]
    assert mean_abs_diff(half_l, in_l[15].y) < 3.0 < min(mean_abs_diff(half_l, in_l[k].y) for k in (13, 17))
    assert mean_abs_diff(half_r, in_r[15].y) < min(mean_abs_diff(half_r, in_r[k].y) for k in (14, 16))


@pytest.fixture(scope="module")
def keyed_clip(clips, tmp_path_factory) -> Path:
    """rooftop_left re-encoded with a key frame every 10 frames (the bundled clips have one key frame)."""
    path = tmp_path_factory.mktemp("keyed") / "keyed.mp4"
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=30, options={"g": "10", "x264-params": "keyint=10:min-keyint=10:scenecut=0"})
        stream.width, stream.height, stream.pix_fmt = 270, 480, "yuv420p"
        for k, frame in enumerate(decoded_frames(clips / "rooftop_left.mp4")):
            picture = av.VideoFrame(270, 480, "yuv420p")
            for plane, values in zip(picture.planes, (frame.y, frame.u, frame.v)):
                rows = np.frombuffer(plane, np.uint8).reshape(plane.height, plane.line_size)
                rows[:, : plane.width] = values
            picture.pts = k
            out.mux(stream.encode(picture))
        out.mux(stream.encode(None))
    return path


def test_a_span_s_start_is_reached_by_seeking_and_its_end_stops_decoding(keyed_clip):
    with FrameReader(keyed_clip, span_s=(Fraction(6, 5), Fraction(3, 2))) as reader:
        frames = list(reader)
    # Frames 36-44: the seek lands on the key frame of frame 30, so only 30-35 are decoded before the span.
    assert [f.time_s for f in frames] == [Fraction(k, 30) for k in range(36, 45)]
    assert reader.log.skipped == 6 and reader.log.stopped_at_end and reader.log.decoded == 9
