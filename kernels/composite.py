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
# that depends only on them (validity, tap positions, bilinear weights with alpha folded in, coverage)
# is worked out once per map set by ``composite_layout_kernel``, like ``cv2.convertMaps``; the
# per-frame ``composite_fixed_kernel`` then does only loads, integer multiply-adds and one shift.
# On CPU each array access costs about as much as the arithmetic, so the layout is packed to need
# few: one vec2i of tap offsets and one vec4us of weights per side and pixel.
WEIGHT_BITS = wp.constant(14)  # a pixel's tap weights sum to 2**14: rounding error < 0.07 grey level
WEIGHT_ONE = wp.constant(1 << 14)
WEIGHT_HALF = wp.constant(1 << 13)
vec4us = wp.types.vector(length=4, dtype=wp.uint16)


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
def side_layout(p: wp.vec2, shape: wp.vec3i, scale: float, weights: wp.array(dtype=vec4us), k: int) -> int:
    """Tap code of one side at (x, y) with blend weight ``scale`` > 0; its 4 weights go to weights[k].

    Code = 2 * flat element offset of the top-left tap ((y0 * W + x0) * C) + 1 when the side is a
    plain copy (whole weight on one tap: weight 1 at an integer position), so the frame kernel can
    skip the multiply-adds. Weights: round(2**14 * scale * bilinear weight) of taps (x0, y0),
    (x1, y0), (x0, y1), (x1, y1).
    """
    o = tap_origin(p, shape[0], shape[1])
    fx = p[0] - o[0]
    fy = p[1] - o[1]
    one = float(WEIGHT_ONE) * scale
    weights[k] = vec4us(
        wp.uint16(int(one * (1.0 - fx) * (1.0 - fy) + 0.5)), wp.uint16(int(one * fx * (1.0 - fy) + 0.5)),
        wp.uint16(int(one * (1.0 - fx) * fy + 0.5)), wp.uint16(int(one * fx * fy + 0.5)),
    )
    copy = wp.where(scale == 1.0 and fx == 0.0 and fy == 0.0, 1, 0)
    return 2 * ((int(o[1]) * shape[1] + int(o[0])) * shape[2]) + copy


@wp.kernel
def composite_layout_kernel(
    row0: int,
    map_src: wp.array2d(dtype=wp.vec2),
    map_tgt: wp.array2d(dtype=wp.vec2),
    alpha_src: wp.array2d(dtype=float),
    shape_src: wp.vec3i,
    shape_tgt: wp.vec3i,
    taps: wp.array(dtype=wp.vec2i),
    weights: wp.array(dtype=vec4us),
    coverage: wp.array2d(dtype=wp.uint8),
):
    """Per canvas pixel q = y * Wc + x: taps[q] = (source code, target code), -1 = side unused;
    weights[2q] / weights[2q + 1] the source / target tap weights; coverage 255 / 0.

    ``shape_*`` = (H, W, C) of the uint8 images that will be composited (codes index them
    flattened, see ``side_layout``). A side is unused where it is invalid or its blend weight is
    exactly 0, so pixels with alpha 0 or 1 read one image only. Same rule as ``composite_kernel``.
    """
    i, x = wp.tid()
    y = row0 + i
    q = y * map_src.shape[1] + x
    p_src = map_src[y, x]
    p_tgt = map_tgt[y, x]
    ok_src = p_src[0] >= 0.0 and p_src[1] >= 0.0 and p_src[0] <= float(shape_src[1] - 1) and p_src[1] <= float(shape_src[0] - 1)
    ok_tgt = p_tgt[0] >= 0.0 and p_tgt[1] >= 0.0 and p_tgt[0] <= float(shape_tgt[1] - 1) and p_tgt[1] <= float(shape_tgt[0] - 1)
    a = wp.clamp(alpha_src[y, x], 0.0, 1.0)
    if not ok_src:
        a = 0.0
    if not ok_tgt:
        a = 1.0
    code_src = -1
    code_tgt = -1
    if ok_src and a > 0.0:
        code_src = side_layout(p_src, shape_src, a, weights, 2 * q)
    if ok_tgt and a < 1.0:
        code_tgt = side_layout(p_tgt, shape_tgt, 1.0 - a, weights, 2 * q + 1)
    taps[q] = wp.vec2i(code_src, code_tgt)
    coverage[y, x] = wp.where(ok_src or ok_tgt, wp.uint8(255), wp.uint8(0))


@wp.func
def taps_sum(img: wp.array(dtype=wp.uint8), w: vec4us, p: int, step_x: int, step_y: int) -> int:
    """w . the 2x2 footprint at flat offset p (neighbours step_x / step_y elements away)."""
    return (
        int(w[0]) * int(img[p]) + int(w[1]) * int(img[p + step_x])
        + int(w[2]) * int(img[p + step_y]) + int(w[3]) * int(img[p + step_y + step_x])
    )


@wp.kernel
def composite_fixed_kernel(
    row0: int,
    col_step: int,
    width: int,
    img_src: wp.array(dtype=wp.uint8),
    img_tgt: wp.array(dtype=wp.uint8),
    steps: wp.vec4i,
    taps: wp.array(dtype=wp.vec2i),
    weights: wp.array(dtype=vec4us),
    channels: int,
    fill: wp.vec4i,
    out: wp.array(dtype=wp.uint8),
):
    """out[y, x, c] from the precomputed layout (``composite_layout_kernel``); ``fill[c]`` where no side is.

    Flat arrays: ``img_*`` (H, W, C), ``out`` (Hc, Wc, C), ``taps`` (Hc, Wc), ``weights`` (Hc, Wc, 2);
    C = ``channels`` <= 4. ``steps`` = (src x step, src y step, tgt x step, tgt y step) in elements:
    C and W*C (0 along an axis of length 1). Thread (i, j) does row ``row0 + i``, columns j,
    j + col_step, ...: on CPU a thread loops over a whole row (no per-pixel launch overhead, see
    ``runtime.launch_row_loops``), on CUDA it does one pixel.
    """
    i, j = wp.tid()
    y = row0 + i
    for x in range(j, width, col_step):
        q = y * width + x
        code = taps[q]
        o_src = code[0] >> 1
        o_tgt = code[1] >> 1
        if code[0] >= 0 and (code[0] & 1) == 1:
            for c in range(channels):
                out[q * channels + c] = img_src[o_src + c]
        elif code[1] >= 0 and (code[1] & 1) == 1:
            for c in range(channels):
                out[q * channels + c] = img_tgt[o_tgt + c]
        elif code[0] < 0 and code[1] < 0:
            for c in range(channels):
                out[q * channels + c] = wp.uint8(fill[c])
        else:
            w_src = weights[2 * q]
            w_tgt = weights[2 * q + 1]
            for c in range(channels):
                acc = int(WEIGHT_HALF)
                if code[0] >= 0:
                    acc = acc + taps_sum(img_src, w_src, o_src + c, steps[0], steps[1])
                if code[1] >= 0:
                    acc = acc + taps_sum(img_tgt, w_tgt, o_tgt + c, steps[2], steps[3])
                out[q * channels + c] = wp.uint8(wp.min(acc >> WEIGHT_BITS, 255))
