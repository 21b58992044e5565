"""Opening, probing and decoding one video input with PyAV, on its own thread.

Frames leave this module as YUV 4:2:0 planes (the codec's own layout: no colour conversion on the
hot path) with their presentation time in seconds, measured from the video stream's start time and
shifted by a user offset, so two inputs share one clock. Times are exact ``Fraction``s
(``pts * time_base``) so pairing ties are decided exactly (see ``pairing.py``).

Decoding runs in a thread per input (PyAV releases the GIL inside FFmpeg) and hands frames over a
bounded queue, which caps memory and lets decoding overlap compositing and encoding.

Frames leave upright: a display matrix (the rotation phones record instead of turning the pixels)
is applied to the planes. Damaged input, the policy: after a packet the decoder rejects or a frame
it flags as corrupt, every frame up to the next key frame is *damaged* (predicted from the damage:
macroblock garbage), and so is every frame the decoder lost meanwhile (the gap it leaves, on the
nominal frame rate). Each damaged frame is replaced by the last good frame at the damaged frame's
own time, so the timing holds; damage before the first good frame is dropped. The reader counts
them and their time span; the loop turns that into a warning, or with ``strict`` the first one
stops the run.

Time stamps that go back (two recordings joined) or repeat: such a frame is dropped, never given a
time of its own squeezed in after the last one, and counted; a frame of another size than the first
(the resolution changes mid-stream) is rescaled to the first size and counted. Both are warnings, or
with ``strict`` errors, as damage is.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import queue
import threading
import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Iterator

import av
import cv2
import numpy as np

from ..errors import InputError, VideoError
from ..imageio import check_size, existing_file

PIX_FMT = "yuv420p"
_POLL_S = 0.1  # how often a blocked decoder thread re-checks whether it was asked to stop
_END = object()  # queue marker: the decoder thread has finished
# FFmpeg demuxers of single pictures; the others are all named "<format>_pipe" (png_pipe, jpeg_pipe, ...)
STILL_IMAGE_DEMUXERS = ("image2",)


@dataclass(frozen=True)
class VideoInfo:
    """What a probe of one input found. Sizes in pixels; times in seconds."""

    path: Path
    width: int
    height: int
    fps: Fraction  # average frame rate of the video stream
    time_base: Fraction
    start_time_s: Fraction  # the video stream's first presentation time
    duration_s: float  # of the video stream (container duration when the stream has none)
    frame_count: int  # as the container declares it (0 when unknown)
    rotation_deg: int  # counter-clockwise turn the display matrix asks for (0, 90, 180, 270); width/height are after it
    pix_fmt: str
    codec: str
    has_audio: bool
    audio_codec: str | None


@dataclass(frozen=True)
class YuvFrame:
    """One decoded frame as contiguous uint8 planes, ``plane[row, col]``.

    ``y`` is ``(H, W)``; ``u`` and ``v`` are ``((H + 1) // 2, (W + 1) // 2)`` (4:2:0 chroma).
    ``time_s`` is the presentation time on the shared clock; ``index`` counts decoded frames of
    this input from 0.
    """

    time_s: Fraction
    index: int
    y: np.ndarray
    u: np.ndarray
    v: np.ndarray

    def to_bgr(self) -> np.ndarray:
        """The frame as BGR uint8 ``(H, W, 3)`` (BT.601, for estimating maps, not per frame)."""
        h, w = self.y.shape
        he, we = h + h % 2, w + w % 2
        y = np.pad(self.y, ((0, he - h), (0, we - w)), mode="edge")
        i420 = np.concatenate([y.ravel(), self.u.ravel(), self.v.ravel()]).reshape(he * 3 // 2, we)
        return cv2.cvtColor(i420, cv2.COLOR_YUV2BGR_I420)[:h, :w]


def open_input(path: str | os.PathLike) -> av.container.InputContainer:
    """Open a media file for reading, or raise InputError/VideoError saying what is wrong."""
    path = existing_file(path)
    try:
        container = av.open(str(path), mode="r")
    except av.error.FFmpegError as exc:
        raise InputError(
            f"{path}: not a readable media file ({exc.strerror}); a video may be truncated or corrupt: copy it again"
        ) from exc
    if container.format.name in STILL_IMAGE_DEMUXERS or container.format.name.endswith("_pipe"):
        container.close()  # FFmpeg reads a photo as a one-frame video: refuse it rather than "stitch" one frame
        raise VideoError(f"{path}: is an image, not a video; give a video file (photos: sena-warp image)")
    if not container.streams.video:
        container.close()
        raise VideoError(f"{path}: has no video stream; give a video file")
    return container


def probe_video(path: str | os.PathLike, max_megapixels: float | None = None) -> VideoInfo:
    """Size, rate, start, duration and audio presence of a video input.

    A probe decodes the first frame (for its display rotation, about 30 ms at 1080p), so the stream's
    coded size is checked against ``max_megapixels`` first (InputError; None: no limit of ours): a
    small file can hold one huge frame. Probed once per version of the file (inode, size,
    modification time) and limit: the loop, the first estimate and the compositor each ask.
    """
    path = Path(path)
    try:
        stat = path.stat()
    except OSError:
        return _probe(path, max_megapixels)  # open_input says what is wrong
    version = (stat.st_ino, stat.st_size, stat.st_mtime_ns)
    return dataclasses.replace(_probe_version(path.resolve(), version, max_megapixels), path=path)


@functools.lru_cache(maxsize=16)
def _probe_version(path: Path, version: tuple[int, int, int], max_megapixels: float | None) -> VideoInfo:
    return _probe(path, max_megapixels)


def _probe(path: Path, max_megapixels: float | None) -> VideoInfo:
    with open_input(path) as container:
        stream = container.streams.video[0]
        ctx = stream.codec_context
        check_size(str(path), ctx.width, ctx.height, max_megapixels, "a frame")
        rate = stream.average_rate or stream.guessed_rate
        if not rate:
            raise VideoError(f"{path}: the video stream declares no frame rate")
        time_base = Fraction(stream.time_base)
        if stream.duration is not None:
            duration_s = float(stream.duration * time_base)
        elif container.duration is not None:
            duration_s = container.duration / av.time_base
        else:
            duration_s = 0.0
        audio = container.streams.audio
        turns = _quarter_turns(_first_frame_rotation(container))
        width, height = (ctx.height, ctx.width) if turns % 2 else (ctx.width, ctx.height)
        return VideoInfo(
            path=path,
            width=width,
            height=height,
            fps=Fraction(rate),
            time_base=time_base,
            start_time_s=Fraction(stream.start_time or 0) * time_base,
            duration_s=duration_s,
            frame_count=stream.frames,
            rotation_deg=90 * turns,
            pix_fmt=ctx.format.name if ctx.format is not None else "unknown",
            codec=ctx.name,
            has_audio=bool(audio),
            audio_codec=audio[0].codec_context.name if audio else None,
        )


def _first_frame_rotation(container: av.container.InputContainer) -> float:
    """The display rotation of the first frame that decodes (0 when none does); rewinds the container."""
    try:
        rotation = next((frame.rotation for frame in container.decode(video=0)), 0)
    except av.error.FFmpegError:
        rotation = 0
    container.seek(0)
    return rotation


def _quarter_turns(rotation_deg: float) -> int:
    """Counter-clockwise quarter turns (0-3) nearest to a display rotation in degrees."""
    return round(rotation_deg / 90) % 4


def span_of(start_s: float, end_s: float, margin_s: Fraction = Fraction(0)) -> tuple[Fraction | None, Fraction | None]:
    """A :class:`FrameReader`'s ``span_s`` for the trim [``start_s``, ``end_s``) (``Config.video_start_s`` /
    ``video_end_s``; 0: not trimmed there), widened by ``margin_s`` at both ends."""
    return (Fraction(str(start_s)) - margin_s if start_s else None,
            Fraction(str(end_s)) + margin_s if end_s else None)


def plane_array(plane: av.video.plane.VideoPlane) -> np.ndarray:
    """A contiguous ``(height, width)`` uint8 copy of one frame plane, dropping the line padding."""
    rows = np.frombuffer(plane, dtype=np.uint8, count=plane.height * plane.line_size)
    return rows.reshape(plane.height, plane.line_size)[:, : plane.width].copy()


@dataclass
class DecodeLog:
    """What one :class:`FrameReader` met, for the loop's warnings and the report.

    ``decoded`` good frames; ``damaged`` frames replaced (``damaged_span_s``: the first and last damaged
    time on the shared clock); ``skipped`` frames before the span's start (from the key frame a seek lands
    on); ``stopped_at_end``: decoding stopped at the span's end, before the end of the file;
    ``interval_range_s``: the (shortest, longest) time between two good frames (a variable frame rate when
    they differ; not across a dropped frame); ``converted_from``: the source pixel format when it was not
    yuv420p; ``out_of_order`` frames dropped because their time stamp went back or repeated
    (``out_of_order_at``: the first, as (last time kept, its time)); ``size``: (width, height) of the first
    frame, as stored (before rotation); ``rescaled`` frames of another size, brought to ``size``
    (``rescaled_from``: the first one's size and time); ``decoder_threads``: the count the decoder was
    opened with; ``wait_s``: the consumer's time blocked waiting for frames; ``decode_s``: the decoder
    thread's time decoding and copying planes out (not its waits on a full queue).
    """

    decoded: int = 0
    damaged: int = 0
    damaged_span_s: tuple[Fraction, Fraction] | None = None
    skipped: int = 0
    stopped_at_end: bool = False
    interval_range_s: tuple[Fraction, Fraction] | None = None
    converted_from: str | None = None
    out_of_order: int = 0
    out_of_order_at: tuple[Fraction, Fraction] | None = None
    size: tuple[int, int] | None = None
    rescaled: int = 0
    rescaled_from: tuple[tuple[int, int], Fraction] | None = None
    decoder_threads: int | None = None
    wait_s: float = 0.0
    decode_s: float = 0.0

    def count_damage(self, time_s: Fraction) -> None:
        self.damaged += 1
        first, _ = self.damaged_span_s or (time_s, time_s)
        self.damaged_span_s = (first, time_s)

    def count_interval(self, step_s: Fraction) -> None:
        low, high = self.interval_range_s or (step_s, step_s)
        self.interval_range_s = (min(low, step_s), max(high, step_s))


class FrameReader:
    """Decode one input on a background thread; iterate to get :class:`YuvFrame` in time order.

    Use as a context manager (``with FrameReader(...) as reader: for frame in reader: ...``);
    leaving the block stops and joins the thread even mid-file. Damaged frames are replaced as the
    module says; with ``strict`` the first one raises VideoError instead. Any other failure is
    re-raised in the iterating thread. ``log`` (:class:`DecodeLog`) counts what happened.
    ``threads``: FFmpeg decoder threads (``Config.cpu_threads``; 0 lets FFmpeg choose).

    ``span_s`` = (start, end) on the shared clock: only frames with start <= time < end come out (None:
    from the beginning, to the end of the file). A start inside the file is reached by seeking to the
    key frame before it, so only the frames from there on are decoded (``skipped``: those before the
    start); decoding stops at the first frame at or past the end.
    """

    def __init__(self, path: str | os.PathLike, offset_s: Fraction = Fraction(0), queue_frames: int = 8,
                 threads: int = 0, strict: bool = False,
                 span_s: tuple[Fraction | None, Fraction | None] = (None, None)):
        self.path = Path(path)
        self.offset_s = Fraction(offset_s)
        self.span_s = span_s
        self.threads = threads
        self.strict = strict
        self.log = DecodeLog()
        self._container = open_input(self.path)
        self._queue: queue.Queue = queue.Queue(maxsize=queue_frames)
        self._stop = threading.Event()
        self._ended = False  # the end marker (or an error) was taken: iterating again yields nothing
        self._last_good: YuvFrame | None = None  # the last frame queued, repeated in place of damaged ones
        self._dropped_since_last = False  # a frame was dropped (its time stamp) since the last one queued
        self._done = threading.Event()  # the decoder thread has finished
        self._thread = threading.Thread(target=self._run, name=f"decode:{self.path.name}", daemon=True)

    def __enter__(self) -> "FrameReader":
        self._thread.start()
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def close(self) -> None:
        """Stop the decoder thread and release the file (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._done.wait()  # not Thread.join: see loop.EncodeThread (a signal there would close under it)
        self._container.close()

    def __iter__(self) -> Iterator[YuvFrame]:
        while not self._ended:
            t0 = time.perf_counter()
            item = self._queue.get()
            self.log.wait_s += time.perf_counter() - t0
            if item is _END:
                self._ended = True
            elif isinstance(item, BaseException):
                self._ended = True
                raise item
            else:
                yield item

    def _put(self, item) -> bool:
        """Queue ``item``, waiting while the queue is full; False when asked to stop meanwhile."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def _run(self) -> None:
        try:
            self._decode_all()
        except av.error.FFmpegError as exc:
            self._put(VideoError(f"{self.path}: decoding failed after {self.log.decoded} frames ({exc.strerror})"))
        except BaseException as exc:  # handed to the consumer, which re-raises it
            self._put(exc)
        finally:
            self._put(_END)
            self._done.set()

    def _decode_all(self) -> None:
        stream = self._container.streams.video[0]
        # Let FFmpeg decode with frame and slice threads; set before the codec opens.
        stream.thread_type = "AUTO"
        stream.thread_count = self.threads
        time_base = Fraction(stream.time_base)
        start_pts = stream.start_time or 0
        rate = Fraction(stream.average_rate or stream.guessed_rate)
        period_pts = 1 / (rate * time_base)
        last_pts = None
        first_s, end_s = self.span_s
        if first_s is not None and first_s - self.offset_s > 0:
            self._seek(stream, start_pts + (first_s - self.offset_s) / time_base)
        # After damage, up to the next key frame: frames are predicted from it, and frames the decoder
        # lost leave gaps in time. (With frame threads its error comes a few packets late: the packet
        # that raises is not the damaged one, so the gaps, not the packets, say what is missing.)
        tainted = False
        for packet in self._container.demux(stream):
            t0 = time.perf_counter()
            try:
                frames = packet.decode()
            except av.error.InvalidDataError:
                if self.strict:
                    raise self._damage_error(self._last_good.time_s if self._last_good else Fraction(0)) from None
                tainted = True
                continue
            finally:
                self.log.decode_s += time.perf_counter() - t0
            for frame in frames:
                self.log.decoder_threads = stream.codec_context.thread_count
                was_tainted = tainted
                tainted = (tainted and not frame.key_frame) or frame.is_corrupt
                pts = frame.pts
                if pts is None:  # rare (broken muxing): place it one frame after the previous one
                    pts = start_pts if last_pts is None else last_pts + period_pts
                last_pts = pts
                time_s = (pts - start_pts) * time_base + self.offset_s
                if self._last_good is not None and time_s <= self._last_good.time_s:
                    self._count_out_of_order(time_s)
                    continue
                if first_s is not None and time_s < first_s:  # between the key frame a seek lands on and the span's start
                    self.log.skipped += 1
                    continue
                if end_s is not None and time_s >= end_s:
                    self.log.stopped_at_end = True
                    return
                if (was_tainted or tainted) and not self._fill_gap(time_s, 1 / rate):
                    return
                if tainted:
                    if not self._emit_damaged(time_s):
                        return
                    continue
                t0 = time.perf_counter()
                yuv = self._to_yuv(frame, time_s)
                self.log.decode_s += time.perf_counter() - t0
                if not self._put(yuv):
                    return

    def _seek(self, stream, pts: Fraction) -> None:
        """Move to the key frame at or before ``pts`` (the stream's time base); where the file cannot seek,
        decoding starts at its beginning and the frames before the span are passed over all the same."""
        with contextlib.suppress(av.error.FFmpegError):
            self._container.seek(int(pts), stream=stream, backward=True, any_frame=False)

    def _damage_error(self, time_s: Fraction) -> VideoError:
        return VideoError(f"{self.path}: damaged frame at {float(time_s):.2f} s after {self.log.decoded} good frames "
                          f"(--strict)")

    def _count_out_of_order(self, time_s: Fraction) -> None:
        """Count a frame whose time is not after the last one kept (it is dropped); VideoError with strict."""
        last_s = self._last_good.time_s
        if self.strict:
            how = "repeat" if time_s == last_s else f"go back to {float(time_s):.3f} s"
            raise VideoError(f"{self.path}: frame time stamps {how} after {float(last_s):.3f} s (--strict)")
        self.log.out_of_order += 1
        self.log.out_of_order_at = self.log.out_of_order_at or (last_s, time_s)
        self._dropped_since_last = True

    def _count_damage(self, time_s: Fraction) -> None:
        if self.strict:
            raise self._damage_error(time_s)
        self.log.count_damage(time_s)

    def _fill_gap(self, time_s: Fraction, period_s: Fraction) -> bool:
        """Damaged frames for the frames lost before ``time_s`` (more than half a period missing
        after the last one queued); False when asked to stop."""
        if self._last_good is None:
            return True
        missing = self._last_good.time_s + period_s
        while missing < time_s - period_s / 2:
            if not self._emit_damaged(missing):
                return False
            missing += period_s
        return True

    def _emit_damaged(self, time_s: Fraction) -> bool:
        """Count one damaged frame and queue the last good frame in its place (nothing before the first
        good frame); False when asked to stop."""
        self._count_damage(time_s)
        if self._last_good is None:
            return True
        self._last_good = dataclasses.replace(self._last_good, time_s=time_s)
        return self._put(self._last_good)

    def _to_yuv(self, frame: av.VideoFrame, time_s: Fraction) -> YuvFrame:
        size = (frame.width, frame.height)
        first = self.log.size = self.log.size or size
        if size != first:  # the maps are made for the first size: a later one is brought to it
            if self.strict:
                raise VideoError(f"{self.path}: the resolution changes from {first[0]}x{first[1]} to "
                                 f"{size[0]}x{size[1]} at {float(time_s):.2f} s (--strict)")
            self.log.rescaled += 1
            self.log.rescaled_from = self.log.rescaled_from or (size, time_s)
            frame = frame.reformat(width=first[0], height=first[1], format=PIX_FMT)
        if frame.format.name != PIX_FMT:
            # Only non-4:2:0 sources (e.g. yuv422p webcams) pay for a conversion.
            self.log.converted_from = frame.format.name
            frame = frame.reformat(format=PIX_FMT)
        turns = _quarter_turns(frame.rotation)
        y, u, v = (np.ascontiguousarray(np.rot90(plane_array(p), turns)) if turns else plane_array(p)
                   for p in frame.planes[:3])
        if self._last_good is not None and not self._dropped_since_last:  # a drop's gap is said as the drop
            self.log.count_interval(time_s - self._last_good.time_s)
        self.log.decoded += 1
        self._last_good = YuvFrame(time_s=time_s, index=self.log.decoded - 1, y=y, u=u, v=v)
        self._dropped_since_last = False
        return self._last_good
