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
# that depends only on them (validity, which side is shown, tap positions, sub-pixel fractions,
# alpha, coverage) is worked out once per map set by ``composite_plan_kernel``, like
# ``cv2.convertMaps``; the per-frame ``COMPOSITE_FIXED_KERNELS`` then do integer arithmetic only.
# On the CPU every array access costs about as much as the arithmetic, so a pixel shown from one side
# (all but the seam's transition band) needs one int64 load besides its image taps, and only blend
# pixels read their target taps and alpha from two more arrays.
#
# A plan word (int64): bits 0-1 the kind (KIND_*), bits 2-12 fx and 13-23 fy (the bilinear
# fractions in 1/1024 px, 0..1024), bits 24+ the flat element offset of the top-left tap in the
# image of the side shown (the source for a blend, whose target word has the same layout).
KIND_FILL = wp.constant(0)  # no side covers the pixel: the fill value
KIND_SOURCE = wp.constant(1)  # the source alone (alpha 1, or the target invalid)
KIND_TARGET = wp.constant(2)  # the target alone (alpha 0, or the source invalid)
KIND_BLEND = wp.constant(3)  # alpha * source + (1 - alpha) * target
FRAC_BITS = wp.constant(10)  # sub-pixel steps of 1/1024 px: the value moves < 0.25 grey level
FRAC_ONE = wp.constant(1 << 10)
FRAC_MASK = wp.constant(2047)  # 11 bits: a fraction may be exactly 1 at the last row / column
ALPHA_BITS = wp.constant(14)  # alpha in 1/16384


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
def plan_word(kind: int, p: wp.vec2, shape: wp.vec3i) -> wp.int64:
    """The plan word of sampling an (H, W, C) image (``shape``) at a valid (x, y), tagged ``kind``."""
    o = tap_origin(p, shape[0], shape[1])
    fx = int((p[0] - o[0]) * float(FRAC_ONE) + 0.5)
    fy = int((p[1] - o[1]) * float(FRAC_ONE) + 0.5)
    offset = (int(o[1]) * shape[1] + int(o[0])) * shape[2]
    return (wp.int64(offset) << wp.int64(24)) | (wp.int64(fy) << wp.int64(13)) | (wp.int64(fx) << wp.int64(2)) \
        | wp.int64(kind)


@wp.kernel
def composite_plan_kernel(
    row0: int,
    map_src: wp.array2d(dtype=wp.vec2),
    map_tgt: wp.array2d(dtype=wp.vec2),
    alpha_src: wp.array2d(dtype=float),
    shape_src: wp.vec3i,
    shape_tgt: wp.vec3i,
    plan: wp.array(dtype=wp.int64),
    plan_tgt: wp.array(dtype=wp.int64),
    alpha: wp.array(dtype=wp.uint16),
    coverage: wp.array2d(dtype=wp.uint8),
):
    """Per canvas pixel q = y * Wc + x: plan[q] (see above), and for blends plan_tgt[q] (the target's
    word) and alpha[q] (the source weight in 1/2**14); coverage 255 / 0. Same rule as ``composite_kernel``.

    ``shape_*`` = (H, W, C) of the uint8 images that will be composited (offsets index them flattened).
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
    word = wp.int64(KIND_FILL)
    if ok_src and a >= 1.0:
        word = plan_word(KIND_SOURCE, p_src, shape_src)
    elif ok_tgt and a <= 0.0:
        word = plan_word(KIND_TARGET, p_tgt, shape_tgt)
    elif ok_src and ok_tgt:
        word = plan_word(KIND_BLEND, p_src, shape_src)
        plan_tgt[q] = plan_word(KIND_TARGET, p_tgt, shape_tgt)
        alpha[q] = wp.uint16(int(a * float(1 << ALPHA_BITS) + 0.5))
    plan[q] = word
    coverage[y, x] = wp.where(ok_src or ok_tgt, wp.uint8(255), wp.uint8(0))


@wp.func
def word_offset(word: wp.int64) -> int:
    return int(word >> wp.int64(24))


@wp.func
def word_fx(word: wp.int64) -> int:
    return int((word >> wp.int64(2)) & wp.int64(FRAC_MASK))


@wp.func
def word_fy(word: wp.int64) -> int:
    return int((word >> wp.int64(13)) & wp.int64(FRAC_MASK))


@wp.func
def sample_fixed(img: wp.array(dtype=wp.uint8), p: int, fx: int, fy: int, step_x: int, step_y: int) -> int:
    """The element at flat offset p bilinearly sampled at fractions (fx, fy), in 1/2**20 grey levels."""
    if fx == 0 and fy == 0:  # an exact copy (the unwarped target): one load
        return int(img[p]) << (2 * FRAC_BITS)
    top = (FRAC_ONE - fx) * int(img[p]) + fx * int(img[p + step_x])
    bottom = (FRAC_ONE - fx) * int(img[p + step_y]) + fx * int(img[p + step_y + step_x])
    return (FRAC_ONE - fy) * top + fy * bottom


@wp.func
def grey_level(sample: int) -> wp.uint8:
    """A sample in 1/2**20 grey levels rounded to uint8."""
    return wp.uint8(wp.min((sample + (1 << (2 * FRAC_BITS - 1))) >> (2 * FRAC_BITS), 255))


def _composite_fixed_kernel(channels: int):
    """The frame kernel for images of ``channels`` (1 to 4) channels, its channel loops unrolled.

    A compile-time channel count matters on the CPU: a dynamic per-pixel channel loop doubled the
    kernel's time at 1080p.
    """

    @wp.kernel(module="unique")
    def composite_fixed(
        row0: int,
        col_step: int,
        width: int,
        img_src: wp.array(dtype=wp.uint8),
        img_tgt: wp.array(dtype=wp.uint8),
        steps: wp.vec4i,
        plan: wp.array(dtype=wp.int64),
        plan_tgt: wp.array(dtype=wp.int64),
        alpha: wp.array(dtype=wp.uint16),
        fill: wp.vec4i,
        out: wp.array(dtype=wp.uint8),
    ):
        """out[y, x, c] from the plan (``composite_plan_kernel``); ``fill[c]`` where no side is.

        Flat arrays: ``img_*`` (H, W, C), ``out`` (Hc, Wc, C), ``plan*`` and ``alpha`` (Hc, Wc).
        ``steps`` = (src x step, src y step, tgt x step, tgt y step) in elements: C and W*C (0 along an
        axis of length 1). Thread (i, j) does row ``row0 + i``, columns j, j + col_step, ...: on CPU a
        thread loops over a whole row (no per-pixel launch overhead, see ``runtime.launch_row_loops``),
        on CUDA it does one pixel.
        """
        i, j = wp.tid()
        y = row0 + i
        for x in range(j, width, col_step):
            q = y * width + x
            o = q * wp.static(channels)
            word = plan[q]
            kind = int(word & wp.int64(3))
            p = word_offset(word)
            fx = word_fx(word)
            fy = word_fy(word)
            if kind == KIND_SOURCE:
                for c in range(wp.static(channels)):
                    out[o + c] = grey_level(sample_fixed(img_src, p + c, fx, fy, steps[0], steps[1]))
            elif kind == KIND_TARGET:
                for c in range(wp.static(channels)):
                    out[o + c] = grey_level(sample_fixed(img_tgt, p + c, fx, fy, steps[2], steps[3]))
            elif kind == KIND_BLEND:
                word_t = plan_tgt[q]
                p_t = word_offset(word_t)
                fx_t = word_fx(word_t)
                fy_t = word_fy(word_t)
                a = wp.int64(alpha[q])
                shift = wp.int64(2 * FRAC_BITS + ALPHA_BITS)
                for c in range(wp.static(channels)):
                    mix = a * wp.int64(sample_fixed(img_src, p + c, fx, fy, steps[0], steps[1])) + (
                        wp.int64(1 << ALPHA_BITS) - a) * wp.int64(sample_fixed(img_tgt, p_t + c, fx_t, fy_t, steps[2], steps[3]))
                    out[o + c] = wp.uint8(wp.min(int((mix + (wp.int64(1) << (shift - wp.int64(1)))) >> shift), 255))
            else:
                for c in range(wp.static(channels)):
                    out[o + c] = wp.uint8(fill[c])

    return composite_fixed


MAX_CHANNELS = 4  # the frame kernel takes the fill values as one vec4i
# The frame kernel per channel count, built at import so that ``runtime.prewarm`` loads them all.
COMPOSITE_FIXED_KERNELS = {channels: _composite_fixed_kernel(channels) for channels in range(1, MAX_CHANNELS + 1)}
