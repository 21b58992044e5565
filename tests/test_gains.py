"""Exposure compensation: Brown & Lowe's gains, the pixels they trust, OpenCV's compensator, a real pair."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.gains import agreeing_pixels, brown_lowe_gains, compensated, opencv_gains, overlap_gains
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
        return np.abs(compensated(views.src, g.gain_src, g.bias_src).astype(float).mean(axis=(0, 1))
                      - compensated(views.tgt, g.gain_tgt, g.bias_tgt).mean(axis=(0, 1)))

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
