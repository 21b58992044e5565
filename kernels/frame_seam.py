"""The per-frame seam's work on its band of cells (``video/frame_seam.py``), on the host.

The band's difference, sum and change since the last frame come from
``composite.band_difference_kernel`` on the frame's device (``NOT_BOTH`` and 0 where a cell does not
hold both views), downloaded in one small block; what is in front of the background on a static rig
from ``kernels/frame_objects.py``. Two kernels follow on Warp's CPU device (:data:`DEVICE`), where the
band's few thousand cells are, so the band is read a few times rather than by a dozen array
expressions: what each cell costs the seam's paths, and the difference next to the chosen seam (the
seam blend's). Both run one thread per line (``runtime.launch_rows`` with width 1): they reduce along
it. A third, on one thread, moves the band's centre no faster than a path can follow (a chain of
clamps, each on the last: a loop, 10x cheaper compiled than in Python).

The kernels' loops are ``while`` loops: Warp's CPU code for a ``range()`` with run-time bounds steps a
general iterator (its step's sign unknown), which cost a third of the cost kernel's time (0.27 -> 0.19
ms a frame on the 1080p bench's band of 400 x 99 cells).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS
from sena_warp.kernels.composite import holds_both

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring

DEVICE = "cpu"  # the band's cells are on the host, whatever the frame's device


@wp.struct
class SeamCosts:
    """What a band cell costs the per-frame seam (``band_cost_kernel``): per px away from the last seam
    ``stay_cost``, the glide's reach ``speed`` px, the noise floor ``noise`` of the difference,
    ``motion_cost`` where something is in front, ``object_cost`` on the strips an object's copies span,
    ``blocked_cost`` without both views, ``block_cost`` off limits."""

    speed: float
    noise: float
    motion_cost: float
    object_cost: float
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
def band_cost_kernel(
    row0: int,
    diff: wp.array2d(dtype=float),
    moving: wp.array2d(dtype=wp.uint8),
    kept_off: wp.array2d(dtype=wp.uint8),
    home_term: wp.array2d(dtype=float),
    band_x0: wp.array(dtype=int),
    cell: int,
    last: LastSeam,
    costs: SeamCosts,
    out: CellCosts,
):
    """What each band cell costs a path (band cell j of line k at ``band_x0[k] + cell j``):

    - ``out.change``: its difference beyond ``noise``, plus ``motion_cost`` where something is in front
      (``moving``), or ``blocked_cost`` without both views; plus ``object_cost`` on the strips an
      object's copies span (``kept_off``);
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
    j = int(0)
    while j < width:  # not range(): see the module docstring
        d = diff[k, j]
        c = wp.max(wp.abs(d) - costs.noise, 0.0)
        c = c + costs.motion_cost * float(moving[k, j])
        if not holds_both(d):
            c = costs.blocked_cost
        c = c + costs.object_cost * float(kept_off[k, j])
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
        j = j + 1
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
    j = wp.max(at - reach, 0)
    last_j = wp.min(at + reach, width - 1)
    while j <= last_j:  # not range(): see the module docstring
        d = diff[k, j]
        if holds_both(d):
            total = total + d
            found = found + 1
        j = j + 1
    mean[k] = total / float(wp.max(found, 1))
    count[k] = found


@wp.func
def clamped(v: wp.float64, next_to: wp.float64, most: wp.float64) -> wp.float64:
    """``v`` clamped to within ``most`` of ``next_to``, as Python's ``min(max(v, next_to - most), next_to + most)``."""
    lo = next_to - most
    hi = next_to + most
    if lo > v:
        v = lo
    if hi < v:
        v = hi
    return v


@wp.kernel
def gentle_kernel(row0: int, positions: wp.array(dtype=wp.float64), most: wp.float64):
    """``positions`` in place, each clamped to within ``most`` of the one before it, forwards and then
    backwards (``frame_seam.gentle``: a band centre a path can follow); each clamp as Python's
    ``min(max(x, lo), hi)``. One thread (``runtime.launch_rows`` of 1 x 1): the clamps run in order."""
    _i, _j = wp.tid()
    count = positions.shape[0]
    k = int(1)
    while k < count:  # while loops, not range(): see the module docstring
        positions[k] = clamped(positions[k], positions[k - 1], most)
        k = k + 1
    k = count - 2
    while k >= 0:
        positions[k] = clamped(positions[k], positions[k + 1], most)
        k = k - 1
