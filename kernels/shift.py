"""A plane shown shifted: the output frame as a window on the composited canvas (a moving rig's steady
canvas, ``video/steady.py``).

Output pixel (x, y) is the canvas at (x, y) + ``origin``, a sub-pixel position, interpolated with
Catmull-Rom's cubic (four taps a direction: a whole-pixel origin copies the canvas exactly, and a half
pixel softens less than a bilinear tap would); positions off the canvas show ``fill``. Generic in C
(1: the Y plane, 2: the interleaved U/V plane).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring


@wp.func
def catmull_rom(t: float) -> wp.vec4:
    """The four tap weights (at -1, 0, 1, 2) of Catmull-Rom's cubic at fraction t in [0, 1)."""
    t2 = t * t
    t3 = t2 * t
    return wp.vec4(0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
                   0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2))


@wp.kernel
def shifted_plane_kernel(
    row0: int,
    col_step: int,
    width: int,
    canvas: wp.array3d(dtype=wp.uint8),
    origin: wp.vec2,
    fill: wp.vec2i,
    out: wp.array3d(dtype=wp.uint8),
):
    """out[y, x, c] = canvas at (x + origin.x, y + origin.y), channel c (module docstring); row-loop launch."""
    i, j = wp.tid()
    y = row0 + i
    rows = canvas.shape[0]
    cols = canvas.shape[1]
    sy = float(y) + origin[1]
    iy = int(wp.floor(sy))
    wy = catmull_rom(sy - float(iy))
    x = j
    while x < width:
        sx = float(x) + origin[0]
        inside = sx >= 0.0 and sy >= 0.0 and sx <= float(cols - 1) and sy <= float(rows - 1)
        ix = int(wp.floor(sx))
        wx = catmull_rom(sx - float(ix))
        for c in range(out.shape[2]):
            v = float(fill[c])
            if inside:
                v = 0.0
                for a in range(4):
                    r = wp.clamp(iy - 1 + a, 0, rows - 1)
                    line = 0.0
                    for b in range(4):
                        line += wx[b] * float(canvas[r, wp.clamp(ix - 1 + b, 0, cols - 1), c])
                    v += wy[a] * line
            out[y, x, c] = wp.uint8(int(wp.clamp(v + 0.5, 0.0, 255.0)))
        x += col_step
