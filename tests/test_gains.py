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
        return np.abs(compensated(views.src, g.gain_src, g.bias_src, g.knee_grey).astype(float).mean(axis=(0, 1))
                      - compensated(views.tgt, g.gain_tgt, g.bias_tgt, g.knee_grey).mean(axis=(0, 1)))

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
        src = compensated(views.src, gains.gain_src, gains.bias_src, knee).astype(float)
        tgt = compensated(views.tgt, gains.gain_tgt, gains.bias_tgt, knee).astype(float)
        return float(np.mean(src[clipped] - tgt[clipped]))

    assert gap(255.0) > 8 and abs(gap(CFG.gain_knee_ratio * 255)) < 0.5 * gap(255.0)
