"""The host's one bilinear rule: exact on affine grids, NaN outside, every dtype and channel count."""

from __future__ import annotations

import numpy as np

from sena_warp.bilinear import sample_bilinear


def test_sample_is_exact_on_affine_maps():
    ys, xs = np.mgrid[0:30, 0:40].astype(np.float64)
    m = np.dstack([0.95 * xs + 0.05 * ys + 4, -0.03 * xs + 1.02 * ys - 2]).astype(np.float32)
    pts = np.array([[3.25, 7.5], [39.0, 29.0], [0.0, 0.0]])
    expected = np.stack([0.95 * pts[:, 0] + 0.05 * pts[:, 1] + 4, -0.03 * pts[:, 0] + 1.02 * pts[:, 1] - 2], -1)
    np.testing.assert_allclose(sample_bilinear(m, pts), expected, atol=1e-4)


def test_outside_and_nan_positions_are_nan_not_clamped():
    m = np.zeros((30, 40, 2), np.float32)
    out = sample_bilinear(m, np.array([[-0.1, 3.0], [10.0, 29.5], [np.nan, 1.0], [39.0, 29.0]]))
    assert np.isnan(out[:3]).all() and np.isfinite(out[3]).all()


def test_planes_and_images_blend_the_four_taps():
    plane = np.array([[0, 10], [20, 30]], np.uint8)
    np.testing.assert_allclose(sample_bilinear(plane, np.array([[0.5, 0.5], [1.0, 0.25], [0.0, 1.0]])), [15.0, 15.0, 20.0])
    image = np.dstack([plane, 2 * plane]).astype(np.uint8)
    np.testing.assert_allclose(sample_bilinear(image, np.array([[0.25, 0.0]])), [[2.5, 5.0]])
