"""Bilinear remap of a uint8 (H, W, C) image by a canvas map (docs/method.md step 6, "apply").

A map holds, per canvas pixel, the (x, y) position to sample; pixel centres are at integer
coordinates. A position is valid when all four bilinear taps lie inside the image
(0 <= x <= W-1, 0 <= y <= H-1); NaN positions are invalid. Generic in C (C = 1 for video planes).
The ``@wp.func`` helpers here are shared by ``composite.py`` and other kernels.
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring


@wp.func
def inside_image(img: wp.array3d(dtype=wp.uint8), p: wp.vec2) -> bool:
    """True when the bilinear footprint of (x, y) lies in the image (False for NaN)."""
    return (
        p[0] >= 0.0
        and p[1] >= 0.0
        and p[0] <= float(img.shape[1] - 1)
        and p[1] <= float(img.shape[0] - 1)
    )


@wp.func
def bilinear_sample(img: wp.array3d(dtype=wp.uint8), p: wp.vec2, c: int) -> float:
    """Channel c of img bilinearly interpolated at (x, y); p must satisfy inside_image."""
    x0 = wp.min(int(wp.floor(p[0])), img.shape[1] - 1)
    y0 = wp.min(int(wp.floor(p[1])), img.shape[0] - 1)
    x1 = wp.min(x0 + 1, img.shape[1] - 1)
    y1 = wp.min(y0 + 1, img.shape[0] - 1)
    fx = p[0] - float(x0)
    fy = p[1] - float(y0)
    top = (1.0 - fx) * float(img[y0, x0, c]) + fx * float(img[y0, x1, c])
    bottom = (1.0 - fx) * float(img[y1, x0, c]) + fx * float(img[y1, x1, c])
    return (1.0 - fy) * top + fy * bottom


@wp.func
def to_uint8(v: float) -> wp.uint8:
    """Round a grey level to the nearest uint8, saturating."""
    return wp.uint8(int(wp.clamp(v + 0.5, 0.0, 255.0)))


@wp.kernel
def remap_kernel(
    row0: int,
    img: wp.array3d(dtype=wp.uint8),
    map_canvas: wp.array2d(dtype=wp.vec2),
    out: wp.array3d(dtype=wp.uint8),
    valid: wp.array2d(dtype=wp.uint8),
):
    """out[y, x, :] = img bilinearly sampled at map_canvas[y, x]; valid 1/0; invalid pixels are 0."""
    i, x = wp.tid()
    y = row0 + i
    p = map_canvas[y, x]
    ok = inside_image(img, p)
    for c in range(out.shape[2]):
        v = wp.uint8(0)
        if ok:
            v = to_uint8(bilinear_sample(img, p, c))
        out[y, x, c] = v
    valid[y, x] = wp.where(ok, wp.uint8(1), wp.uint8(0))
