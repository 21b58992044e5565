"""Step 6: source map, numeric forward inversion, warping, on a real pair through steps 4-6."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from sena_warp.affine import apply_affine
from sena_warp.bilinear import sample_bilinear
from sena_warp.config import Config
from sena_warp.ffd import field_from_lattice, smoothed_blend_lattice
from sena_warp.gate import gate_canvas, guard_field
from sena_warp.warp_map import forward_points, remap_image, source_map_canvas
from test_kernels_maps import scene_geometry, source_map_reference

CFG = Config(device="cpu")


@pytest.fixture(scope="module")
def pipeline(udisd_pair):
    """Steps 4-6 on the udisd pair's geometry with inliers spread over the overlap."""
    cfg = CFG
    img_src, img_tgt = udisd_pair
    geo = scene_geometry(img_src.shape, img_tgt.shape)
    canvas = geo["canvas"]
    field = field_from_lattice(smoothed_blend_lattice(canvas, geo["affine_src_to_tgt"], geo["affines_src_to_tgt"],
                                                      geo["centres_tgt"], geo["conf"], geo["sigma_f"], cfg), canvas)
    ys, xs = np.nonzero(geo["overlap_mask_canvas"])
    pick = np.random.default_rng(2).choice(xs.size, size=400, replace=False)
    inliers_canvas = np.stack([xs[pick], ys[pick]], axis=1).astype(np.float64)
    h, w = img_tgt.shape[:2]
    gate = gate_canvas(geo["source_only_canvas"], inliers_canvas, math.hypot(w, h), max(w, h), cfg)
    guarded = guard_field(field, gate, cfg)
    map_src = source_map_canvas(canvas, geo["affine_src_to_tgt"], guarded, cfg)
    return img_src, img_tgt, geo, gate, guarded, map_src


def test_source_map_matches_reference(pipeline):
    _, _, geo, _, guarded, map_src = pipeline
    assert map_src.shape == (*geo["canvas"].shape, 2) and map_src.dtype == np.float32
    expected = source_map_reference(geo["canvas"], geo["affine_src_to_tgt"], guarded.astype(np.float64))
    np.testing.assert_allclose(map_src, expected, atol=1e-3)


def test_map_is_the_global_affine_where_the_gate_is_zero(pipeline):
    _, _, geo, gate, guarded, map_src = pipeline
    global_only = source_map_reference(geo["canvas"], geo["affine_src_to_tgt"], np.zeros_like(guarded, dtype=np.float64))
    error = np.linalg.norm(map_src - global_only, axis=-1)
    assert error[gate == 0].max() < 0.5
    assert error[gate > 0.5].max() > 1.0  # inside the overlap the local alignment does move pixels


def test_forward_points_round_trip(pipeline):
    img_src, _, geo, _, _, map_src = pipeline
    canvas = geo["canvas"]
    h, w = img_src.shape[:2]
    rng = np.random.default_rng(7)
    pts_src = rng.uniform([2, 2], [w - 3, h - 3], size=(500, 2))
    pts_canvas = forward_points(map_src, geo["affine_src_to_tgt"], canvas, pts_src, CFG)
    assert np.isfinite(pts_canvas).all()
    back_src = sample_bilinear(map_src, pts_canvas)
    assert np.abs(back_src - pts_src).max() < 0.05
    # The naive A s + o is measurably off where the field is strong: the inversion matters.
    naive = canvas.tgt_to_canvas(apply_affine(geo["affine_src_to_tgt"], pts_src))
    assert np.linalg.norm(naive - pts_canvas, axis=1).max() > 1.0


def test_forward_points_off_canvas_are_nan(pipeline):
    img_src, _, geo, _, _, map_src = pipeline
    pts_canvas = forward_points(map_src, geo["affine_src_to_tgt"], geo["canvas"], np.array([[-5000.0, 0.0], [10.0, 10.0]]),
                                CFG)
    assert np.isnan(pts_canvas[0]).all() and np.isfinite(pts_canvas[1]).all()


def test_remap_image_places_target_exactly_and_source_like_warp_affine(pipeline):
    img_src, img_tgt, geo, _, guarded, _ = pipeline
    canvas = geo["canvas"]
    ox, oy = (int(v) for v in canvas.offset_tgt)
    u = np.stack(np.meshgrid(np.arange(canvas.width), np.arange(canvas.height)), axis=-1).astype(np.float32)
    warped_tgt, valid_tgt = remap_image(img_tgt, u - np.asarray(canvas.offset_tgt, dtype=np.float32), CFG)
    h, w = img_tgt.shape[:2]
    np.testing.assert_array_equal(warped_tgt[oy : oy + h, ox : ox + w], img_tgt)
    assert valid_tgt.sum() == h * w

    map_global = source_map_canvas(canvas, geo["affine_src_to_tgt"], np.zeros_like(guarded), CFG)
    warped_src, valid_src = remap_image(img_src, map_global, CFG)
    affine_src_to_canvas = geo["affine_src_to_tgt"].copy()
    affine_src_to_canvas[:, 2] += canvas.offset_tgt
    expected = cv2.warpAffine(img_src, affine_src_to_canvas, (canvas.width, canvas.height), flags=cv2.INTER_LINEAR)
    inner = cv2.erode(valid_src.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert inner.sum() > 0.8 * img_src.shape[0] * img_src.shape[1]
    assert np.abs(warped_src[inner].astype(int) - expected[inner].astype(int)).mean() < 0.5
    assert warped_src[~valid_src].max() == 0
