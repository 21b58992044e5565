"""Step 5 host path: gate_canvas and guard_field on a real pair's overlap."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.gate import gate_canvas, guard_field, inlier_density, open_border_distance_px, ramp_width_px
from test_kernels_maps import gate_reference, scene_geometry, smooth_field

CFG = Config(device="cpu")


@pytest.fixture(scope="module")
def setup(udisd_pair):
    img_src, img_tgt = udisd_pair
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
    gate = gate_canvas(geo["source_only_canvas"], inliers_canvas, diag, long_side, CFG)
    return geo, mask, inliers_canvas, diag, long_side, gate


def test_ramp_width():
    assert ramp_width_px(300.0, CFG) == CFG.ramp_min_px
    assert ramp_width_px(1000.0, CFG) == pytest.approx(CFG.ramp_diag_ratio * 1000.0)


def test_gate_matches_formula_and_is_zero_where_the_source_is_alone(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    source_only = geo["source_only_canvas"]
    assert gate.shape == mask.shape and gate.dtype == np.float32
    sdf = open_border_distance_px(source_only)
    density = inlier_density(mask.shape, inliers_canvas, CFG.sigma_d_ratio * long_side)
    assert density.max() == pytest.approx(1.0)
    np.testing.assert_allclose(gate, gate_reference(sdf, density, ramp_width_px(diag, CFG), CFG), atol=1e-5)
    assert gate[source_only].max() == 0.0
    assert 0.0 <= gate.min() and gate.max() <= 1.0 + 1e-6  # float32 rounding of gamma_min + (1 - gamma_min)


def test_ramp_starts_only_at_the_source_only_border(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    sdf = open_border_distance_px(geo["source_only_canvas"])
    # Overlap pixels on the overlap's right border (where the source ends, target continues) are far
    # from the source-only region: the gate is not pulled to 0 there.
    right_edge = mask & ~np.roll(mask, -1, axis=1)
    far_edge = right_edge & (sdf > ramp_width_px(diag, CFG))
    assert far_edge.any() and gate[far_edge].min() >= CFG.gamma_min * 0.99
    # Next to the source-only region the gate is 0 and rises over the ramp.
    near = mask & (sdf < 2.0)
    assert gate[near].max() < 0.01
    assert open_border_distance_px(np.zeros((5, 7), bool)).min() == pytest.approx(np.hypot(5, 7))


def test_gate_is_high_where_supported_and_floored_where_sparse(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    deep = mask & (open_border_distance_px(geo["source_only_canvas"]) >= ramp_width_px(diag, CFG))
    ys = np.nonzero(deep)[0]
    upper, lower = np.percentile(ys, 25), np.percentile(ys, 90)
    rows = np.arange(mask.shape[0])[:, None]
    assert gate[deep & (np.abs(rows - upper) < 5)].max() > 0.8  # density peaks are spread over 300 random inliers
    sparse = gate[deep & (rows > lower)]
    assert sparse.size and sparse.max() < CFG.gamma_min + 0.1


def test_guard_field_blurs_the_gated_product_and_vanishes_far_outside(setup):
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    field = smooth_field(mask.shape, 20.0)
    guarded = guard_field(field, gate, CFG)
    expected = cv2.GaussianBlur((gate[..., None] * field).astype(np.float32), (0, 0), CFG.sigma_g_px)
    np.testing.assert_allclose(guarded, expected, atol=1e-4)
    far = cv2.distanceTransform((gate == 0).astype(np.uint8), cv2.DIST_L2, 5) > 6 * CFG.sigma_g_px
    assert np.abs(guarded[far]).max() < 1e-3
    assert np.abs(guarded[mask]).max() > 5.0


@pytest.mark.parametrize("sigma_px", [90.0, 24.0])
def test_coarse_density_equals_the_full_resolution_blur(setup, sigma_px):
    """The coarse-grid density is the full-resolution blur of the splat (no points beyond the canvas)."""
    geo, mask, inliers_canvas, diag, long_side, gate = setup
    splat = np.zeros(mask.shape, np.float32)
    pts = np.rint(inliers_canvas).astype(int)
    np.add.at(splat, (pts[:, 1], pts[:, 0]), 1.0)
    full = cv2.GaussianBlur(splat, (0, 0), sigma_px, borderType=cv2.BORDER_CONSTANT)
    density = inlier_density(mask.shape, inliers_canvas, sigma_px)
    assert density.shape == mask.shape and density.dtype == np.float32
    np.testing.assert_allclose(density, full / full.max(), atol=0.02)
