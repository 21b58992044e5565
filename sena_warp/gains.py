"""Exposure compensation: one gain per channel and view (Brown & Lowe, IJCV 2007, section 6).

The two views of a pair rarely share one exposure and white balance, and without compensation the
seam shows a brightness or colour step. Over the overlap, with mean intensities mu_s and
mu_t of the warped source and the placed target (per channel), the gains minimise

    (g_s mu_s - g_t mu_t)^2 / sigma_n^2 + ((1 - g_s)^2 + (1 - g_t)^2) / sigma_g^2,

the data term pulling the two means together, the prior keeping both gains near 1 (sigma_n = 10
grey levels as Brown & Lowe; their sigma_g = 0.1, also OpenCV's ``ChannelsCompensator``'s, leaves a
quarter of a 30-level difference in place for the pair to show, so ours is 0.5: the two views meet
halfway). Unlike OpenCV's compensator the means are taken over the pixels that agree: the largest
differences (misalignment, parallax, moving objects) and near-saturated pixels are left out, so what
is measured is the exposure, not the content.

A gain below 1 turns a view's saturated white grey, one above 1 clips its highlights flat: either way
the two views' skies disagree however well their mid-tones are matched (rew_theater's sky). So a
gain applies in full up to a knee (``Config.gain_knee_ratio`` x white) and above it the line runs
straight on to white (``tone_curve``; the compositor's kernel applies the same rule).

Each channel through its own knee (``Config.gain_knee_peak`` False), a gain below 1 gives the line
above the knee a slope near 2: the small differences between the channels of a near-white pixel
double, and a bluish-white sky turns blue (rew_theater's target: (248, 252, 255) -> (243, 249, 255),
beside the source's (250, 252, 254)); and a pixel whose red alone clips keeps the gains' tint in its
other channels, so a warm gain turns a clipped grey-brown orange. So (True) the channels near the
pixel's largest one, its *peak*, share the peak's knee: ``bias + (line(peak) - bias) x value / peak``,
one factor per channel that runs from its gain at the knee to 1 at white, which fades the gains'
tint and makes no colour of its own (a clipped white stays the neutral it was). How near white a
pixel is, its smallest channel says: from a knee's width below the knee (none) to the knee (all) its
channels move from their own lines to the shared one. A blue sky whose blue alone nears white keeps
each channel's own line, its red and green their gains, matched across the seam (railtracks: with
every pixel sharing its peak's knee the sky's green stepped 11 levels there).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import cv2
import numpy as np

from .config import Config
from .errors import InputError
from .warp_map import CanvasViews

WHITE = 255.0  # white of the 8-bit images the gains apply to


@dataclass(frozen=True)
class Gains:
    """Per-channel affine gains of both views: ``value' = gain * value + bias`` (grey levels).

    ``gain_src``, ``bias_src``, ``gain_tgt``, ``bias_tgt``: (C,) float64. ``pixels``: how many overlap
    pixels the estimate used (0: none, the gains are the identity); ``model``: ``Config.gain_model``;
    ``knee_grey``: where the highlight knee starts (``tone_curve``; 255: none); ``knee_peak``: the
    knee follows each pixel's largest channel (``Config.gain_knee_peak``).
    """

    gain_src: np.ndarray
    bias_src: np.ndarray
    gain_tgt: np.ndarray
    bias_tgt: np.ndarray
    pixels: int
    model: str
    knee_grey: float = 255.0
    knee_peak: bool = False

    @staticmethod
    def identity(channels: int, model: str) -> "Gains":
        ones, zeros = np.ones(channels), np.zeros(channels)
        return Gains(ones, zeros, ones.copy(), zeros.copy(), 0, model)


def agreeing_pixels(values_src: np.ndarray, values_tgt: np.ndarray, cfg: Config) -> np.ndarray:
    """(N,) bool over (N, C) pixel values of both views: not near saturation on either side and
    not among the ``cfg.gain_outlier_fraction`` largest differences."""
    values_src = np.asarray(values_src, np.float64)
    values_tgt = np.asarray(values_tgt, np.float64)
    unsaturated = np.all((values_src > cfg.gain_dark_level) & (values_src < cfg.gain_bright_level)
                         & (values_tgt > cfg.gain_dark_level) & (values_tgt < cfg.gain_bright_level), axis=1)
    diff = np.abs(values_src.mean(axis=1) - values_tgt.mean(axis=1))
    if not unsaturated.any():
        return unsaturated
    limit = np.quantile(diff[unsaturated], 1.0 - cfg.gain_outlier_fraction)
    return unsaturated & (diff <= limit)


def brown_lowe_gains(mean_src: np.ndarray, mean_tgt: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """(g_src, g_tgt), each (C,), minimising the module docstring's error for per-channel means (C,)."""
    inv_n, inv_g = 1.0 / cfg.gain_sigma_n**2, 1.0 / cfg.gain_sigma_g**2
    gains_src, gains_tgt = [], []
    for ms, mt in zip(np.asarray(mean_src, np.float64), np.asarray(mean_tgt, np.float64)):
        system = np.array([[ms * ms * inv_n + inv_g, -ms * mt * inv_n], [-ms * mt * inv_n, mt * mt * inv_n + inv_g]])
        g_src, g_tgt = np.linalg.solve(system, [inv_g, inv_g])
        gains_src.append(g_src)
        gains_tgt.append(g_tgt)
    return np.array(gains_src), np.array(gains_tgt)


def overlap_gains(warped_src: np.ndarray, placed_tgt: np.ndarray, both_valid: np.ndarray, cfg: Config) -> Gains:
    """Gains of the two views from their overlap on the canvas.

    warped_src, placed_tgt: (H, W, C) or (H, W) uint8 canvas images; both_valid: (H, W) bool where both
    are defined. Every ``cfg.gain_stride``-th pixel in each direction is used. The identity when
    too few pixels agree (``cfg.gain_min_pixels``).
    """
    stride = max(1, cfg.gain_stride)
    mask = both_valid[::stride, ::stride]
    src = np.asarray(warped_src)[::stride, ::stride][mask].reshape(int(mask.sum()), -1)
    tgt = np.asarray(placed_tgt)[::stride, ::stride][mask].reshape(int(mask.sum()), -1)
    channels = src.shape[1]
    keep = agreeing_pixels(src, tgt, cfg) if len(src) else np.zeros(0, bool)
    if keep.sum() < cfg.gain_min_pixels:
        return Gains.identity(channels, "channels")
    gain_src, gain_tgt = brown_lowe_gains(src[keep].mean(axis=0), tgt[keep].mean(axis=0), cfg)
    zeros = np.zeros(channels)
    return Gains(gain_src, zeros, gain_tgt, zeros.copy(), int(keep.sum()), "channels")


def opencv_gains(views: CanvasViews) -> Gains:
    """The reference to beat: OpenCV's ``ChannelsCompensator`` (Brown & Lowe's gains per channel, over
    every overlap pixel) fed the two canvas views; (C,) gains, no bias."""
    compensator = cv2.detail.ExposureCompensator_createDefault(cv2.detail.ExposureCompensator_CHANNELS)
    masks = [cv2.UMat((valid * 255).astype(np.uint8)) for valid in (views.valid_src, views.valid_tgt)]
    compensator.feed(corners=[(0, 0), (0, 0)], images=[cv2.UMat(views.src), cv2.UMat(views.tgt)], masks=masks)
    channels = views.src.shape[2]
    gain_src, gain_tgt = (np.asarray(g, np.float64).ravel()[:channels] for g in compensator.getMatGains())
    zeros = np.zeros(channels)
    return Gains(gain_src, zeros, gain_tgt, zeros.copy(), int(views.both.sum()), "opencv")


def view_gains(views: CanvasViews, cfg: Config) -> Gains:
    """The gains of ``cfg.gain_model``: "channels" (``overlap_gains``), "opencv" (``opencv_gains``) or
    "none" (the paper: no compensation), with the knee of ``cfg.gain_knee_ratio`` and ``cfg.gain_knee_peak``."""
    knee = WHITE * cfg.gain_knee_ratio
    if cfg.gain_model == "channels":
        gains = overlap_gains(views.src, views.tgt, views.both, cfg)
        return replace(gains, knee_grey=knee, knee_peak=cfg.gain_knee_peak)
    if cfg.gain_model == "opencv":
        return replace(opencv_gains(views), knee_grey=knee, knee_peak=cfg.gain_knee_peak)
    if cfg.gain_model == "none":
        return Gains.identity(views.src.shape[2], "none")
    raise InputError(f"unknown gain model {cfg.gain_model!r}; choose channels, opencv or none")


def tone_curve(values: np.ndarray, gain: np.ndarray, bias: np.ndarray, knee: float, white: float = WHITE,
               shared: bool = False) -> np.ndarray:
    """``gain * values + bias`` per channel (last axis) up to ``knee``; above it the line from the knee's
    value runs straight on to (white, white), so white stays white whatever the gain (float32).
    No knee where ``knee >= white`` or the knee's value is already white (a gain that large clips).
    ``shared``: the last axis is one pixel's channels, which share its largest channel's knee as the
    pixel nears white (the module docstring's rule); else each channel has its own."""
    values = np.asarray(values, np.float32)
    gain, bias = np.asarray(gain, np.float32), np.asarray(bias, np.float32)
    out = values * gain + bias
    at_knee = knee * gain + bias
    if knee >= white:
        return out

    def line(v):  # the gain's line bent at the knee, at v > knee
        return np.where(at_knee < white, at_knee + (v - knee) * (white - at_knee) / (white - knee), v * gain + bias)

    own = np.where(values > knee, line(values), out)
    if not shared:
        return own
    peak, floor = values.max(axis=-1, keepdims=True), values.min(axis=-1, keepdims=True)
    by_peak = bias + (np.minimum(line(peak), white) - bias) * values / np.maximum(peak, knee)
    near = np.clip((floor - (2 * knee - white)) / (white - knee), 0, 1)  # 1 from the knee on, 0 a knee's width below
    return np.where(peak > knee, own + near * (by_peak - own), own)


def compensated(img: np.ndarray, gain: np.ndarray, bias: np.ndarray, knee: float, by_peak: bool) -> np.ndarray:
    """:func:`tone_curve` of a uint8 (H, W, C) image (C <= 4), rounded and clipped to uint8: the curve
    is evaluated at the 256 levels once and looked up (``cv2.LUT``); ``by_peak``: a pixel's channels
    share its knee (``tone_curve``'s ``shared``), worked out again at the pixels near white."""
    levels = np.repeat(np.arange(256, dtype=np.float32)[:, None], img.shape[2], axis=1)
    table = np.clip(tone_curve(levels, gain, bias, knee) + 0.5, 0, 255).astype(np.uint8)
    out = cv2.LUT(img, table.reshape(256, 1, img.shape[2])).reshape(img.shape)
    if by_peak and img.shape[2] >= 3 and knee < WHITE:
        planes = cv2.split(img)  # OpenCV's per-pixel max and min: numpy's over the last axis took 40 ms a view
        near = (functools.reduce(cv2.max, planes) > knee) & (functools.reduce(cv2.min, planes) > 2 * knee - WHITE)
        out[near] = np.clip(tone_curve(img[near], gain, bias, knee, shared=True) + 0.5, 0, 255).astype(np.uint8)
    return out


def compensated_views(views: CanvasViews, gains: Gains) -> CanvasViews:
    """The views as they enter the panorama: each with its side's gains (and their knee)."""
    def each(img, gain, bias):
        return compensated(img, gain, bias, gains.knee_grey, gains.knee_peak)

    return CanvasViews(each(views.src, gains.gain_src, gains.bias_src), each(views.tgt, gains.gain_tgt, gains.bias_tgt),
                       views.valid_src, views.valid_tgt)
