"""kernels/seam.py against a numpy reference of the same formulas (docs/method.md step 9)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from sena_warp.kernels import runtime
from sena_warp.kernels.seam import seam_maps_kernel


def _smootherstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * t * (t * (t * 6 - 15) + 10)


def _alpha_reference(t, transition, sigma):
    erf = np.vectorize(math.erf)

    def pos(z):  # E[max(z + n, 0)], n ~ N(0, sigma^2)
        u = z / sigma
        return z * 0.5 * (1 + erf(u / math.sqrt(2))) + sigma * np.exp(-0.5 * u * u) / math.sqrt(2 * math.pi)

    return np.clip((pos(transition / 2 - t) - pos(-transition / 2 - t)) / transition, 0, 1)


def _bilinear_reference(map_canvas, qx, qy):
    h, w = map_canvas.shape[:2]
    qx = np.clip(qx, 0, w - 1)
    qy = np.clip(qy, 0, h - 1)
    x0 = np.minimum(np.floor(qx).astype(int), w - 1)
    y0 = np.minimum(np.floor(qy).astype(int), h - 1)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (qx - x0)[..., None]
    fy = (qy - y0)[..., None]
    m = map_canvas.astype(np.float64)
    return (1 - fy) * ((1 - fx) * m[y0, x0] + fx * m[y0, x1]) + fy * ((1 - fx) * m[y1, x0] + fx * m[y1, x1])


@pytest.mark.parametrize("sigma", [0.0, 1.5])
def test_seam_kernel_matches_numpy_reference(sigma):
    rng = np.random.default_rng(3)
    height, width = 48, 96
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    # a smooth non-trivial step-6 map: rotation-ish affine plus a ripple
    map_src = np.stack([0.9 * xs + 0.1 * ys + 3 * np.sin(ys / 7), -0.1 * xs + 1.05 * ys + 2 * np.cos(xs / 11)], -1)
    map_src = map_src.astype(np.float32)
    seam_x = (40 + 10 * np.sin(np.arange(height) / 9)).astype(np.float32)
    src_row_y = (np.arange(height) + rng.uniform(-3, 3, height)).astype(np.float32)
    shift_x = rng.uniform(-2, 2, height).astype(np.float32)
    offset = (5.0, -7.5)
    transition, fade = 12.0, 20.0

    device = "cpu"
    outs = [wp.empty((height, width), dtype=t, device=device) for t in (wp.vec2, wp.vec2, float)]
    runtime.launch_rows(
        seam_maps_kernel,
        height,
        width,
        [
            wp.array(map_src, dtype=wp.vec2, device=device),
            wp.array(seam_x, dtype=float, device=device),
            wp.array(src_row_y, dtype=float, device=device),
            wp.array(shift_x, dtype=float, device=device),
            wp.vec2(*offset),
            transition,
            sigma,
            fade,
            *outs,
        ],
        device,
        threads=2,
    )
    map_src_out, map_tgt_out, alpha_out = (o.numpy() for o in outs)

    t = xs - seam_x[:, None]
    f = 1 - _smootherstep((np.abs(t) - transition / 2) / fade)
    qx = xs + f * shift_x[:, None]
    qy = ys + f * (src_row_y[:, None] - ys)
    np.testing.assert_allclose(map_src_out, _bilinear_reference(map_src, qx, qy), atol=1e-3)
    np.testing.assert_allclose(map_tgt_out, np.stack([xs - offset[0], ys - offset[1]], -1), atol=1e-4)
    alpha_ref = np.clip(0.5 - t / transition, 0, 1) if sigma == 0 else _alpha_reference(t, transition, sigma)
    np.testing.assert_allclose(alpha_out, alpha_ref, atol=1.01e-4)  # within 1e-4 of 0 or 1 it is 0 or 1 (as shown)
    assert np.all(alpha_out[alpha_ref > 0.9999] == 1.0) and np.all(alpha_out[alpha_ref < 0.0001] == 0.0)
    assert alpha_out.min() == 0.0 and alpha_out.max() == 1.0
