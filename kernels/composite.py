"""Per-frame compositing: out = alpha * src(map_src) + (1 - alpha) * tgt(map_tgt) (SENA.md "Maps, not images").

Bilinear samples of both images; where only one side is valid it is used alone; where neither is,
the pixel is 0 and its coverage 0. Generic in C (C = 3 images, C = 1 video planes).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels.remap import bilinear_sample, inside_image, to_uint8


@wp.kernel
def composite_kernel(
    row0: int,
    img_src: wp.array3d(dtype=wp.uint8),
    img_tgt: wp.array3d(dtype=wp.uint8),
    map_src: wp.array2d(dtype=wp.vec2),
    map_tgt: wp.array2d(dtype=wp.vec2),
    alpha_src: wp.array2d(dtype=float),
    out: wp.array3d(dtype=wp.uint8),
    coverage: wp.array2d(dtype=wp.uint8),
):
    """out[y, x, :] blended from both sides; coverage[y, x] = 255 where any side is valid, else 0."""
    i, x = wp.tid()
    y = row0 + i
    p_src = map_src[y, x]
    p_tgt = map_tgt[y, x]
    ok_src = inside_image(img_src, p_src)
    ok_tgt = inside_image(img_tgt, p_tgt)
    a = wp.clamp(alpha_src[y, x], 0.0, 1.0)
    if not ok_src:
        a = 0.0
    if not ok_tgt:
        a = 1.0
    covered = ok_src or ok_tgt
    for c in range(out.shape[2]):
        v = 0.0
        if ok_src and a > 0.0:
            v = v + a * bilinear_sample(img_src, p_src, c)
        if ok_tgt and a < 1.0:
            v = v + (1.0 - a) * bilinear_sample(img_tgt, p_tgt, c)
        out[y, x, c] = wp.where(covered, to_uint8(v), wp.uint8(0))
    coverage[y, x] = wp.where(covered, wp.uint8(255), wp.uint8(0))


# Fixed-point compositing (the per-frame path). The maps do not change between frames, so everything
# that depends only on them (validity, tap positions, bilinear weights with alpha folded in) is worked
# out once per map set by ``composite_layout_kernel``, like ``cv2.convertMaps``; the per-frame
# ``composite_fixed_kernel`` then does only loads, integer multiply-adds and one rounding shift.
WEIGHT_BITS = wp.constant(14)  # the 8 tap weights of a pixel sum to 2**14: rounding error < 0.07 grey level
WEIGHT_ONE = wp.constant(1 << 14)
WEIGHT_HALF = wp.constant(1 << 13)
TAPS = wp.constant(8)  # 4 bilinear taps of the source, then 4 of the target


@wp.func
def tap_origin(p: wp.vec2, height: int, width: int) -> wp.vec2:
    """(x0, y0) top-left bilinear tap of a valid (x, y), kept at x0 <= W-2, y0 <= H-2 (when W, H >= 2).

    Keeping the 2x2 footprint inside the plane (x = W-1 becomes x0 = W-2 with fx = 1) lets the frame
    kernel read all four taps without a bounds check.
    """
    x0 = wp.min(wp.floor(p[0]), float(wp.max(width - 2, 0)))
    y0 = wp.min(wp.floor(p[1]), float(wp.max(height - 2, 0)))
    return wp.vec2(x0, y0)


@wp.func
def put_taps(weights: wp.array3d(dtype=wp.uint16), y: int, x: int, k0: int, scale: float, fx: float, fy: float):
    """weights[y, x, k0:k0+4] = round(2**14 * scale * bilinear weight) for taps (x0,y0),(x1,y0),(x0,y1),(x1,y1)."""
    one = float(WEIGHT_ONE)
    weights[y, x, k0 + 0] = wp.uint16(int(one * scale * (1.0 - fx) * (1.0 - fy) + 0.5))
    weights[y, x, k0 + 1] = wp.uint16(int(one * scale * fx * (1.0 - fy) + 0.5))
    weights[y, x, k0 + 2] = wp.uint16(int(one * scale * (1.0 - fx) * fy + 0.5))
    weights[y, x, k0 + 3] = wp.uint16(int(one * scale * fx * fy + 0.5))


@wp.kernel
def composite_layout_kernel(
    row0: int,
    map_src: wp.array2d(dtype=wp.vec2),
    map_tgt: wp.array2d(dtype=wp.vec2),
    alpha_src: wp.array2d(dtype=float),
    shape_src: wp.vec3i,
    shape_tgt: wp.vec3i,
    tap_src: wp.array2d(dtype=wp.int32),
    tap_tgt: wp.array2d(dtype=wp.int32),
    weights: wp.array3d(dtype=wp.uint16),
):
    """Per canvas pixel: flat element offsets of the top-left taps (-1 = side unused) and 8 weights.

    ``shape_*`` = (H, W, C) of the uint8 images that will be composited; offsets index them flattened
    (``(y0 * W + x0) * C``). A side is unused where it is invalid or its blend weight is exactly 0, so
    pixels with alpha 0 or 1 read one image only. Same rule as ``composite_kernel``.
    """
    i, x = wp.tid()
    y = row0 + i
    p_src = map_src[y, x]
    p_tgt = map_tgt[y, x]
    ok_src = p_src[0] >= 0.0 and p_src[1] >= 0.0 and p_src[0] <= float(shape_src[1] - 1) and p_src[1] <= float(shape_src[0] - 1)
    ok_tgt = p_tgt[0] >= 0.0 and p_tgt[1] >= 0.0 and p_tgt[0] <= float(shape_tgt[1] - 1) and p_tgt[1] <= float(shape_tgt[0] - 1)
    a = wp.clamp(alpha_src[y, x], 0.0, 1.0)
    if not ok_src:
        a = 0.0
    if not ok_tgt:
        a = 1.0
    tap_src[y, x] = -1
    tap_tgt[y, x] = -1
    for k in range(TAPS):
        weights[y, x, k] = wp.uint16(0)
    if ok_src and a > 0.0:
        o = tap_origin(p_src, shape_src[0], shape_src[1])
        tap_src[y, x] = (int(o[1]) * shape_src[1] + int(o[0])) * shape_src[2]
        put_taps(weights, y, x, 0, a, p_src[0] - o[0], p_src[1] - o[1])
    if ok_tgt and a < 1.0:
        o = tap_origin(p_tgt, shape_tgt[0], shape_tgt[1])
        tap_tgt[y, x] = (int(o[1]) * shape_tgt[1] + int(o[0])) * shape_tgt[2]
        put_taps(weights, y, x, 4, 1.0 - a, p_tgt[0] - o[0], p_tgt[1] - o[1])


@wp.func
def taps_sum(img: wp.array(dtype=wp.uint8), weights: wp.array(dtype=wp.uint16), k: int, p: int, step_x: int,
             step_y: int) -> int:
    """sum of weights[k:k+4] times the 2x2 footprint at flat offset p (neighbours step_x / step_y away)."""
    return (
        int(weights[k]) * int(img[p]) + int(weights[k + 1]) * int(img[p + step_x])
        + int(weights[k + 2]) * int(img[p + step_y]) + int(weights[k + 3]) * int(img[p + step_y + step_x])
    )


@wp.kernel
def composite_fixed_kernel(
    row0: int,
    col_step: int,
    width: int,
    img_src: wp.array(dtype=wp.uint8),
    img_tgt: wp.array(dtype=wp.uint8),
    steps: wp.vec4i,
    tap_src: wp.array(dtype=wp.int32),
    tap_tgt: wp.array(dtype=wp.int32),
    weights: wp.array(dtype=wp.uint16),
    fill: wp.array(dtype=wp.uint8),
    out: wp.array(dtype=wp.uint8),
    coverage: wp.array(dtype=wp.uint8),
):
    """out[y, x, c] from the precomputed layout; ``fill[c]`` (and coverage 0) where no side is sampled.

    Every array is flat: ``img_*`` (H, W, C), ``tap_*`` / ``coverage`` (Hc, Wc), ``weights``
    (Hc, Wc, 8), ``out`` (Hc, Wc, C) with C = ``fill.shape[0]``. ``steps`` = (src x step, src y step,
    tgt x step, tgt y step) in elements: C and W*C (0 along an axis of length 1). Thread (i, j) does
    row ``row0 + i``, columns j, j + col_step, ...: on CPU a thread loops over a whole row (no
    per-pixel launch overhead, see ``runtime.launch_row_loops``), on CUDA it does one pixel.
    """
    i, j = wp.tid()
    y = row0 + i
    channels = fill.shape[0]
    for x in range(j, width, col_step):
        q = y * width + x
        o_src = tap_src[q]
        o_tgt = tap_tgt[q]
        covered = o_src >= 0 or o_tgt >= 0
        for c in range(channels):
            acc = int(WEIGHT_HALF)
            if o_src >= 0:
                acc = acc + taps_sum(img_src, weights, q * TAPS, o_src + c, steps[0], steps[1])
            if o_tgt >= 0:
                acc = acc + taps_sum(img_tgt, weights, q * TAPS + 4, o_tgt + c, steps[2], steps[3])
            out[q * channels + c] = wp.where(covered, wp.uint8(wp.min(acc >> WEIGHT_BITS, 255)), fill[c])
        coverage[q] = wp.where(covered, wp.uint8(255), wp.uint8(0))
