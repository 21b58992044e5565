"""What moves in each view, on the per-frame seam's cells (``video/frame_objects.py``).

The band's cells hold, per solved seam line and cell, the source minus the target (``diff``,
``NOT_BOTH`` where a cell lacks a view) and their sum (``total``), as
``composite.band_difference_kernel`` gives them; each view's own luma there is half their sum and
half their difference. Two kernels: each view's background model (a running mean and mean absolute
deviation per cell, which flags the cells where that view is off it), and the object band's masks on
the seam's finer band. Both run over
``runtime.launch_row_loops`` (thread i does line ``row0 + i``, cells j, j + col_step, ... < width).
The loops over a line's cells are ``while`` loops: Warp's CPU code for a ``range()`` with a run-time step
steps a general iterator (0.23 -> 0.20 ms a frame for the masks' copy on the 1080p bench's band), and the
masks' loop follows its coarse cell without an integer division per cell (0.20 -> 0.16 ms).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS
from sena_warp.kernels.composite import holds_both

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring


@wp.struct
class ViewModels:
    """Both views' background models over the band's cells, index 0 the source's, 1 the target's:
    ``background`` (2, K, width) float32 each cell's luma; ``spread`` how much it changes from one frame
    to the next as a rule (a running mean of that change: leaves in the wind, a flickering screen);
    ``last`` its luma in the last frame; ``off`` (2, K, width) uint8 1 where the last frame was off the
    background by more than ``noise`` and ``spread_factor`` x the spread. Both learn at ``learn`` per
    frame, where the cell is off the background at ``learn_off`` (what stands still in front of the
    background stays in front for a while) and the spread at ``spread_off`` (an object's own texture
    passing by changes the cell every frame: it is not the background's usual change)."""

    background: wp.array3d(dtype=float)
    spread: wp.array3d(dtype=float)
    last: wp.array3d(dtype=float)
    off: wp.array3d(dtype=wp.uint8)
    noise: float
    spread_factor: float
    learn: float
    learn_off: float
    spread_off: float


@wp.func
def view_luma(diff: float, total: float, view: int) -> float:
    """A view's luma from the band's difference (source minus target) and sum: view 0 the source's."""
    if view == 0:
        return 0.5 * (total + diff)
    return 0.5 * (total - diff)


@wp.kernel
def view_background_kernel(
    row0: int,
    col_step: int,
    width: int,
    diff: wp.array2d(dtype=float),
    total: wp.array2d(dtype=float),
    explained: wp.vec4,
    models: ViewModels,
):
    """One frame of both views' background models: ``off`` 1 where a view's luma is off its
    background beyond what that view's whole-band gain and offset explain (``explained``: gain - 1
    and offset of the source, then of the target: ``(gain - 1) * background + offset``), by more than
    the noise and the spread factor x the cell's spread; then both learn. Cells without both views
    neither count nor learn."""
    i, j0 = wp.tid()
    k = row0 + i
    j = j0
    while j < width:  # not range(): see the module docstring
        d = diff[k, j]
        both = holds_both(d)
        for view in range(2):
            model = models.background[view, k, j]
            models.off[view, k, j] = wp.uint8(0)
            if both:
                luma = view_luma(d, total[k, j], view)
                change = luma - model
                deviation = wp.abs(change - (explained[2 * view] * model + explained[2 * view + 1]))
                spread_now = models.spread[view, k, j]
                rate = models.learn
                spread_rate = models.learn
                if deviation > wp.max(models.noise, models.spread_factor * spread_now):
                    models.off[view, k, j] = wp.uint8(1)
                    rate = models.learn_off
                    spread_rate = models.spread_off
                models.background[view, k, j] = model + rate * change
                step = wp.abs(luma - models.last[view, k, j]) - spread_now
                models.spread[view, k, j] = spread_now + spread_rate * step
                models.last[view, k, j] = luma
        j = j + col_step


@wp.struct
class CellGrid:
    """A band's cells: solved line k's first cell at position ``x0[k]``, cells ``cell`` px wide; its
    solved lines are every ``step``-th seam line (the last one too)."""

    x0: wp.array(dtype=int)
    cell: int
    step: int


@wp.kernel
def coarse_masks_kernel(
    row0: int,
    col_step: int,
    width: int,
    lines: wp.array(dtype=int),
    fine: CellGrid,
    coarse: CellGrid,
    moving_coarse: wp.array2d(dtype=wp.uint8),
    kept_coarse: wp.array2d(dtype=wp.uint8),
    moving: wp.array2d(dtype=wp.uint8),
    kept_off: wp.array2d(dtype=wp.uint8),
):
    """The object band's ``moving`` and ``kept_off`` cells on a finer band's (solved line k = row0 + i,
    seam line ``lines[k]``, cells of ``fine``): each fine cell takes the coarse cell it lies in, on
    the nearest coarse line; 0 outside the coarse band."""
    i, j0 = wp.tid()
    k = row0 + i
    kc = wp.min((lines[k] + coarse.step / 2) / coarse.step, moving_coarse.shape[0] - 1)
    start = coarse.x0[kc]
    step = col_step * fine.cell
    j = j0
    pos = fine.x0[k] + j * fine.cell
    # The coarse cell jc of pos (where pos >= start) kept as pos - start = jc coarse cells + rest, 0 <= rest
    # < a coarse cell: one division a line, not one a cell (module docstring).
    jc = int(0)
    rest = pos - start
    if rest >= 0:
        jc = rest / coarse.cell
        rest = rest - jc * coarse.cell
    while j < width:  # not range(): see the module docstring
        if pos >= start and jc < moving_coarse.shape[1]:
            moving[k, j] = moving_coarse[kc, jc]
            kept_off[k, j] = kept_coarse[kc, jc]
        else:
            moving[k, j] = wp.uint8(0)
            kept_off[k, j] = wp.uint8(0)
        j = j + col_step
        if j < width:
            pos = pos + step
            rest = rest + step
            while rest >= coarse.cell:
                rest = rest - coarse.cell
                jc = jc + 1
