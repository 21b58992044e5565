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
