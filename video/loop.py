"""The paired-video loop: decode both inputs in threads, pair by time, composite, encode.

The stitch itself is not in here: the loop takes a *frame compositor*, built once from the first
pairs of frames it takes (that is where a real stitch estimates its maps: "cached warps, per-frame
seam slicing", docs/method.md "Maps, not images"; the pairs it took are composited after), then called for
every pair on YUV 4:2:0 planes, so frames never go through RGB on the hot path.
"""

from __future__ import annotations

import os
import queue
import threading
import time
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from fractions import Fraction
from itertools import chain
from operator import attrgetter
from typing import Callable, Protocol

import numpy as np

from ..config import Config, is_seconds
from ..config_file import check_value
from ..errors import InputError, VideoError
from ..outputs import OutputPlan, staged
from ..progress import LOGGER, Count, stage
from .pairing import PairingStats, pair_by_time
from .reader import FrameReader, VideoInfo, YuvFrame, probe_video, span_of
from .writer import VideoWriter

VFR_SPREAD = Fraction(3, 2)  # longest / shortest frame interval above this: a variable frame rate (noted)
_POLL_S = 0.1  # how often a blocked producer re-checks that the encoder thread is still alive


class FrameCompositor(Protocol):
    """Turns one pair of YUV 4:2:0 frames into one output frame.

    ``output_size`` is ``(width, height)`` of the output in pixels. ``composite_yuv`` takes the left
    and right planes (``y (H, W)``, ``u, v (ceil(H/2), ceil(W/2))``, uint8, ``plane[row, col]``) and
    returns the output's ``(y, u, v)`` planes of ``output_size`` (chroma halved, rounded up), as
    arrays it will not touch again: they are encoded on another thread while the next pair composites.

    Optionally it has ``update(frame_l, frame_r)``, called on the main thread before each pair is
    composited (e.g. to re-estimate its maps between frames); its time is reported as ``maps_update``.
    And optionally ``look_ahead(frame_l, frame_r)`` with ``lookahead_frames``: each pair is shown to
    it that many pairs before it is composited (the pairs in between are held).
    """

    output_size: tuple[int, int]

    def composite_yuv(
        self, y_l: np.ndarray, u_l: np.ndarray, v_l: np.ndarray, y_r: np.ndarray, u_r: np.ndarray, v_r: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


CompositorFactory = Callable[[Iterator[tuple[YuvFrame, YuvFrame]]], FrameCompositor]
"""Builds the compositor from the video's first (left, right) pairs of frames (e.g. by estimating maps
on a few of them): it takes as many as it needs from the iterator (none at all is fine). Every pair is
composited all the same, so those it took are held (decoded once) until then: the factory bounds how
much of a video it holds by how many it takes."""


@dataclass(frozen=True)
class VideoOptions:
    """Settings of one video run.

    ``offset_s`` shifts the right (second) input's clock: its frame at time t is paired as if it
    were at t + offset_s (+0.5: the right camera started 0.5 s after the left one). ``start_s`` /
    ``end_s``: the span of the left input's time (after the offset) that is stitched, [start, end);
    ``end_s`` 0: to the end. ``audio``: whose audio to copy. ``crf`` (constant quality) or
    ``bitrate_kbps`` (an average rate), either capped at ``maxrate_kbps`` (0: no cap).
    ``threads``: decoder and encoder threads (0: FFmpeg chooses); ``thread_type``: how
    libx264 uses its threads (``Config.video_encoder_thread_type``). ``strict``: a
    damaged frame, a truncated input or audio left out fails the run (VideoError) instead of a
    warning. ``max_megapixels``: larger frames are refused. Values are checked here (InputError),
    before any file is opened.
    """

    offset_s: float = 0.0
    start_s: float = Config.video_start_s
    end_s: float = Config.video_end_s
    audio: str = Config.video_audio
    codec: str = Config.video_codec
    crf: int = Config.video_crf
    bitrate_kbps: int = Config.video_bitrate_kbps
    maxrate_kbps: int = Config.video_maxrate_kbps
    preset: str = Config.video_preset
    thread_type: str = Config.video_encoder_thread_type
    queue_frames: int = Config.video_queue_frames
    threads: int = Config.cpu_threads
    strict: bool = False
    max_megapixels: float = Config.max_input_megapixels

    def __post_init__(self) -> None:
        if not is_seconds(self.offset_s):
            raise InputError(f"offset {self.offset_s!r} s is not a time; give a finite number of seconds (--offset)")
        # The encoder and span settings take the values of their Config fields, checked by the same rule.
        for name, value in (("video_audio", self.audio), ("video_crf", self.crf), ("video_preset", self.preset),
                            ("video_encoder_thread_type", self.thread_type), ("video_codec", self.codec),
                            ("video_bitrate_kbps", self.bitrate_kbps), ("video_maxrate_kbps", self.maxrate_kbps),
                            ("video_start_s", self.start_s), ("video_end_s", self.end_s)):
            check_value(name, value, "video options")
        if self.end_s and self.end_s <= self.start_s:
            raise InputError(f"the span ends at {self.end_s:g} s, not after its start at {self.start_s:g} s; "
                             f"give --to after --ss (or a positive -t)")

    @classmethod
    def from_config(cls, cfg: Config, **changes) -> "VideoOptions":
        """Options taking their span, encoder, queue and thread settings from ``cfg``."""
        base = dict(start_s=cfg.video_start_s, end_s=cfg.video_end_s, audio=cfg.video_audio, codec=cfg.video_codec,
                    crf=cfg.video_crf, bitrate_kbps=cfg.video_bitrate_kbps, maxrate_kbps=cfg.video_maxrate_kbps,
                    preset=cfg.video_preset, thread_type=cfg.video_encoder_thread_type,
                    queue_frames=cfg.video_queue_frames, threads=cfg.cpu_threads,
                    max_megapixels=cfg.max_input_megapixels)
        return cls(**{**base, **changes})



def _input_summary(info: VideoInfo, reader: FrameReader) -> dict:
    span = reader.log.damaged_span_s
    return {
        "path": str(info.path), "width": info.width, "height": info.height, "fps": float(info.fps),
        "rotation_deg": info.rotation_deg, "pix_fmt": info.pix_fmt, "converted_from": reader.log.converted_from,
        "offset_s": float(reader.offset_s), "frames_decoded": reader.log.decoded, "frames_skipped": reader.log.skipped,
        "damaged": reader.log.damaged,
        "damaged_span_s": None if span is None else [round(float(t), 4) for t in span],
        "time_stamps_dropped": reader.log.out_of_order, "rescaled": reader.log.rescaled,
        "decode_wait_s": round(reader.log.wait_s, 4), "decode_s": round(reader.log.decode_s, 4),
        "decoder_threads": reader.log.decoder_threads,
    }


def run_video(
    left: str | os.PathLike,
    right: str | os.PathLike,
    output: str | os.PathLike,
    compositor_factory: CompositorFactory,
    options: VideoOptions,
    plan: OutputPlan | None = None,
) -> dict:
    """Stitch two videos frame pair by frame pair into ``output``; return the run's report.

    Output frames follow the left input's frames (its times, exactly: also a variable frame rate);
    each is paired with the right frame nearest in time (see ``pairing.py``). Only the frames of
    ``options``' span are decoded (a start is reached by seeking). The output appears
    under its name only once complete (with ``plan``: when the plan commits). Report keys:
    ``frames_in``, ``frames_out``, ``dropped``, ``repeated``, ``damaged`` (per input), ``pairing``
    (all counts), ``span_s`` (the trimmed span asked for: start, end or None), ``started`` (when the
    run began, ISO 8601 UTC), ``timing_s`` (decode_wait, compositor_setup, first_frame, composite,
    encode, total; maps_update when the compositor has ``update``), ``output_fps``, ``inputs``,
    ``output``, ``notes``, and ``warnings``: what a user must hear about (damaged frames, a truncated
    input, audio left out), one sentence each; with ``options.strict`` those raise VideoError instead.
    """
    with staged(plan, output, (left, right)) as plan:  # the output is checked before any input is opened
        return _run(left, right, output, compositor_factory, options, plan)


def run_still(left: str | os.PathLike, right: str | os.PathLike, output: str | os.PathLike,
              compositor_factory: CompositorFactory, options: VideoOptions, plan: OutputPlan | None = None) -> dict:
    """Write the stitched frame at ``options.start_s`` (the first pair of the span) as the image ``output``
    (.png or .jpg, by its suffix) and stop: a look at the rig in about the time of the estimate. The
    compositor is built as :func:`run_video` builds it, so the frame is the one a video from there
    would start with. Report keys: ``still`` (the left and right frames' times), ``started``,
    ``span_s``, ``timing_s`` (compositor_setup, composite, total), ``inputs``, ``output`` (path,
    width, height), ``notes``, ``warnings``.
    """
    from ..imageio import write_image

    with staged(plan, output, (left, right)) as plan:
        t_run = time.perf_counter()
        started = datetime.now(timezone.utc)
        infos = _probed(left, right, options)
        stats = PairingStats()
        with _paired(left, right, infos, options, stats) as (readers, first, pairs):
            t0 = time.perf_counter()
            stage("estimating maps")
            compositor = compositor_factory(chain([first], pairs))  # the pairs it takes are not shown
            t1 = time.perf_counter()
            update = getattr(compositor, "update", None)
            if update is not None:
                update(*first)
            y, u, v = compositor.composite_yuv(first[0].y, first[0].u, first[0].v, first[1].y, first[1].u, first[1].v)
            image = YuvFrame(first[0].time_s, 0, y, u, v).to_bgr()
            t2 = time.perf_counter()
        stage("writing outputs")
        write_image(output, image, plan=plan)
        timing = {"compositor_setup": t1 - t0, "composite": t2 - t1, "total": time.perf_counter() - t_run}
        return {"started": started.isoformat(timespec="microseconds"),
                "still": {"left_time_s": float(first[0].time_s), "right_time_s": float(first[1].time_s)},
                "span_s": _span_report(options), "timing_s": {k: round(v, 4) for k, v in timing.items()},
                "inputs": {side: _input_summary(infos[side], reader) for side, reader in zip(SIDES, readers)},
                "output": {"path": str(output), "width": int(image.shape[1]), "height": int(image.shape[0])},
                "notes": [], "warnings": []}


SIDES = ("left", "right")


def _probed(left, right, options: VideoOptions) -> dict[str, VideoInfo]:
    """Both inputs probed ("left", "right"), their frames checked against ``options.max_megapixels``."""
    stage("opening videos")
    return {"left": probe_video(left, options.max_megapixels), "right": probe_video(right, options.max_megapixels)}


@contextmanager
def _paired(left, right, infos: dict[str, VideoInfo], options: VideoOptions, stats: PairingStats):
    """Both inputs decoding over ``options``' span and paired by time: ((left reader, right reader), the
    first pair, an iterator of the pairs after it). The right input's span is a frame wider each side,
    so the left frames at its ends have their nearest right frame."""
    period_r = 1 / infos["right"].fps
    with FrameReader(left, Fraction(0), options.queue_frames, options.threads, options.strict,
                     span_of(options.start_s, options.end_s)) as reader_l, \
            FrameReader(right, Fraction(str(options.offset_s)), options.queue_frames, options.threads,
                        options.strict, span_of(options.start_s, options.end_s, period_r)) as reader_r:
        pairs = pair_by_time(reader_l, reader_r, period_r, attrgetter("time_s"), stats)
        first = next(pairs, None)
        trimmed = f" between --ss {options.start_s:g} s and --to {options.end_s:g} s" if options.end_s else (
            f" from --ss {options.start_s:g} s on" if options.start_s else "")
        undecoded = [path for path, reader in ((left, reader_l), (right, reader_r)) if not reader.log.decoded + reader.log.damaged]
        if first is None and undecoded and not trimmed:
            raise VideoError(f"{undecoded[0]}: no frame could be decoded: it holds no key frame (as a piece cut out of a "
                             f"longer stream may not); re-encode it")
        if first is None:
            raise VideoError(f"{left} and {right}: no frames overlap in time{trimmed} with offset "
                             f"{options.offset_s} s; check --offset{', --ss and --to' if trimmed else ''}")
        yield (reader_l, reader_r), first, pairs


def _span_report(options: VideoOptions) -> dict:
    return {"start": options.start_s or None, "end": options.end_s or None}


def _run(left, right, output, compositor_factory: CompositorFactory, options: VideoOptions,
         plan: OutputPlan) -> dict:
    t_run = time.perf_counter()
    started = datetime.now(timezone.utc)
    infos = _probed(left, right, options)
    offsets = {"left": Fraction(0), "right": Fraction(str(options.offset_s))}
    notes: list[str] = []
    audio_side = None if options.audio == "none" else options.audio
    if audio_side is not None and not infos[audio_side].has_audio:
        _note(notes, f"{audio_side} input has no audio: output has none")
        audio_side = None
    rate = infos["left"].fps
    stats = PairingStats()
    timing = {"compositor_setup": 0.0, "composite": 0.0, "encode": 0.0}

    with _paired(left, right, infos, options, stats) as ((reader_l, reader_r), first, pairs):
        t0 = time.perf_counter()
        stage("estimating maps")
        held: deque[tuple[YuvFrame, YuvFrame]] = deque([first])
        compositor = compositor_factory(chain([first], _held_as_taken(pairs, held)))
        timing["compositor_setup"] = time.perf_counter() - t0
        width, height = compositor.output_size
        # The output clock is the left input's own time base, so every frame keeps its input time.
        with plan.writing(output) as tmp, VideoWriter(tmp, width, height, rate, options.codec, options.crf,
                                                      options.preset, options.threads,
                                                      infos["left"].time_base, options.thread_type,
                                                      options.bitrate_kbps, options.maxrate_kbps) as writer:
            problems = []  # (what is the matter, what was done about it): warnings, or errors with --strict
            if audio_side is not None:
                # Audio time in its file -> output clock: the same shift as that input's video frames.
                side = infos[audio_side]
                if writer.add_audio(side.path, side.start_time_s - offsets[audio_side] + first[0].time_s) is None:
                    audio_side = None
                    problems.append((writer.audio_refusal, "the output has no audio"))
            for note in writer.notes:
                _note(notes, note)
            stage("stitching frames")
            _encode_pairs(chain(_drained(held), pairs), compositor, writer,
                          Count("frames", _expected_frames(infos, options), "fps"), timing, options.queue_frames,
                          t_run)
            readers = {"left": reader_l, "right": reader_r}
            problems += _input_problems(infos, readers)
            if problems and options.strict:
                raise VideoError("; ".join(what for what, _ in problems) + "; nothing written (--strict)")
    warnings = [f"{what}: {done}" for what, done in problems]
    for warning in warnings:
        LOGGER.warning(warning)
    timing["total"] = time.perf_counter() - t_run
    timing["decode_wait"] = reader_l.log.wait_s + reader_r.log.wait_s
    for note in _input_notes(infos, readers, stats):
        _note(notes, note)
    return {"started": started.isoformat(timespec="microseconds"), "span_s": _span_report(options),
            **_report(infos, (reader_l, reader_r), writer, stats, timing, notes, warnings, output, audio_side)}


def _expected_frames(infos: dict[str, VideoInfo], options: VideoOptions) -> int:
    """Output frames to expect: the left frames of the time both inputs cover, within the span."""
    end = min(infos["left"].duration_s, infos["right"].duration_s)
    if options.end_s:
        end = min(end, options.end_s)
    return max(round((end - options.start_s) * infos["left"].fps), 0)


def _held_as_taken(pairs: Iterator[tuple[YuvFrame, YuvFrame]], held: deque[tuple[YuvFrame, YuvFrame]]
                   ) -> Iterator[tuple[YuvFrame, YuvFrame]]:
    """``pairs``, each also kept in ``held`` as it is taken (for the frame loop after the factory)."""
    for pair in pairs:
        held.append(pair)
        yield pair


def _drained(held: deque[tuple[YuvFrame, YuvFrame]]) -> Iterator[tuple[YuvFrame, YuvFrame]]:
    """``held``'s pairs, oldest first, each let go of as it is yielded."""
    while held:
        yield held.popleft()


def _note(notes: list[str], text: str) -> None:
    """Keep ``text`` in the report's notes and say it now, as one warning line."""
    notes.append(text)
    LOGGER.warning(text)


def _input_notes(infos: dict[str, VideoInfo], readers: dict[str, FrameReader], stats: PairingStats) -> list[str]:
    """What the report's reader should know about the inputs: left frames with no right frame (left
    out of the output), rates that differ or vary, rotations."""
    notes = []
    for count, where in ((stats.unpaired_ticks_start, "first"), (stats.leftover_ticks, "last")):
        if count:
            side = "starts after" if where == "first" else "ends before"
            notes.append(f"the right input {side} the left one: the {where} {count} left frames have no right "
                         f"frame and are not in the output")
    rate_l, rate_r = infos["left"].fps, infos["right"].fps
    if rate_l != rate_r:
        notes.append(f"frame rates differ (left {float(rate_l):g} fps, right {float(rate_r):g} fps): frames paired "
                     f"by time at the left rate; {stats.dropped} right frames dropped, {stats.repeated} repeated")
    for side, reader in readers.items():
        if reader.log.interval_range_s is not None and reader.log.interval_range_s[0] > 0:
            low, high = reader.log.interval_range_s
            if high > VFR_SPREAD * low:
                kept = "the output keeps its frame times" if side == "left" else "paired to the left frames by time"
                notes.append(f"{side} input has a variable frame rate (frames {1000 * float(low):.0f} to "
                             f"{1000 * float(high):.0f} ms apart): {kept}")
        if infos[side].rotation_deg:
            notes.append(f"{side} input is displayed turned {infos[side].rotation_deg} degrees (display matrix): "
                         f"stitched upright")
    return notes


def _input_problems(infos: dict[str, VideoInfo], readers: dict[str, FrameReader]) -> list[tuple[str, str]]:
    """Damaged frames, time stamps that go back, a resolution that changes and truncated inputs: (what is
    the matter, what was done), see ``reader.py``."""
    problems = []
    for side, reader in readers.items():
        if reader.log.damaged:
            span = reader.log.damaged_span_s
            where = f" between {float(span[0]):.2f} s and {float(span[1]):.2f} s" if span is not None else ""
            problems.append((f"{side} input has {reader.log.damaged} damaged frames{where}",
                             "each replaced by the last good frame (--strict fails instead)"))
        if reader.log.out_of_order:
            last_s, time_s = reader.log.out_of_order_at
            frames = "1 frame whose time stamp goes back or repeats" if reader.log.out_of_order == 1 else \
                f"{reader.log.out_of_order} frames whose time stamps go back or repeat"
            problems.append((f"{side} input has {frames} (the first: {float(time_s):.3f} s after "
                             f"{float(last_s):.3f} s)", "dropped (--strict fails instead)"))
        if reader.log.rescaled:
            (width, height), time_s = reader.log.rescaled_from
            problems.append((f"{side} input changes resolution from {reader.log.size[0]}x{reader.log.size[1]} to "
                             f"{width}x{height} at {float(time_s):.2f} s",
                             f"{reader.log.rescaled} frames were rescaled to {reader.log.size[0]}x{reader.log.size[1]} "
                             f"(--strict fails instead)"))
        declared = infos[side].frame_count
        # Counted only over a whole file: a trimmed input was not decoded from its start or to its end.
        whole = reader.span_s[0] is None and not reader.log.stopped_at_end
        if whole and declared and reader.log.decoded + reader.log.damaged < declared:
            problems.append((f"{side} input ended after {reader.log.decoded + reader.log.damaged} of the {declared} frames "
                             f"its header declares (truncated?)", "stitched up to where it ends"))
    return problems


class EncodeThread:
    """Encodes frames on a thread of its own, fed through a bounded queue.

    Compositing frame n+1 (Warp launches release the GIL) then overlaps encoding frame n (x264 runs
    in FFmpeg's threads): the decode / composite / encode pipeline. The queue holds at most
    ``queue_frames`` output frames, so memory does not grow with the video's length. ``seconds`` is
    the time spent in the encoder; an encoder failure is re-raised in the producing thread.
    """

    def __init__(self, writer: VideoWriter, queue_frames: int):
        self.writer = writer
        self.seconds = 0.0
        self._queue: queue.Queue = queue.Queue(maxsize=max(queue_frames, 1))
        self._error: BaseException | None = None
        self._stop = threading.Event()
        # Set when the thread is done. Waited on instead of Thread.join: a signal that interrupts a
        # join marks the thread stopped while it still runs (CPython 3.11), and the file would be
        # closed under the encoder.
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="encode", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                item = self._queue.get()
                if item is None:
                    return
                planes, pts = item
                t0 = time.perf_counter()
                self.writer.write(*planes, pts=pts)
                self.seconds += time.perf_counter() - t0
        except BaseException as exc:  # handed to the producer, which re-raises it
            self._error = exc
        finally:
            self._done.set()

    def _put(self, item) -> None:
        while not self._done.is_set():
            try:
                self._queue.put(item, timeout=_POLL_S)
                return
            except queue.Full:
                continue
        self._raise_error()

    def _raise_error(self) -> None:
        if self._error is not None:
            raise self._error

    def write(self, planes: tuple[np.ndarray, np.ndarray, np.ndarray], pts: int) -> None:
        """Queue one frame's (y, u, v) planes (kept, not copied: pass fresh arrays) at ``pts``."""
        self._raise_error()
        self._put((planes, pts))

    def finish(self) -> None:
        """Wait until every queued frame is encoded, then flush the encoder."""
        self._put(None)
        self._done.wait()
        self._raise_error()
        t0 = time.perf_counter()
        self.writer.finish()
        self.seconds += time.perf_counter() - t0

    def abandon(self) -> None:
        """Stop after the frame being encoded, dropping the queue (a failed or interrupted run)."""
        self._stop.set()
        while not self._done.is_set():
            try:
                self._queue.get_nowait()
            except queue.Empty:
                self._queue.put(None)
            self._done.wait(_POLL_S)


def _encode_pairs(pairs, compositor: FrameCompositor, writer: VideoWriter, progress: Count, timing: dict,
                  queue_frames: int, t_run: float) -> None:
    """Composite every ``(left, right)`` pair and encode it on :class:`EncodeThread`.

    The output pts follow the left frames' times. ``timing["composite"]`` is this thread's compositing
    time, ``timing["encode"]`` the encoder thread's time (the two overlap), ``timing["first_frame"]``
    the time from the run's start (``t_run``, a ``perf_counter``) until the first frame was composited.
    """
    t_first, last_pts = None, -1
    update = getattr(compositor, "update", None)
    if update is not None:
        timing["maps_update"] = 0.0
    look_ahead = getattr(compositor, "look_ahead", None)
    if look_ahead is not None:
        pairs = looked_ahead(pairs, look_ahead, compositor.lookahead_frames)
    encoder = EncodeThread(writer, queue_frames)
    try:
        for frame_l, frame_r in pairs:
            if update is not None:
                t0 = time.perf_counter()
                update(frame_l, frame_r)
                timing["maps_update"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            planes = compositor.composite_yuv(frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v)
            timing["composite"] += time.perf_counter() - t0
            if t_first is None:
                timing["first_frame"] = time.perf_counter() - t_run
                t_first = frame_l.time_s
            # The left frame's own time in the writer's time base; forced to increase should rounding collide.
            last_pts = max(last_pts + 1, round((frame_l.time_s - t_first) / writer.time_base))
            encoder.write(planes, last_pts)
            progress.update(writer.frames)
        encoder.finish()
    except BaseException:
        encoder.abandon()
        raise
    finally:
        timing["encode"] += encoder.seconds
    progress.close(writer.frames)


def looked_ahead(pairs, look_ahead, depth: int):
    """``pairs`` in order, each shown to ``look_ahead`` ``depth`` pairs before it is yielded."""
    held: deque = deque()
    for pair in pairs:
        look_ahead(*pair)
        held.append(pair)
        if len(held) > depth:
            yield held.popleft()
    yield from held


def _report(infos, readers, writer: VideoWriter, stats: PairingStats, timing: dict, notes: list[str],
            warnings: list[str], output, audio_side: str | None) -> dict:
    """The run's report as plain JSON-ready values (see :func:`run_video`)."""
    reader_l, reader_r = readers
    audio = writer.audio
    return {
        "frames_in": {"left": reader_l.log.decoded, "right": reader_r.log.decoded},
        "frames_out": writer.frames,
        "dropped": stats.dropped,
        "repeated": stats.repeated,
        "damaged": {"left": reader_l.log.damaged, "right": reader_r.log.damaged},
        "pairing": stats.as_dict(),
        "timing_s": {name: round(seconds, 4) for name, seconds in timing.items()},
        "output_fps": round(writer.frames / timing["total"], 2),
        "inputs": {"left": _input_summary(infos["left"], reader_l), "right": _input_summary(infos["right"], reader_r)},
        "output": {
            "path": str(output), "width": writer.width, "height": writer.height, "fps": float(writer.rate),
            "encoder": writer.encoder_settings(), "audio": audio_side or "none",
            "audio_mode": None if audio is None else ("copy" if audio.remux else "aac"),
            "audio_span_s": None if audio is None else [audio.first_s, audio.end_s],
        },
        "notes": notes,
        "warnings": warnings,
    }

