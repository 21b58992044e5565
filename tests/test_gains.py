"""Exposure compensation: Brown & Lowe's gains, the pixels they trust, OpenCV's compensator, a real pair."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.gains import (agreeing_pixels, brown_lowe_gains, compensated, opencv_gains, overlap_gains,
                             tone_curve)
from sena_warp.imageio import read_image
from sena_warp.warp_map import CanvasViews

BUNDLED = Path(__file__).resolve().parent / "data"
CFG = Config()


def test_brown_lowe_closed_form_meets_its_normal_equations():
    mean_src, mean_tgt = np.array([150.0, 120.0, 90.0]), np.array([120.0, 120.0, 100.0])
    g_src, g_tgt = brown_lowe_gains(mean_src, mean_tgt, CFG)
    inv_n, inv_g = 1 / CFG.gain_sigma_n**2, 1 / CFG.gain_sigma_g**2
    diff = g_src * mean_src - g_tgt * mean_tgt
    np.testing.assert_allclose(mean_src * diff * inv_n - (1 - g_src) * inv_g, 0, atol=1e-9)
    np.testing.assert_allclose(-mean_tgt * diff * inv_n - (1 - g_tgt) * inv_g, 0, atol=1e-9)
    # The brighter source is darkened, the target brightened; equal channels stay at 1.
    assert g_src[0] < 1 < g_tgt[0] and g_src[1] == pytest.approx(1) and g_tgt[1] == pytest.approx(1)
    assert abs(diff[0]) < abs(mean_src[0] - mean_tgt[0]) / 5


def test_agreeing_pixels_leave_out_saturation_and_the_largest_differences():
    rng = np.random.default_rng(0)
    src = rng.uniform(20, 200, (1000, 3))
    tgt = src.copy()
    tgt[:100] += 60  # misaligned content
    src[100:110] = 255  # saturated
    keep = agreeing_pixels(src, tgt, CFG)
    assert not keep[100:110].any() and not keep[:100].any()
    assert keep[110:].mean() > 0.85


def views_with_exposure(img: np.ndarray, factor: np.ndarray) -> CanvasViews:
    """The same image as both views, the target at another exposure (per channel), full overlap."""
    tgt = np.clip(img * factor, 0, 255).astype(np.uint8)
    valid = np.ones(img.shape[:2], bool)
    return CanvasViews(img, tgt, valid, valid)


def test_overlap_gains_undo_an_exposure_difference_on_a_real_image():
    img = read_image(BUNDLED / "udisd_test_000001" / "a.jpg")
    factor = np.array([0.8, 0.85, 0.9])
    views = views_with_exposure(img, factor)
    def mean_step(g) -> np.ndarray:
        """Per channel |mean source - mean target| after the gains (grey levels)."""
        src = compensated(views.src, g.gain_src, g.bias_src, g.knee_grey, g.knee_peak).astype(float)
        tgt = compensated(views.tgt, g.gain_tgt, g.bias_tgt, g.knee_grey, g.knee_peak)
        return np.abs(src.mean(axis=(0, 1)) - tgt.mean(axis=(0, 1)))

    gains = overlap_gains(views.src, views.tgt, views.both, CFG)
    before = np.abs(views.src.astype(float).mean(axis=(0, 1)) - views.tgt.mean(axis=(0, 1)))
    assert np.all(before > 10) and np.all(mean_step(gains) < 1.0)  # measured: 21/10/13 -> 0.6/0.7/0.2
    np.testing.assert_allclose(gains.gain_tgt / gains.gain_src, 1 / factor, rtol=0.02)
    # The reference to beat: OpenCV's compensator (sigma_g 0.1, every pixel) leaves several levels.
    assert np.all(mean_step(opencv_gains(views)) > 2 * mean_step(gains))


def test_too_few_agreeing_pixels_give_the_identity():
    img = np.full((10, 10, 3), 128, np.uint8)
    views = views_with_exposure(img, np.ones(3))
    gains = overlap_gains(views.src, views.tgt, views.both, CFG)
    assert gains.pixels == 0 and np.all(gains.gain_src == 1) and np.all(gains.gain_tgt == 1)


def test_the_tone_curve_is_the_gain_below_the_knee_and_keeps_white_white():
    values = np.arange(256, dtype=np.float32)[:, None]
    for gain in (0.8, 0.88, 1.0, 1.09):
        curve = tone_curve(values, np.array([gain]), np.array([0.0]), 0.9 * 255)[:, 0]
        np.testing.assert_allclose(curve[:230], gain * values[:230, 0], rtol=1e-6)
        assert curve[255] == pytest.approx(255.0) and np.all(np.diff(curve) > 0)
    # A gain that takes the knee itself past white clips as before.
    np.testing.assert_allclose(tone_curve(values, np.array([1.2]), np.array([0.0]), 0.9 * 255)[:, 0], 1.2 * values[:, 0])
    # No knee (ratio 1): the affine gain, clipping above white.
    np.testing.assert_allclose(tone_curve(values, np.array([0.9]), np.array([2.0]), 255.0)[:, 0], 0.9 * values[:, 0] + 2)


def test_with_the_knee_a_saturated_view_stays_as_white_as_the_other_one():
    """A real image and a copy 30 % brighter (its highlights clipped to 255): the gains match the two
    over the pixels that agree; without a knee the brighter view's clipped whites come out grey
    (255 x its gain < 1), darker than the other view's copy of them; with it, less than half as much."""
    img = read_image(BUNDLED / "udisd_test_000001" / "a.jpg")
    views = views_with_exposure(img, np.array([1.3, 1.3, 1.3]))
    gains = overlap_gains(views.src, views.tgt, views.both, CFG)
    clipped = (views.tgt == 255).all(axis=2) & (img.min(axis=2) > 200)
    assert gains.gain_tgt.max() < 1 and clipped.sum() > 500

    def gap(knee: float) -> float:
        src = compensated(views.src, gains.gain_src, gains.bias_src, knee, gains.knee_peak).astype(float)
        tgt = compensated(views.tgt, gains.gain_tgt, gains.bias_tgt, knee, gains.knee_peak).astype(float)
        return float(np.mean(src[clipped] - tgt[clipped]))

    assert gap(255.0) > 8 and abs(gap(CFG.gain_knee_ratio * 255)) < 0.5 * gap(255.0)


def test_the_knee_by_peak_makes_no_colour_where_each_channel_s_own_knee_does():
    """Gains far from 1 and unequal per channel (B 0.8, G 1.0, R 1.25: a view made much warmer). A light grey-brown
    ramp (RGB in the ratio 1 : 0.95 : 0.9, its top past the knee, its red clipped at the end): with a pixel's
    channels sharing its largest one's knee as it nears white every channel's factor (output / input) lies
    between its gain and 1, and where the red clips the pixel comes out as it went in; each channel through its
    own knee leaves blue its gain of 0.8 there while red stays 255, and the clipped grey-brown comes out orange.
    Clipped white stays white either way; a bluish near-white (rew_theater's target sky, RGB 248 252 255, gains
    0.88-0.91) keeps its own spread by the peak and nearly doubles it channel by channel (7 -> 12 levels). A
    blue sky whose red and green are mid-tones (railtracks's) is not near white: it keeps each channel's own
    knee, its red and green their gains, the exposure matched across the seam."""
    gain, bias, knee = np.array([0.8, 1.0, 1.25]), np.zeros(3), CFG.gain_knee_ratio * 255
    level = np.linspace(150, 255, 106, dtype=np.float32)[:, None]
    ramp = level * np.array([0.9, 0.95, 1.0], np.float32)  # BGR
    by_peak = tone_curve(ramp, gain, bias, knee, shared=True)
    factor = by_peak / ramp
    assert np.all(factor >= np.minimum(gain, 1) - 1e-5) and np.all(factor <= np.maximum(gain, 1) + 1e-5)
    hue_in = np.log(ramp[-1, 0] / ramp[-1, 2])  # blue against red
    assert np.log(by_peak[-1, 0] / by_peak[-1, 2]) == pytest.approx(hue_in, abs=0.01)
    own = np.minimum(tone_curve(ramp, gain, bias, knee), 255)
    assert np.log(own[-1, 0] / own[-1, 2]) < hue_in - 0.15  # each channel's own knee: the top turns orange
    white = np.full((1, 3), 255, np.float32)
    for shared in (True, False):
        np.testing.assert_allclose(np.minimum(tone_curve(white, gain, bias, knee, shared=shared), 255), 255)
    sky = np.array([[255, 252, 248]], np.uint8)[None]  # BGR
    theater = np.array([0.8837, 0.8966, 0.9078])

    def spread(by: bool) -> int:
        out = compensated(sky, theater, np.zeros(3), knee, by).astype(int)
        return int(out.max() - out.min())

    assert spread(True) <= 7 and spread(False) >= 11
    blue_sky = np.array([[245.0, 200.0, 138.0]], np.float32)  # BGR
    for g in (np.full(3, 0.97), np.full(3, 1.03)):
        np.testing.assert_allclose(tone_curve(blue_sky, g, bias, knee, shared=True),
                                   tone_curve(blue_sky, g, bias, knee), atol=1e-4)


def test_compensated_by_peak_is_the_tone_curve_of_each_pixel():
    """The image path's views (a table for pixels not near white, the rest worked out again) give the
    tone curve with each pixel's channels sharing its knee, rounded."""
    rng = np.random.default_rng(3)
    img = rng.integers(180, 256, size=(40, 50, 3), dtype=np.uint8)
    gain, bias, knee = np.array([0.85, 1.05, 1.2]), np.array([1.0, 0.0, -2.0]), CFG.gain_knee_ratio * 255
    values = img.reshape(-1, 3).astype(np.float32)
    expected = tone_curve(values, gain, bias, knee, shared=True)
    out = compensated(img, gain, bias, knee, True).reshape(-1, 3).astype(np.float32)
    assert np.abs(out - np.clip(expected, 0, 255)).max() <= 0.5 + 1e-3
