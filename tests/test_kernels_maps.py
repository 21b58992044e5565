"""Map-building kernels (FFD lattice, gate, gated field, source map) against numpy references.

The geometry is a realistic two-view layout of the (bundled) udisd_test_000001 pair: a rotated, scaled
global affine, four perturbed local affines with centres in the overlap. Helpers here are reused
by the host-module tests (test_ffd, test_gate, test_warp_map, test_composite).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import warp as wp

from sena_warp.affine import apply_affine, invert_affine
from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.kernels import runtime
from sena_warp.kernels.ffd import ffd_lattice_kernel
from sena_warp.kernels.gate import gate_kernel, gated_field_kernel
from sena_warp.kernels.sampling import source_map_kernel

HAS_CUDA = wp.get_cuda_device_count() > 0
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not HAS_CUDA, reason="no CUDA GPU"))]


def scene_geometry(shape_src: tuple, shape_tgt: tuple, seed: int = 0) -> dict:
    """Global affine, canvas, overlap mask and four local affines of a left-source / right-target rig."""
    rng = np.random.default_rng(seed)
    h_src, w_src = shape_src[:2]
    h_tgt, w_tgt = shape_tgt[:2]
    angle = math.radians(3.0)
    scale = 1.02
    linear = scale * np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    affine_src_to_tgt = np.hstack([linear, [[-0.55 * w_src], [10.0]]])
    corners_src = np.array([[0, 0], [w_src - 1, 0], [w_src - 1, h_src - 1], [0, h_src - 1]], dtype=np.float64)
    corners_tgt = apply_affine(affine_src_to_tgt, corners_src)
    all_pts = np.vstack([corners_tgt, [[0, 0], [w_tgt - 1, h_tgt - 1]]])
    lo = np.floor(all_pts.min(axis=0))
    hi = np.ceil(all_pts.max(axis=0))
    canvas = Canvas(width=int(hi[0] - lo[0]) + 1, height=int(hi[1] - lo[1]) + 1, offset_tgt=(-lo[0], -lo[1]))
    src_mask = np.zeros(canvas.shape, np.uint8)
    cv2.fillConvexPoly(src_mask, np.rint(canvas.tgt_to_canvas(corners_tgt)).astype(np.int32), 1)
    tgt_mask = np.zeros(canvas.shape, np.uint8)
    ox, oy = int(-lo[0]), int(-lo[1])
    tgt_mask[oy : oy + h_tgt, ox : ox + w_tgt] = 1
    overlap_mask = (src_mask & tgt_mask).astype(bool)
    ys, xs = np.nonzero(overlap_mask)
    centres_canvas = np.array(
        [[np.percentile(xs, qx), np.percentile(ys, qy)] for qy in (25, 75) for qx in (25, 75)], dtype=np.float64
    )
    local = np.repeat(affine_src_to_tgt[None], 4, axis=0)
    local[:, :, :2] += rng.normal(0.0, 0.01, size=(4, 2, 2))
    local[:, :, 2] += rng.normal(0.0, 6.0, size=(4, 2))
    return {
        "affine_src_to_tgt": affine_src_to_tgt,
        "canvas": canvas,
        "overlap_mask_canvas": overlap_mask,
        "source_only_canvas": src_mask.astype(bool) & ~tgt_mask.astype(bool),
        "affines_src_to_tgt": local,
        "centres_tgt": canvas.canvas_to_tgt(centres_canvas),
        "conf": rng.uniform(0.2, 1.5, size=4),
        "sigma_f": 0.35 * math.hypot(xs.max() - xs.min(), ys.max() - ys.min()) / 2,
    }


def ffd_lattice_reference(geo: dict, ny: int, nx: int, d_max: float) -> np.ndarray:
    """Numpy float64 SENA step 4 on the lattice (nodes where cv2.resize samples)."""
    canvas = geo["canvas"]
    cols = (np.arange(nx) + 0.5) * canvas.width / nx - 0.5
    rows = (np.arange(ny) + 0.5) * canvas.height / ny - 0.5
    u = np.stack(np.meshgrid(cols, rows), axis=-1)
    p_tgt = u - np.asarray(canvas.offset_tgt)
    p_base = apply_affine(invert_affine(geo["affine_src_to_tgt"]), p_tgt).reshape(p_tgt.shape)
    d_sum = np.zeros_like(p_tgt)
    w_sum = np.zeros(p_tgt.shape[:2])
    for affine, centre, conf in zip(geo["affines_src_to_tgt"], geo["centres_tgt"], geo["conf"]):
        p_j = apply_affine(invert_affine(affine), p_tgt).reshape(p_tgt.shape)
        w = conf * np.exp(-np.sum((p_tgt - centre) ** 2, axis=-1) / (2 * geo["sigma_f"] ** 2))
        d_sum += w[..., None] * (p_j - p_base)
        w_sum += w
    return np.clip(d_sum / w_sum[..., None], -d_max, d_max)


def smootherstep_reference(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return 6 * t**5 - 15 * t**4 + 10 * t**3


def gate_reference(sdf: np.ndarray, density: np.ndarray, ramp_px: float, cfg: Config) -> np.ndarray:
    ramp = np.clip(sdf / ramp_px, 0.0, 1.0)
    return smootherstep_reference(ramp) ** cfg.gamma_p * (cfg.gamma_min + (1 - cfg.gamma_min) * smootherstep_reference(density))


def source_map_reference(canvas: Canvas, affine_src_to_tgt: np.ndarray, field: np.ndarray) -> np.ndarray:
    """M_s(u) = A^-1 (u - o) + D(u) in float64, (H, W, 2)."""
    u = np.stack(np.meshgrid(np.arange(canvas.width, dtype=np.float64), np.arange(canvas.height, dtype=np.float64)), axis=-1)
    return apply_affine(invert_affine(affine_src_to_tgt), u - np.asarray(canvas.offset_tgt)).reshape(u.shape) + field


def smooth_field(shape: tuple[int, int], amplitude_px: float, seed: int = 1) -> np.ndarray:
    """A smooth (H, W, 2) float32 displacement: blurred noise scaled to +-amplitude."""
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(-1.0, 1.0, size=(8, 8, 2)).astype(np.float32)
    return amplitude_px * cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)


@pytest.fixture(scope="module")
def geo(udisd_pair):
    img_src, img_tgt = udisd_pair
    return scene_geometry(img_src.shape, img_tgt.shape)


@pytest.mark.parametrize("device", DEVICES)
def test_ffd_lattice_kernel_matches_numpy(geo, device, warp_device):
    ny, nx, d_max = 48, 40, 60.0
    glob = invert_affine(geo["affine_src_to_tgt"])
    local = invert_affine(geo["affines_src_to_tgt"])
    out = wp.zeros((ny, nx), dtype=wp.vec2, device=device)
    inputs = [
        wp.vec2d(geo["canvas"].width / nx, geo["canvas"].height / ny),
        wp.vec2d(*geo["canvas"].offset_tgt),
        wp.mat22d(glob[:, :2]),
        wp.vec2d(glob[:, 2]),
        wp.array(np.ascontiguousarray(local[:, :, :2]), dtype=wp.mat22d, device=device),
        wp.array(np.ascontiguousarray(local[:, :, 2]), dtype=wp.vec2d, device=device),
        wp.array(geo["centres_tgt"], dtype=wp.vec2d, device=device),
        wp.array(geo["conf"], dtype=wp.float64, device=device),
        float(geo["sigma_f"]),
        d_max,
        out,
    ]
    runtime.launch_rows(ffd_lattice_kernel, ny, nx, inputs, device, 2)
    expected = ffd_lattice_reference(geo, ny, nx, d_max)
    got = out.numpy().reshape(ny, nx, 2)
    assert np.abs(expected).max() > 1.0  # the local affines really move pixels
    np.testing.assert_allclose(got, expected, atol=1e-3)


@pytest.mark.parametrize("device", DEVICES)
def test_gate_kernels_match_numpy(geo, device, warp_device):
    cfg = Config()
    h, w = geo["canvas"].shape
    sdf = cv2.distanceTransform(geo["overlap_mask_canvas"].astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    density = np.clip(smooth_field((h, w), 1.0)[:, :, 0] + 0.5, 0.0, 1.0).astype(np.float32)
    field = smooth_field((h, w), 20.0, seed=3)
    ramp_px = 51.2
    gate = wp.zeros((h, w), dtype=float, device=device)
    sdf_wp = wp.array(sdf, dtype=float, device=device)
    density_wp = wp.array(density, dtype=float, device=device)
    runtime.launch_rows(gate_kernel, h, w, [sdf_wp, density_wp, ramp_px, cfg.gamma_p, cfg.gamma_min, gate], device, 2)
    expected_gate = gate_reference(sdf.astype(np.float64), density.astype(np.float64), ramp_px, cfg)
    np.testing.assert_allclose(gate.numpy(), expected_gate, atol=1e-5)
    assert gate.numpy()[sdf == 0].max() == 0.0 and gate.numpy().max() > 0.9

    gated = wp.zeros((h, w), dtype=wp.vec2, device=device)
    field_wp = wp.array(field, dtype=wp.vec2, device=device)
    runtime.launch_rows(gated_field_kernel, h, w, [field_wp, gate, gated], device, 2)
    np.testing.assert_allclose(gated.numpy().reshape(h, w, 2), expected_gate[..., None] * field, atol=1e-4)


@pytest.mark.parametrize("device", DEVICES)
def test_source_map_kernel_matches_numpy(geo, device, warp_device):
    canvas = geo["canvas"]
    field = smooth_field(canvas.shape, 15.0)
    tgt_to_src = invert_affine(geo["affine_src_to_tgt"])
    map_src = wp.zeros(canvas.shape, dtype=wp.vec2, device=device)
    inputs = [
        wp.vec2d(*canvas.offset_tgt),
        wp.mat22d(tgt_to_src[:, :2]),
        wp.vec2d(tgt_to_src[:, 2]),
        wp.array(field, dtype=wp.vec2, device=device),
        map_src,
    ]
    runtime.launch_rows(source_map_kernel, canvas.height, canvas.width, inputs, device, 3)
    expected = source_map_reference(canvas, geo["affine_src_to_tgt"], field.astype(np.float64))
    np.testing.assert_allclose(map_src.numpy().reshape(*canvas.shape, 2), expected, atol=1e-3)
