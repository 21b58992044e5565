"""Step 5 host path: gate_canvas and guard_field on a real pair's overlap."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.gate import gate_canvas, guard_field, inlier_density, inside_distance_px, ramp_width_px
from test_kernels_maps import gate_reference, load_pair, scene_geometry, smooth_field


@pytest.fixture(scope="module")
def setup(shared_dir):
    img_src, img_tgt = load_pair(shared_dir)
    geo = scene_geometry(img_src.shape, img_tgt.shape)
    h, w = img_tgt.shape[:2]
    mask = geo["overlap_mask_canvas"]
    ys, xs = np.nonzero(mask)
    # Inliers only in the upper half of the overlap, so the lower half is "sparse".
    rng = np.random.default_rng(5)
    upper = ys < np.median(ys)
    pick = rng.choice(np.flatnonzero(upper), size=300, replace=False)
    inliers_canvas = np.stack([xs[pick], ys[pick]], axis=1).astype(np.float64)
    diag, long_side = math.hypot(w, h), max(w, h)
    gate = gate_canvas(mask, inliers_canvas, diag, long_side, Config())
    return geo, mask, inliers_canvas, diag, long_side, gate


def test_ramp_width():
    cfg = Config()
    assert ramp_width_px(300.0, cfg) == cfg.ramp_min_px
    assert ramp_width_px(1000.0, cfg) == pytest.approx(cfg.ramp_diag_ratio * 1000.0)


def test_gate_matches_formula_and_is_zero_outside_overlap(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    cfg = Config()
    assert gate.shape == mask.shape and gate.dtype == np.float32
    sdf = inside_distance_px(mask)
    density = inlier_density(mask.shape, inliers_canvas, cfg.sigma_d_ratio * long_side)
    assert density.max() == pytest.approx(1.0)
    np.testing.assert_allclose(gate, gate_reference(sdf, density, ramp_width_px(diag, cfg), cfg), atol=1e-5)
    assert gate[~mask].max() == 0.0
    assert 0.0 <= gate.min() and gate.max() <= 1.0


def test_gate_is_high_where_supported_and_floored_where_sparse(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    cfg = Config()
    deep = inside_distance_px(mask) >= ramp_width_px(diag, cfg)
    ys = np.nonzero(deep)[0]
    upper, lower = np.percentile(ys, 25), np.percentile(ys, 90)
    rows = np.arange(mask.shape[0])[:, None]
    assert gate[deep & (np.abs(rows - upper) < 5)].max() > 0.8  # density peaks are spread over 300 random inliers
    sparse = gate[deep & (rows > lower)]
    assert sparse.size and sparse.max() < cfg.gamma_min + 0.1


def test_guard_field_blurs_the_gated_product_and_vanishes_far_outside(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    cfg = Config()
    field = smooth_field(mask.shape, 20.0)
    guarded = guard_field(field, gate, cfg)
    expected = cv2.GaussianBlur((gate[..., None] * field).astype(np.float32), (0, 0), cfg.sigma_g_px)
    np.testing.assert_allclose(guarded, expected, atol=1e-4)
    far = cv2.distanceTransform((gate == 0).astype(np.uint8), cv2.DIST_L2, 5) > 6 * cfg.sigma_g_px
    assert np.abs(guarded[far]).max() < 1e-3
    assert np.abs(guarded[mask]).max() > 5.0
