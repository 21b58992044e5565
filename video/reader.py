"""Opening, probing and decoding one video input with PyAV, on its own thread.

Frames leave this module as YUV 4:2:0 planes (the codec's own layout: no colour conversion on the
hot path) with their presentation time in seconds, measured from the video stream's start time and
shifted by a user offset, so two inputs share one clock. Times are exact ``Fraction``s
(``pts * time_base``) so pairing ties are decided exactly (see ``pairing.py``).

Decoding runs in a thread per input (PyAV releases the GIL inside FFmpeg) and hands frames over a
bounded queue, which caps memory and lets decoding overlap compositing and encoding.
"""

from __future__ import annotations

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
from ..imageio import existing_file

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


def probe_video(path: str | os.PathLike) -> VideoInfo:
    """Size, rate, start, duration and audio presence of a video input."""
    path = Path(path)
    with open_input(path) as container:
        stream = container.streams.video[0]
        ctx = stream.codec_context
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
        return VideoInfo(
            path=path,
            width=ctx.width,
            height=ctx.height,
            fps=Fraction(rate),
            time_base=time_base,
            start_time_s=Fraction(stream.start_time or 0) * time_base,
            duration_s=duration_s,
            frame_count=stream.frames,
            pix_fmt=ctx.format.name if ctx.format is not None else "unknown",
            codec=ctx.name,
            has_audio=bool(audio),
            audio_codec=audio[0].codec_context.name if audio else None,
        )


def plane_array(plane: av.video.plane.VideoPlane) -> np.ndarray:
    """A contiguous ``(height, width)`` uint8 copy of one frame plane, dropping the line padding."""
    rows = np.frombuffer(plane, dtype=np.uint8, count=plane.height * plane.line_size)
    return rows.reshape(plane.height, plane.line_size)[:, : plane.width].copy()


class FrameReader:
    """Decode one input on a background thread; iterate to get :class:`YuvFrame` in time order.

    Use as a context manager (``with FrameReader(...) as reader: for frame in reader: ...``);
    leaving the block stops and joins the thread even mid-file. Decode errors of single packets
    are skipped and counted in ``damaged``; any other failure is re-raised in the iterating thread.
    ``wait_s`` accumulates the time the consumer spent blocked waiting for frames; ``decode_s`` the
    decoder thread's time decoding and copying planes out (not its waits on a full queue).
    ``threads``: FFmpeg decoder threads (``Config.cpu_threads``; 0 lets FFmpeg choose); once decoding
    has started, ``decoder_threads`` is the count the decoder was opened with.
    """

    def __init__(self, path: str | os.PathLike, offset_s: Fraction = Fraction(0), queue_frames: int = 8,
                 threads: int = 0):
        self.path = Path(path)
        self.offset_s = Fraction(offset_s)
        self.threads = threads
        self.decoder_threads: int | None = None
        self.decoded = 0
        self.damaged = 0
        self.converted_from: str | None = None  # source pixel format when it was not yuv420p
        self.wait_s = 0.0
        self.decode_s = 0.0
        self._container = open_input(self.path)
        self._queue: queue.Queue = queue.Queue(maxsize=queue_frames)
        self._stop = threading.Event()
        self._ended = False  # the end marker (or an error) was taken: iterating again yields nothing
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
            self._thread.join()
        self._container.close()

    def __iter__(self) -> Iterator[YuvFrame]:
        while not self._ended:
            t0 = time.perf_counter()
            item = self._queue.get()
            self.wait_s += time.perf_counter() - t0
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
            stream = self._container.streams.video[0]
            # Let FFmpeg decode with frame and slice threads; set before the codec opens.
            stream.thread_type = "AUTO"
            stream.thread_count = self.threads
            time_base = Fraction(stream.time_base)
            start_pts = stream.start_time or 0
            period_pts = 1 / (Fraction(stream.average_rate or stream.guessed_rate) * time_base)
            last_pts = None
            for packet in self._container.demux(stream):
                t0 = time.perf_counter()
                try:
                    frames = packet.decode()
                except av.error.InvalidDataError:
                    self.damaged += 1
                    continue
                finally:
                    self.decode_s += time.perf_counter() - t0
                for frame in frames:
                    self.decoder_threads = stream.codec_context.thread_count
                    if frame.is_corrupt:  # FFmpeg concealed errors in it: skip rather than stitch garbage
                        self.damaged += 1
                        continue
                    pts = frame.pts
                    if pts is None:  # rare (broken muxing): place it one frame after the previous one
                        pts = start_pts if last_pts is None else last_pts + period_pts
                    last_pts = pts
                    t0 = time.perf_counter()
                    yuv = self._to_yuv(frame, (pts - start_pts) * time_base + self.offset_s)
                    self.decode_s += time.perf_counter() - t0
                    if not self._put(yuv):
                        return
        except av.error.FFmpegError as exc:
            self._put(VideoError(f"{self.path}: decoding failed after {self.decoded} frames ({exc.strerror})"))
        except BaseException as exc:  # handed to the consumer, which re-raises it
            self._put(exc)
        finally:
            self._put(_END)

    def _to_yuv(self, frame: av.VideoFrame, time_s: Fraction) -> YuvFrame:
        if frame.format.name != PIX_FMT:
            # Only non-4:2:0 sources (e.g. yuv422p webcams) pay for a conversion.
            self.converted_from = frame.format.name
            frame = frame.reformat(format=PIX_FMT)
        y, u, v = (plane_array(p) for p in frame.planes[:3])
        self.decoded += 1
        return YuvFrame(time_s=time_s, index=self.decoded - 1, y=y, u=u, v=v)
