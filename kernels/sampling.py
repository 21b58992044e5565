"""Full-resolution source sampling map (docs/method.md step 6).

``M_s(u) = A_glob^-1 (u - o) + D_guarded(u)``: for each canvas pixel u = (x, y), the (x, y)
position in the source image to sample. Affine math in float64, map stored as float32.
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring


@wp.kernel
def source_map_kernel(
    row0: int,
    offset_tgt: wp.vec2d,
    glob_linear_tgt_to_src: wp.mat22d,
    glob_translation_tgt_to_src: wp.vec2d,
    field_guarded: wp.array2d(dtype=wp.vec2),
    map_src: wp.array2d(dtype=wp.vec2),
):
    """map_src[y, x] = source (x, y) sampled by canvas pixel (x, y)."""
    i, x = wp.tid()
    y = row0 + i
    p_tgt = wp.vec2d(wp.float64(x), wp.float64(y)) - offset_tgt
    p_src = glob_linear_tgt_to_src @ p_tgt + glob_translation_tgt_to_src
    d = field_guarded[y, x]
    map_src[y, x] = wp.vec2(wp.float32(p_src[0]) + d[0], wp.float32(p_src[1]) + d[1])
