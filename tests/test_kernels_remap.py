"""Remap and composite kernels against numpy bilinear references, on a real image pair (C = 3 and C = 1)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from sena_warp.bilinear import sample_bilinear
from sena_warp.kernels import runtime
from sena_warp.kernels.remap import remap_kernel
from test_kernels_maps import DEVICES, scene_geometry, smooth_field, source_map_reference


def remap_reference(img: np.ndarray, map_canvas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Float64 bilinear sample (the host rule, ``sena_warp.bilinear``) of uint8 (H, W, C) img at float32
    (x, y) positions (Hc, Wc, 2); (values (Hc, Wc, C), 0 where invalid; valid (Hc, Wc) bool)."""
    values = sample_bilinear(img, map_canvas.reshape(-1, 2)).reshape(*map_canvas.shape[:2], img.shape[2])
    valid = np.isfinite(values[..., 0])
    return np.where(valid[..., None], values, 0.0), valid


@pytest.fixture(scope="module")
def scene(udisd_pair):
    img_src, img_tgt = udisd_pair
    geo = scene_geometry(img_src.shape, img_tgt.shape)
    canvas = geo["canvas"]
    map_src = source_map_reference(canvas, geo["affine_src_to_tgt"], smooth_field(canvas.shape, 8.0)).astype(np.float32)
    u = np.stack(np.meshgrid(np.arange(canvas.width), np.arange(canvas.height)), axis=-1).astype(np.float64)
    map_tgt = (u - np.asarray(canvas.offset_tgt)).astype(np.float32)
    # A ramp from source to target across the canvas, so every blend weight occurs.
    alpha = np.broadcast_to(np.linspace(1.2, -0.2, canvas.width, dtype=np.float32), canvas.shape).copy()
    return img_src, img_tgt, map_src, map_tgt, alpha


def run_remap(img, map_canvas, device, threads):
    img3 = np.ascontiguousarray(img if img.ndim == 3 else img[:, :, None])
    hc, wc = map_canvas.shape[:2]
    out = wp.zeros((hc, wc, img3.shape[2]), dtype=wp.uint8, device=device)
    valid = wp.zeros((hc, wc), dtype=wp.uint8, device=device)
    inputs = [wp.array(img3, dtype=wp.uint8, device=device), wp.array(map_canvas, dtype=wp.vec2, device=device), out, valid]
    runtime.launch_rows(remap_kernel, hc, wc, inputs, device, threads)
    return out.numpy(), valid.numpy()


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("channels", [3, 1])
def test_remap_kernel_matches_numpy(scene, device, channels, warp_device):
    img_src, _, map_src, _, _ = scene
    img = img_src if channels == 3 else np.ascontiguousarray(img_src[:, :, 1])
    out, valid = run_remap(img, map_src, device, threads=3)
    expected, expected_valid = remap_reference(img if channels == 3 else img[:, :, None], map_src)
    np.testing.assert_array_equal(valid.astype(bool), expected_valid)
    assert 0.2 < expected_valid.mean() < 0.9  # part of the canvas is outside the source
    assert np.abs(out.astype(np.float64) - expected).max() <= 1.0
    assert out[~expected_valid].max() == 0
