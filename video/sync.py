"""How far apart two recordings started (``sena-warp video --offset auto``).

The answer has ``--offset``'s sign and clock: seconds the right input started after the left one,
on the clock of each input's video stream (zero at its first frame, as ``reader.FrameReader``
counts), so an event at left time t is at right time t - offset.

Two signals, tried in this order:

- *audio*, when both inputs have a track: each decoded over its first ``cfg.sync_audio_span_s``
  and resampled to mono at ``cfg.sync_audio_rate_hz``; the waveforms are correlated, so the
  estimate is good to a fraction of a millisecond where both microphones hear the same sounds.
- *motion*: the frame-difference energy of each video (mean absolute difference of consecutive
  luma frames, downscaled to ``cfg.sync_motion_side_px``) over its first ``cfg.sync_motion_span_s``,
  median-filtered over ``cfg.sync_motion_median_frames`` (a keyframe's quality jump is a one-frame
  spike, the same in every GOP: a 30-frame GOP in both inputs otherwise makes a 1 s comb that
  matches itself at any whole second) and put on one time grid at the finer of the two frame rates.

At every lag the two signals' Pearson correlation over the samples they share is computed (FFT
and cumulative sums), over offsets within ``cfg.sync_max_lag_s`` where they share at least
``cfg.sync_min_overlap`` of the shorter one; the best is refined to a fraction of a sample by a
parabola through its neighbours. Its *runner-up* is the best correlation outside the peak's lobe
(the lags around it above half-way between it and the median) and, for audio, further than
``cfg.sync_audio_exclusion_s`` (a waveform peak rings at its dominant frequency). The
*confidence* is the share of the way from the runner-up to a perfect match that the peak goes.
A method refuses a flat signal (silence, a static scene), a peak below its minimum correlation
or a confidence below ``cfg.sync_min_confidence``; when audio refuses, motion is tried; when both
refuse, :class:`SyncError` says what each found.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from fractions import Fraction
from typing import Iterator

import av
import numpy as np

from ..config import Config
from ..errors import SyncError, VideoError
from .reader import open_input, probe_video

METHODS = ("audio", "motion")
WHAT = {"audio": "hear the same sounds", "motion": "see the same motion"}  # what a low peak means
MAD_TO_STD = 1.4826  # median absolute deviation x this = standard deviation, for normal noise


@dataclass(frozen=True)
class Signal:
    """``values[i]`` is sampled at ``start_s + i / rate_hz`` seconds on its input's video clock."""

    values: np.ndarray
    rate_hz: float
    start_s: float

    @property
    def span_s(self) -> float:
        return len(self.values) / self.rate_hz


@dataclass(frozen=True)
class Peak:
    """The correlation's best offset and its runner-up, the best one outside the peak's lobe (seconds)."""

    offset_s: float
    value: float
    runner_up_offset_s: float
    runner_up: float

    @property
    def confidence(self) -> float:
        """The share of the way from the runner-up to a perfect match that the peak goes: 0 to 1."""
        runner_up = max(self.runner_up, 0.0)
        return max(self.value - runner_up, 0.0) / (1.0 - runner_up) if runner_up < 1.0 else 0.0


@dataclass(frozen=True)
class SyncEstimate:
    """An accepted offset: ``offset_s`` as ``--offset`` takes it, and how it was found."""

    method: str
    peak: Peak
    span_s: tuple[float, float]  # seconds of the left and of the right signal that were correlated
    rate_hz: float  # sample rate of the correlated signals

    @property
    def offset_s(self) -> float:
        return self.peak.offset_s

    def summary(self) -> str:
        """One line for the user: method, offset in ms, confidence, what was correlated."""
        return (f"{self.method}, {self.offset_s * 1000:+.1f} ms, confidence {self.peak.confidence:.2f} "
                f"(correlation {self.peak.value:.2f}, runner-up {self.peak.runner_up:.2f} at "
                f"{self.peak.runner_up_offset_s * 1000:+.0f} ms; {self.span_s[0]:.1f} s / {self.span_s[1]:.1f} s)")

    def as_dict(self) -> dict:
        """The report's ``sync`` entry, JSON-ready."""
        return {
            "method": self.method,
            "offset_ms": round(self.offset_s * 1000, 3),
            "confidence": round(self.peak.confidence, 4),
            "correlation": round(self.peak.value, 4),
            "runner_up": {"offset_ms": round(self.peak.runner_up_offset_s * 1000, 3),
                          "correlation": round(self.peak.runner_up, 4)},
            "span_s": {"left": round(self.span_s[0], 3), "right": round(self.span_s[1], 3)},
            "rate_hz": round(self.rate_hz, 4),
        }


def estimate_offset(left: str | os.PathLike, right: str | os.PathLike, cfg: Config) -> SyncEstimate:
    """``--offset auto``: audio where both inputs have it, else (or when audio refuses) motion.

    Raises :class:`SyncError` naming what each method found when none gives a clear peak, and
    InputError, before anything is decoded, for frames above ``cfg.max_input_megapixels`` (as the
    stitch refuses them).
    """
    infos = probe_video(left, cfg.max_input_megapixels), probe_video(right, cfg.max_input_megapixels)
    both_audio = infos[0].has_audio and infos[1].has_audio
    refusals = [] if both_audio else ["audio: not both inputs have a track"]
    for method in METHODS if both_audio else METHODS[1:]:
        try:
            return measure_offset(left, right, method, cfg)
        except SyncError as exc:
            refusals.append(str(exc))
    raise SyncError(f"{left} and {right}: no clear time offset ({'; '.join(refusals)}); give --offset S")


def measure_offset(left: str | os.PathLike, right: str | os.PathLike, method: str, cfg: Config) -> SyncEstimate:
    """The offset by one method ("audio" or "motion"); :class:`SyncError` when its peak is not clear."""
    if method not in METHODS:
        raise VideoError(f"sync method {method!r} unknown; use one of {', '.join(METHODS)}")
    try:
        if method == "audio":
            signals = audio_signal(left, cfg), audio_signal(right, cfg)
        else:
            rate_hz = float(max(probe_video(left).fps, probe_video(right).fps))
            signals = motion_signal(left, rate_hz, cfg), motion_signal(right, rate_hz, cfg)
        exclusion_s = cfg.sync_audio_exclusion_s if method == "audio" else 0.0  # motion: the lobe alone
        min_overlap_s = max(cfg.sync_min_overlap_s, cfg.sync_min_overlap * min(s.span_s for s in signals))
        peak = correlate(*signals, cfg.sync_max_lag_s, exclusion_s, min_overlap_s)
        check_peak(peak, method, cfg)
    except SyncError as exc:
        raise SyncError(f"{method}: {exc}") from None
    return SyncEstimate(method, peak, (signals[0].span_s, signals[1].span_s), signals[0].rate_hz)


def check_peak(peak: Peak, method: str, cfg: Config) -> None:
    """Refuse (:class:`SyncError`) a peak too low for ``method`` or not clear of its runner-up."""
    min_peak = cfg.sync_audio_min_peak if method == "audio" else cfg.sync_motion_min_peak
    found = (f"best {peak.offset_s * 1000:+.1f} ms (correlation {peak.value:.2f}), runner-up "
             f"{peak.runner_up_offset_s * 1000:+.0f} ms ({peak.runner_up:.2f})")
    if peak.value < min_peak:
        raise SyncError(f"{found}: correlation below {min_peak:g}, the two inputs do not {WHAT[method]}")
    if peak.confidence < cfg.sync_min_confidence:
        raise SyncError(f"{found}: confidence {peak.confidence:.2f} < {cfg.sync_min_confidence:g}, ambiguous")


def correlate(left: Signal, right: Signal, max_lag_s: float, exclusion_s: float, min_overlap_s: float) -> Peak:
    """The offset (``--offset``'s sign) at which ``right`` best matches ``left``, within +-``max_lag_s``.

    Both signals must share one sample rate. At lag k, left sample n + k and right sample n show
    one event when the offset is ``k / rate + left.start_s - right.start_s``; the score is their
    Pearson correlation over the samples both have (sums over the overlap: one FFT for the cross
    products, cumulative sums for the means and variances), so a trend in a short window cannot
    pull the peak. Lags sharing less than ``min_overlap_s`` are not searched: a few samples
    correlate well by chance.
    """
    x, y = left.values - left.values.mean(), right.values - right.values.mean()
    size = 1 << (len(x) + len(y) - 1).bit_length()
    lags = np.arange(-(len(y) - 1), len(x))
    sum_xy = np.fft.irfft(np.fft.rfft(x, size) * np.conj(np.fft.rfft(y, size)), size)[lags % size]
    first, stop = np.maximum(0, -lags), np.minimum(len(y), len(x) - lags)  # overlap: right samples first..stop-1
    count = stop - first
    sum_x, var_x = _window_moments(x, first + lags, stop + lags)
    sum_y, var_y = _window_moments(y, first, stop)
    offsets_s = lags / left.rate_hz + (left.start_s - right.start_s)
    searched = (np.abs(offsets_s) <= max_lag_s) & (count >= min_overlap_s * left.rate_hz) & (var_x > 0) & (var_y > 0)
    if searched.sum() < 3:
        raise SyncError(f"the inputs share at most {min(len(x), len(y)) / left.rate_hz:.1f} s at the offsets "
                        f"searched (+-{max_lag_s:g} s); {min_overlap_s:.1f} s are needed")
    corr = np.zeros(len(lags))
    corr[searched] = ((sum_xy - sum_x * sum_y / np.maximum(count, 1))[searched]
                      / np.sqrt(var_x[searched] * var_y[searched]))
    best = int(np.flatnonzero(searched)[np.argmax(corr[searched])])
    # The peak's lobe: the lags around it above half-way between it and the median correlation.
    low = np.flatnonzero(~searched | (corr < (corr[best] + np.median(corr[searched])) / 2))
    lobe_first, lobe_last = low[low < best].max(initial=-1), low[low > best].min(initial=len(corr))
    index = np.arange(len(corr))
    away = (searched & ((index <= lobe_first) | (index >= lobe_last))
            & (np.abs(offsets_s - offsets_s[best]) > exclusion_s))
    runner = int(np.flatnonzero(away)[np.argmax(corr[away])]) if away.any() else best
    if not (0 < best < len(corr) - 1 and searched[best - 1] and searched[best + 1]):
        # The flank of a peak beyond the searched offsets is a confident-looking wrong answer.
        raise SyncError(f"the best offset, {offsets_s[best] * 1000:+.0f} ms, is at the edge of those searched "
                        f"(+-{max_lag_s:g} s, sharing {min_overlap_s:.1f} s): the true one may lie beyond")
    return Peak(float(offsets_s[best] + _parabolic_shift(corr, best) / left.rate_hz), float(corr[best]),
                float(offsets_s[runner]), float(corr[runner]) if away.any() else 0.0)


def _window_moments(values: np.ndarray, first: np.ndarray, stop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum and n x variance of ``values[first:stop]`` for each pair of bounds (cumulative sums)."""
    sums = np.concatenate(([0.0], np.cumsum(values)))
    squares = np.concatenate(([0.0], np.cumsum(np.square(values))))
    count = np.maximum(stop - first, 1)
    total = sums[stop] - sums[first]
    deviations = squares[stop] - squares[first] - total**2 / count
    # A constant window has variance 0 up to rounding: below 1e-9 of the whole signal's, it is 0.
    return total, np.where(deviations > 1e-9 * count * values.var(), deviations, 0.0)


def _parabolic_shift(values: np.ndarray, i: int) -> float:
    """Sub-sample position of the maximum at ``i``: vertex of the parabola through i - 1, i, i + 1."""
    before, at, after = values[i - 1], values[i], values[i + 1]
    curvature = before - 2 * at + after
    return float(np.clip(0.5 * (before - after) / curvature, -0.5, 0.5)) if curvature < 0 else 0.0


def _decoded(container: av.container.InputContainer, stream: av.stream.Stream) -> Iterator[av.frame.Frame]:
    """The stream's frames in order; packets that fail to decode are skipped, as the reader skips them."""
    for packet in container.demux(stream):
        try:
            frames = packet.decode()
        except av.error.InvalidDataError:
            continue
        yield from frames


def audio_signal(path: str | os.PathLike, cfg: Config) -> Signal:
    """The first ``cfg.sync_audio_span_s`` of the input's audio, mono at ``cfg.sync_audio_rate_hz``.

    Samples are placed by their timestamps (a gap stays silent); ``start_s`` is the first sample's
    time on the input's video clock. Raises :class:`SyncError` on a track without sound.
    """
    rate = cfg.sync_audio_rate_hz
    samples = np.zeros(round(cfg.sync_audio_span_s * rate), np.float32)
    first = end = None
    try:
        with open_input(path) as container:
            if not container.streams.audio:
                raise SyncError(f"{path} has no audio track")
            video = container.streams.video[0]
            video_start_s = Fraction(video.start_time or 0) * Fraction(video.time_base)
            resampler = av.AudioResampler(format="flt", layout="mono", rate=rate)
            for frame in _decoded(container, container.streams.audio[0]):
                if frame.pts is None:
                    continue
                for mono in resampler.resample(frame):
                    at = round(mono.pts * mono.time_base * rate)
                    first = at if first is None else first
                    chunk = mono.to_ndarray()[0, : max(len(samples) - (at - first), 0)]
                    samples[at - first : at - first + len(chunk)] = chunk
                    end = max(end or 0, at - first + len(chunk))
                if end == len(samples):
                    break
    except av.error.FFmpegError as exc:
        raise VideoError(f"{path}: decoding its audio failed ({exc.strerror})") from exc
    rms = float(np.sqrt(np.mean(np.square(samples[:end], dtype=np.float64)))) if end else 0.0
    if rms < cfg.sync_audio_min_rms:
        raise SyncError(f"{path} is silent over its first {cfg.sync_audio_span_s:g} s "
                        f"(rms {rms:.1e} < {cfg.sync_audio_min_rms:g})")
    return Signal(samples[:end], float(rate), float(Fraction(first, rate) - video_start_s))


def motion_signal(path: str | os.PathLike, rate_hz: float, cfg: Config) -> Signal:
    """Frame-difference energy (grey levels) of the first ``cfg.sync_motion_span_s``, every 1/``rate_hz`` s.

    Each energy is the mean absolute difference of two consecutive luma frames downscaled to a
    long side of ``cfg.sync_motion_side_px``, placed halfway between their times, then
    median-filtered over ``cfg.sync_motion_median_frames`` (see the module's notes). Raises
    :class:`SyncError` when nothing moves (robust spread of the energy below ``cfg.sync_motion_min_spread``).
    """
    times_s: list[float] = []
    energy: list[float] = []
    previous = None
    try:
        with open_input(path) as container:
            stream = container.streams.video[0]
            stream.thread_type = "AUTO"  # before the codec opens
            time_base, start_pts = Fraction(stream.time_base), stream.start_time or 0
            for frame in _decoded(container, stream):
                if frame.pts is None:
                    continue
                time_s = float((frame.pts - start_pts) * time_base)
                if time_s > cfg.sync_motion_span_s:
                    break
                luma = _small_luma(frame, cfg.sync_motion_side_px)
                if previous is not None:
                    times_s.append((previous[0] + time_s) / 2)
                    energy.append(float(np.abs(luma - previous[1]).mean()))
                previous = (time_s, luma)
    except av.error.FFmpegError as exc:
        raise VideoError(f"{path}: decoding its video failed ({exc.strerror})") from exc
    if len(energy) < 3:
        raise SyncError(f"{path} has too few frames to measure motion")
    grid_s = np.arange(times_s[0], times_s[-1], 1 / rate_hz)
    values = np.interp(grid_s, times_s, _running_median(np.asarray(energy), cfg.sync_motion_median_frames))
    spread = MAD_TO_STD * float(np.median(np.abs(values - np.median(values))))  # robust: a glitch is no motion
    if spread < cfg.sync_motion_min_spread:
        raise SyncError(f"nothing moves in {path} over its first {cfg.sync_motion_span_s:g} s "
                        f"(frame-difference spread {spread:.3f} < {cfg.sync_motion_min_spread:g} grey levels)")
    return Signal(values, rate_hz, times_s[0])


def _small_luma(frame: av.VideoFrame, long_side_px: int) -> np.ndarray:
    """The frame's luma as float32, area-downscaled so its long side is ``long_side_px``."""
    scale = long_side_px / max(frame.width, frame.height)
    width, height = max(round(frame.width * scale), 1), max(round(frame.height * scale), 1)
    small = frame.reformat(width=width, height=height, format="gray", interpolation="AREA")
    return small.to_ndarray().astype(np.float32)


def _running_median(values: np.ndarray, width: int) -> np.ndarray:
    """Median over ``width`` (odd) neighbouring samples; the ends repeat the end samples."""
    padded = np.pad(values, width // 2, mode="edge")
    return np.median(np.lib.stride_tricks.sliding_window_view(padded, width), axis=1)
