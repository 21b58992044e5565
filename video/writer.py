"""Encoding the stitched frames with PyAV, and copying one input's audio alongside.

The caller writes into a temporary path (``sena_warp.outputs``) so a failed or interrupted run
never leaves a partial file under the final name. Video is H.264 or HEVC in yuv420p, at a constant
quality or an average bit rate (optionally capped), at the input's frame
rate; the stitch gives the encoder the left input's own time base and each frame's pts from that
input's presentation time, so timing (a variable frame rate too) is carried through, not recounted. Audio is remuxed
(packets copied, no re-encoding) when the output container accepts its codec, else re-encoded to AAC;
either way it is trimmed to the span of the video that was written.
"""

from __future__ import annotations

import contextlib
import io
import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from ..config import Config
from ..errors import OutputError, VideoError
from .reader import PIX_FMT, open_input

FALLBACK_CODEC = "libx264"  # always in PyAV's wheels
# A hardware encoder that cannot open falls back to the software encoder of its format (and that to libx264).
SOFTWARE_CODEC = {"h264_nvenc": "libx264", "hevc_nvenc": "libx265", "libx265": FALLBACK_CODEC}
NVENC = ("h264_nvenc", "hevc_nvenc")
X26X = ("libx264", "libx265")  # software encoders with x264's presets and constant rate factor
MP4_TAGS = {"libx265": "hvc1", "hevc_nvenc": "hvc1"}  # HEVC in MP4/MOV as hvc1: the tag Apple's players need
VBV_SECONDS = 2  # --maxrate: the rate buffer holds this many seconds at the peak rate
AUDIO_SEEK_MARGIN_S = 1  # a trimmed video's audio is sought this long before its start (packets before it are dropped)
_AAC_FRAME_SAMPLES = 1024  # AAC-LC encodes audio in frames of exactly this many samples
_DEFAULT_LAYOUTS = {1: "mono", 2: "stereo"}  # for sources whose channel order is unspecified


def choose_codec(requested: str, width: int, height: int, rate: Fraction) -> tuple[str, str | None]:
    """The encoder to use for ``requested`` and a note when it had to fall back (NVENC to the software
    encoder of its format, libx265 to libx264: ``SOFTWARE_CODEC``).

    A hardware encoder can be compiled in yet unusable (no GPU, no driver), so it is opened once
    with the real frame size to find out; a software encoder only needs to be in the build.
    """
    if requested == FALLBACK_CODEC:
        return requested, None
    fallback = SOFTWARE_CODEC.get(requested, FALLBACK_CODEC)
    if requested not in av.codecs_available:
        used, note = choose_codec(fallback, width, height, rate)
        return used, f"encoder {requested} is not in this FFmpeg build; used {used}" + (f" ({note})" if note else "")
    if requested not in NVENC:
        return requested, None
    try:
        ctx = av.CodecContext.create(requested, "w")
        ctx.width, ctx.height, ctx.pix_fmt, ctx.time_base = width, height, PIX_FMT, 1 / Fraction(rate)
        ctx.open()  # released when garbage-collected; PyAV has no explicit close
    except (av.error.FFmpegError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or exc
        used, note = choose_codec(fallback, width, height, rate)
        return used, f"encoder {requested} cannot be opened ({reason}); used {used}" + (f" ({note})" if note else "")
    return requested, None


def encoder_options(codec: str, crf: int, preset: str, bitrate_kbps: int = 0, maxrate_kbps: int = 0) -> dict[str, str]:
    """FFmpeg options for ``codec``: constant quality ``crf`` (NVENC: its ``cq``), or an average bit rate
    when ``bitrate_kbps`` is set; a peak rate ``maxrate_kbps`` caps either (a buffer of ``VBV_SECONDS``)."""
    options = {"rc": "vbr"} if codec in NVENC else {"preset": preset}
    if bitrate_kbps:
        options["b"] = f"{bitrate_kbps}k"
    else:
        options["cq" if codec in NVENC else "crf"] = str(crf)
    if maxrate_kbps:
        options.update(maxrate=f"{maxrate_kbps}k", bufsize=f"{VBV_SECONDS * maxrate_kbps}k")
    if codec == "libx265":
        options["x265-params"] = "log-level=error"  # x265 prints its settings on stderr otherwise
    return options


def even_size(width: int, height: int) -> tuple[int, int]:
    """The largest even ``(width, height)`` not above the given one (yuv420p needs even sides)."""
    return width - width % 2, height - height % 2


def _encodable_layout(layout: av.AudioLayout, source) -> str:
    """A channel layout name the AAC encoder accepts for ``layout`` (e.g. "1 channels" -> "mono")."""
    if not layout.name.endswith("channels"):
        return layout.name
    if layout.nb_channels not in _DEFAULT_LAYOUTS:
        raise VideoError(f"{source}: its audio has {layout.nb_channels} channels without a layout, which AAC "
                         f"cannot be given")
    return _DEFAULT_LAYOUTS[layout.nb_channels]


def remux_refusal(source: str | os.PathLike, format_name: str) -> str | None:
    """None when a ``format_name`` muxer stores the packets of ``source``'s audio as they are, else why not.

    The codec list says which codecs a container takes, but some muxers refuse a layout only when
    they write their index at the end (MP4 with PCM in a layout it has no code for): so one packet
    is muxed into memory, trailer included.
    """
    with open_input(source) as probe_in:
        stream = probe_in.streams.audio[0]
        name = stream.codec_context.name
        try:
            with av.open(io.BytesIO(), "w", format=format_name) as probe:
                if name not in probe.supported_codecs:
                    return f"the {format_name} container does not take {name}"
                out = probe.add_stream_from_template(stream)
                packet = next(p for p in probe_in.demux(stream) if p.pts is not None)
                packet.stream = out
                probe.mux(packet)
        except (av.error.FFmpegError, StopIteration) as exc:
            return f"the {format_name} muxer refuses a copy of its {name} audio ({getattr(exc, 'strerror', exc)})"
    return None


class AudioCopier:
    """Copy the audio of ``source`` into ``out`` on the output clock, trimmed to ``[0, end)``.

    Packets are copied when the output's muxer takes them (:func:`remux_refusal`), else re-encoded
    to AAC (``note`` says why); VideoError when AAC cannot take the channel layout either.

    ``shift_s``: output time = source audio time - ``shift_s``. Packets (or decoded frames, when
    re-encoding) are kept when they start inside the span, so the audio matches the video within
    one audio packet (~21 ms for AAC at 48 kHz). Call :meth:`advance` as video is written (keeps the
    file interleaved without buffering) and :meth:`finish` at the end.
    """

    def __init__(self, source: str | os.PathLike, out: av.container.OutputContainer, shift_s: Fraction):
        self._input = open_input(source)
        if not self._input.streams.audio:
            self._input.close()
            raise VideoError(f"{source}: has no audio stream to copy; choose another audio source or none")
        self._in_stream = self._input.streams.audio[0]
        self._out = out
        self._time_base = Fraction(self._in_stream.time_base)
        self._shift_s = shift_s
        refusal = remux_refusal(source, out.format.name)
        self.remux = refusal is None
        self.note = None if self.remux else f"{source}: audio re-encoded to AAC ({refusal})"
        if self.remux:
            self._out_stream = out.add_stream_from_template(self._in_stream)
        else:
            ctx = self._in_stream.codec_context
            try:
                layout = _encodable_layout(ctx.layout, source)
            except VideoError:
                self._input.close()
                raise
            self._out_stream = out.add_stream("aac", rate=ctx.sample_rate, layout=layout)
            self._resampler = av.AudioResampler(
                format="fltp", layout=layout, rate=ctx.sample_rate, frame_size=_AAC_FRAME_SAMPLES
            )
            self._next_pts: int | None = None
        if shift_s > AUDIO_SEEK_MARGIN_S:  # a trimmed video: skip the audio before it instead of reading through it
            with contextlib.suppress(av.error.FFmpegError):
                self._input.seek(int((shift_s - AUDIO_SEEK_MARGIN_S) / self._time_base), stream=self._in_stream,
                                 backward=True)
        self._packets = self._input.demux(self._in_stream)
        self._pending: av.Packet | None = None
        self.packets = 0
        self.first_s: float | None = None  # start of the first audio written, output seconds
        self.end_s: float | None = None  # end of the last audio written, output seconds

    def _out_time(self, pts: int) -> Fraction:
        return pts * self._time_base - self._shift_s

    def advance(self, end_s: Fraction) -> None:
        """Write the audio that starts before ``end_s`` (output seconds) and was not written yet."""
        while True:
            if self._pending is None:
                self._pending = next((p for p in self._packets if p.pts is not None), None)
                if self._pending is None:
                    return
            start_s = self._out_time(self._pending.pts)
            if start_s >= end_s:
                return
            packet, self._pending = self._pending, None
            if start_s >= 0:
                self._write(packet, start_s)

    def _write(self, packet: av.Packet, start_s: Fraction) -> None:
        self.packets += 1
        if self.first_s is None:
            self.first_s = float(start_s)
        self.end_s = float(start_s + (packet.duration or 0) * self._time_base)
        if self.remux:
            shift = round(self._shift_s / self._time_base)
            packet.pts -= shift
            packet.dts = packet.pts if packet.dts is None else packet.dts - shift
            packet.stream = self._out_stream
            self._out.mux(packet)
            return
        for frame in packet.decode():
            for resampled in self._resampler.resample(frame):
                self._encode(resampled, start_s)

    def _encode(self, frame: av.AudioFrame | None, start_s: Fraction) -> None:
        if frame is not None:
            if self._next_pts is None:
                self._next_pts = round(start_s * frame.sample_rate)
            frame.pts, frame.time_base = self._next_pts, Fraction(1, frame.sample_rate)
            self._next_pts += frame.samples
        self._out.mux(self._out_stream.encode(frame))

    def finish(self, end_s: Fraction) -> None:
        """Write the audio up to ``end_s``, flush the encoder if any, and close the source."""
        self.advance(end_s)
        if not self.remux:
            for resampled in self._resampler.resample(None):
                self._encode(resampled, Fraction(0))
            self._encode(None, Fraction(0))
        self.close()

    def close(self) -> None:
        self._input.close()


@dataclass(frozen=True)
class EncoderSettings:
    """How a :class:`VideoWriter` encodes: the encoder used (``codec``) for the one asked for
    (``requested``), its rate control (``crf``, or an average ``bitrate_kbps``; ``maxrate_kbps`` caps
    either), ``preset``, and FFmpeg ``threads`` of ``thread_type``."""

    requested: str
    codec: str
    crf: int
    preset: str
    threads: int
    thread_type: str
    bitrate_kbps: int
    maxrate_kbps: int

    def options(self) -> dict[str, str]:
        return encoder_options(self.codec, self.crf, self.preset, self.bitrate_kbps, self.maxrate_kbps)


class VideoWriter:
    """H.264 or HEVC (``codec``) yuv420p encoder into ``path`` at ``rate`` frames per second (optionally with audio).

    ``width``/``height`` are cropped to even values (see :func:`even_size`); :meth:`write` takes
    planes at least that large. Frame pts are in units of ``time_base`` (default ``1 / rate``; a
    finer one such as the input's keeps a variable frame rate's times) and must increase.
    Use as a context manager: a clean exit flushes the encoder; an exception just closes the file.
    ``threads``: encoder threads (``Config.cpu_threads``; 0 lets the encoder choose, x264: 1.5 per core).
    ``crf`` (constant quality) unless ``bitrate_kbps`` asks for an average rate; ``maxrate_kbps`` caps
    either (:func:`encoder_options`).
    ``thread_type``: "slice" or "frame" (``Config.video_encoder_thread_type``); PyAV asks for slice
    threads unless told, and FFmpeg's libx264 wrapper turns x264's frame threads on for anything else.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        width: int,
        height: int,
        rate: Fraction,
        codec: str = FALLBACK_CODEC,
        crf: int = Config.video_crf,
        preset: str = Config.video_preset,
        threads: int = Config.cpu_threads,
        time_base: Fraction | None = None,
        thread_type: str = Config.video_encoder_thread_type,
        bitrate_kbps: int = Config.video_bitrate_kbps,
        maxrate_kbps: int = Config.video_maxrate_kbps,
    ):
        self.path = Path(path)
        self.width, self.height = even_size(width, height)
        if self.width < 2 or self.height < 2:
            raise VideoError(f"{self.path}: output frame {width}x{height} is too small to encode")
        self.rate = Fraction(rate)
        self.time_base = Fraction(time_base) if time_base is not None else 1 / self.rate
        used, note = choose_codec(codec, self.width, self.height, self.rate)
        self.settings = EncoderSettings(codec, used, crf, preset, threads, thread_type, bitrate_kbps, maxrate_kbps)
        self.notes = [note] if note else []  # fallbacks the report should mention
        self.audio_refusal: str | None = None  # why the audio was left out (see add_audio)
        self._open()
        self.audio: AudioCopier | None = None
        self.frames = 0
        self._last_pts: int | None = None
        self._finished = False

    def encoder_settings(self) -> dict:
        """The encoder as opened: codec (and the one asked for), rate control (constant quality ``crf``, or
        an average ``bitrate_kbps``; a peak ``maxrate_kbps`` or None), preset, thread count and type."""
        settings = self.settings
        software = settings.codec in X26X  # NVENC has no x264 preset nor threads of its own
        ctx = self.stream.codec_context
        return {"codec": settings.codec, "requested": settings.requested,
                "rate_control": "bitrate" if settings.bitrate_kbps else "crf",
                "crf": None if settings.bitrate_kbps else settings.crf,
                "bitrate_kbps": settings.bitrate_kbps or None, "maxrate_kbps": settings.maxrate_kbps or None,
                "preset": settings.preset if software else None, "threads": ctx.thread_count,
                "thread_type": ctx.thread_type.name.lower() if settings.codec == FALLBACK_CODEC else None,
                "pix_fmt": PIX_FMT}

    def _open(self) -> None:
        """(Re)create the file with its video stream, nothing written yet."""
        try:
            self.container = av.open(str(self.path), mode="w")
        except av.error.FFmpegError as exc:
            raise OutputError(f"{self.path}: cannot create the video file ({exc.strerror})") from exc
        settings = self.settings
        self.stream = self.container.add_stream(settings.codec, rate=self.rate, options=settings.options())
        self.stream.width, self.stream.height = self.width, self.height
        self.stream.pix_fmt = PIX_FMT
        if settings.codec in MP4_TAGS and self.container.format.name in ("mp4", "mov"):
            self.stream.codec_context.codec_tag = MP4_TAGS[settings.codec]
        self.stream.time_base = self.stream.codec_context.time_base = self.time_base
        # Both before the encoder opens on the first frame.
        self.stream.codec_context.thread_count = settings.threads
        self.stream.codec_context.thread_type = settings.thread_type.upper()

    def add_audio(self, source: str | os.PathLike, shift_s: Fraction) -> AudioCopier | None:
        """Copy ``source``'s audio (output time = its time - ``shift_s``); call before :meth:`write`.

        Copied or re-encoded to AAC as :class:`AudioCopier` decides (a re-encode is said in
        ``notes``); when neither is possible (a channel layout AAC cannot take, or the muxer refuses
        the stream) the video is written without audio. The file's header is written here, so the
        muxer's answer comes before any frame. Returns the copier, or None without audio (and
        ``audio_refusal`` says why).
        """
        try:
            copier = AudioCopier(source, self.container, shift_s)
        except VideoError as exc:
            reason = str(exc)
        else:
            try:
                self.container.start_encoding()
            except av.error.FFmpegError as exc:
                copier.close()
                reason = f"{source}: the {self.path.suffix} muxer refuses its audio ({exc.strerror})"
            else:
                self.notes += [copier.note] if copier.note else []
                self.audio = copier
                return copier
        self.container.close()
        self._open()
        self.audio_refusal = reason
        return None

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None and not self._finished:
                self.finish()
        finally:
            if self.audio is not None:
                self.audio.close()
            self.container.close()

    def write(self, y: np.ndarray, u: np.ndarray, v: np.ndarray, pts: int) -> None:
        """Encode one frame given as uint8 planes ``y (H, W)``, ``u, v (ceil(H/2), ceil(W/2))``."""
        if self._last_pts is not None and pts <= self._last_pts:
            raise VideoError(f"{self.path}: frame pts {pts} does not increase (previous {self._last_pts})")
        frame = av.VideoFrame(self.width, self.height, PIX_FMT)
        for plane, src in zip(frame.planes, (y, u, v)):
            if src.shape[0] < plane.height or src.shape[1] < plane.width:
                raise VideoError(
                    f"{self.path}: plane {src.shape} smaller than the {plane.height}x{plane.width} the frame needs"
                )
            rows = np.frombuffer(plane, dtype=np.uint8, count=plane.height * plane.line_size)
            rows.reshape(plane.height, plane.line_size)[:, : plane.width] = src[: plane.height, : plane.width]
        frame.pts, frame.time_base = pts, self.time_base
        self.container.mux(self.stream.encode(frame))
        self._last_pts = pts
        self.frames += 1
        if self.audio is not None:
            self.audio.advance(self._frame_end_s(pts))

    def _frame_end_s(self, pts: int) -> Fraction:
        """When frame ``pts`` stops being shown (output seconds), taking it to last one frame period."""
        return pts * self.time_base + 1 / self.rate

    def finish(self) -> None:
        """Flush the encoder and write the audio to the end of the last frame."""
        self._finished = True
        self.container.mux(self.stream.encode(None))
        if self.audio is not None and self._last_pts is not None:
            self.audio.finish(self._frame_end_s(self._last_pts))
