"""The per-frame seam's work on its band of cells (``video/frame_seam.py``), on the host.

The band's difference, sum and change since the last frame come from
``composite.band_difference_kernel`` on the frame's device (``NOT_BOTH`` and 0 where a cell does not
hold both views), downloaded in one small block. Three kernels follow it each frame on Warp's CPU
device (:data:`DEVICE`), where the band's few thousand cells are, so the band is read a few times
rather than by a dozen array expressions: what is in front of the background model (a static rig),
what each cell costs the seam's paths, and the difference next to the chosen seam (the seam blend's).
The first runs over ``runtime.launch_row_loops`` (thread i does line ``row0 + i``, cells j, j +
col_step, ... < width), the others one thread per line (``runtime.launch_rows`` with width 1): they
reduce along it.
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS
from sena_warp.kernels.composite import holds_both

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring

DEVICE = "cpu"  # the band's cells are on the host, whatever the frame's device


@wp.struct
class BackgroundModel:
    """The band's background model (``background_kernel``): per cell the source-plus-target luma of the
    background and its mean absolute deviation, learnt at rate ``learn``; ``off`` 1 where a frame's cell
    is off it by more than ``noise`` and ``spread_factor`` deviations."""

    background: wp.array2d(dtype=float)
    spread: wp.array2d(dtype=float)
    off: wp.array2d(dtype=wp.uint8)
    noise: float
    spread_factor: float
    learn: float


@wp.struct
class SeamCosts:
    """What a band cell costs the per-frame seam (``band_cost_kernel``): per px away from the last seam
    ``stay_cost``, the glide's reach ``speed`` px, the noise floor ``noise`` of the difference,
    ``motion_cost`` where something is in front, ``blocked_cost`` without both views, ``block_cost`` off
    limits."""

    speed: float
    noise: float
    motion_cost: float
    blocked_cost: float
    stay_cost: float
    block_cost: float


@wp.struct
class LastSeam:
    """The last frame's seam per band line (``last``, px), which lines are still (``still`` 1), and the
    first cell of each line's glide (``glide_first``)."""

    last: wp.array(dtype=int)
    still: wp.array(dtype=wp.uint8)
    glide_first: wp.array(dtype=int)


@wp.struct
class CellCosts:
    """``band_cost_kernel``'s output: each cell's ``change``, the free path's ``free`` and the glide's
    ``glide`` costs, each line's cheapest ``line_min``."""

    change: wp.array2d(dtype=float)
    free: wp.array2d(dtype=float)
    glide: wp.array2d(dtype=float)
    line_min: wp.array(dtype=float)


@wp.kernel
def background_kernel(
    row0: int,
    col_step: int,
    width: int,
    diff: wp.array2d(dtype=float),
    total: wp.array2d(dtype=float),
    gain_less_one: float,
    offset: float,
    model: BackgroundModel,
):
    """One frame of the band's background model: ``model.off`` 1 where the cell's source-plus-target
    ``total`` is off its background beyond what the whole band's gain and offset explain
    (``gain_less_one * background + offset``) by more than the noise and ``spread_factor`` x the cell's
    mean absolute deviation; then both learn at rate ``learn``. Cells without both views neither count
    nor learn."""
    i, j0 = wp.tid()
    k = row0 + i
    for j in range(j0, width, col_step):
        both = holds_both(diff[k, j])
        background = model.background[k, j]
        change = float(0.0)
        if both:
            change = total[k, j] - background
        explained = gain_less_one * background
        explained = explained + offset
        deviation = wp.abs(change - explained)
        spread_now = model.spread[k, j]
        limit = wp.max(model.noise, model.spread_factor * spread_now)
        model.off[k, j] = wp.uint8(0)
        if both and deviation > limit:
            model.off[k, j] = wp.uint8(1)
        step = model.learn * change
        model.background[k, j] = background + step
        if both:
            step = model.learn * (deviation - spread_now)
            model.spread[k, j] = spread_now + step


@wp.kernel
def band_cost_kernel(
    row0: int,
    diff: wp.array2d(dtype=float),
    moving: wp.array2d(dtype=wp.uint8),
    home_term: wp.array2d(dtype=float),
    band_x0: wp.array(dtype=int),
    cell: int,
    last: LastSeam,
    costs: SeamCosts,
    out: CellCosts,
):
    """What each band cell costs a path (band cell j of line k at ``band_x0[k] + cell j``):

    - ``out.change``: its difference beyond ``noise``, plus ``motion_cost`` where something is in front
      (``moving``), or ``blocked_cost`` without both views;
    - the path's cost: that plus ``home_term`` and ``stay_cost`` per px from the last frame's seam
      ``last.last``; ``out.free`` adds ``block_cost`` off the last seam on still lines (``last.still``);
    - ``out.glide`` (K, G): the path's cost on the G cells from ``last.glide_first[k]``, plus
      ``block_cost`` on those more than ``speed`` px from the last seam (or than the band's own distance
      from it, where the band has moved past it) and off it on still lines;
    - ``out.line_min``: each line's cheapest ``change``.

    One thread per line (``runtime.launch_rows`` with width 1).
    """
    i, _j = wp.tid()
    k = row0 + i
    x0 = band_x0[k]
    seam = last.last[k]
    keep = last.still[k] != wp.uint8(0)
    first = last.glide_first[k]
    glide_width = out.glide.shape[1]
    width = diff.shape[1]
    outside = wp.max(wp.max(x0 - seam, seam - (x0 + cell * (width - 1))), 0)
    reach = wp.max(costs.speed, float(outside))
    lowest = float(1.0e30)
    for j in range(width):
        d = diff[k, j]
        c = wp.max(wp.abs(d) - costs.noise, 0.0)
        c = c + costs.motion_cost * float(moving[k, j])
        if not holds_both(d):
            c = costs.blocked_cost
        out.change[k, j] = c
        lowest = wp.min(lowest, c)
        pos = x0 + cell * j
        total = c + home_term[k, j]
        total = total + costs.stay_cost * float(wp.abs(pos - seam))
        held = keep and pos != seam
        free = total
        if held:
            free = total + costs.block_cost
        out.free[k, j] = free
        if j >= first and j < first + glide_width:
            glide = total
            if held or float(wp.abs(pos - seam)) > reach:
                glide = total + costs.block_cost
            out.glide[k, j - first] = glide
    out.line_min[k] = lowest


@wp.kernel
def strip_mean_kernel(
    row0: int,
    diff: wp.array2d(dtype=float),
    band_x0: wp.array(dtype=int),
    cell: int,
    path: wp.array(dtype=int),
    reach: int,
    mean: wp.array(dtype=float),
    count: wp.array(dtype=int),
):
    """Per solved line k = row0 + i: the mean difference of the band cells holding both views within
    ``reach`` cells of the seam ``path[k]`` (on the band's grid), and how many there are (``count``;
    ``mean`` 0 without any)."""
    i, _j = wp.tid()
    k = row0 + i
    width = diff.shape[1]
    at = (path[k] - band_x0[k]) / cell
    total = float(0.0)
    found = int(0)
    for j in range(wp.max(at - reach, 0), wp.min(at + reach, width - 1) + 1):
        d = diff[k, j]
        if holds_both(d):
            total = total + d
            found = found + 1
    mean[k] = total / float(wp.max(found, 1))
    count[k] = found
