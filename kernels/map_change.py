"""How far a source map moved between two map sets, per canvas pixel (``video/maps.map_change_px``).

A percentile of |M_s after - M_s before| over the canvas pixels both sample in the source (and, where
asked, the target: the overlap), on a grid of every ``stride``-th row and column: the video reports
it for every frame whose maps changed (stride 4, the jitter figure), and a moving rig's re-estimate
is rejected on its median (stride 1). Worked out per pixel in one pass over the three maps: the
strided numpy version took 9-12 ms a blend step at 1080p, mostly in its gathers. Float32 as numpy
takes it: ``sqrt(dx * dx + dy * dy)``.

The maps are numpy arrays on the host whatever the device of the stitch, so these kernels run on
Warp's CPU device (``DEVICE``; ``runtime.prewarm`` loads them there).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS
from sena_warp.kernels.composite import inside

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring

DEVICE = "cpu"  # where this module's kernels always run
NOT_COUNTED = wp.constant(float("nan"))  # a pixel either map does not sample (or outside the overlap)


@wp.kernel
def map_change_kernel(
    row0: int,
    stride: int,
    before: wp.array2d(dtype=wp.vec2),
    after: wp.array2d(dtype=wp.vec2),
    shape_src: wp.vec3i,
    tgt: wp.array2d(dtype=wp.vec2),
    shape_tgt: wp.vec3i,
    overlap_only: int,
    change: wp.array2d(dtype=float),
):
    """change[i, j] at canvas pixel (stride * (row0 + i), stride * j): |after - before| in source px where
    both sample a source image of (H, W, C) ``shape_src`` and, with ``overlap_only``, ``tgt`` samples
    one of ``shape_tgt``; NaN elsewhere."""
    i, j = wp.tid()
    y = stride * (row0 + i)
    x = stride * j
    p0 = before[y, x]
    p1 = after[y, x]
    counted = inside(p0, shape_src) and inside(p1, shape_src)
    if overlap_only != 0:
        counted = counted and inside(tgt[y, x], shape_tgt)
    value = NOT_COUNTED
    if counted:
        dx = p1[0] - p0[0]
        dy = p1[1] - p0[1]
        value = wp.sqrt(dx * dx + dy * dy)
    change[row0 + i, j] = value
