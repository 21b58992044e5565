"""The seam's path through a band of canvas rows: dynamic programming, one thread per segment.

Row r of the band holds columns ``band_x0[r] .. band_x0[r] + B - 1`` of the canvas. A path takes one
column per row and moves at most ``max_step`` columns between rows, each column of sideways step
costing ``step_cost``; it minimises the sum of ``cost`` along it plus those step costs (the seam of
``sena_warp/seam_path.py``). Segments are row ranges solved independently; a segment may start and
end at a fixed canvas column (an anchor) or anywhere. Segments that share an end row must fix it
to the same column.

The inner loops are ``while`` loops: Warp's CPU code for a ``range()`` with run-time bounds steps a
general iterator (its step's sign unknown), which here cost as much as the work itself (a 400 x 99
band: 0.45 ms a solve with ``range()``, 0.23 ms with these loops, the same path).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring

DEVICE = "cpu"  # a path is a sequential walk per segment: the DP runs on the host, where its cost is

INF = wp.constant(1.0e30)


@wp.kernel
def seam_dp_kernel(
    row0: int,
    cost: wp.array2d(dtype=float),
    band_x0: wp.array(dtype=int),
    seg_first: wp.array(dtype=int),
    seg_last: wp.array(dtype=int),
    seg_start_x: wp.array(dtype=int),
    seg_end_x: wp.array(dtype=int),
    max_step: int,
    step_cost: float,
    acc: wp.array3d(dtype=float),
    back: wp.array2d(dtype=wp.int8),
    path_x: wp.array(dtype=int),
):
    """Segment s = row0 + i: rows seg_first[s] .. seg_last[s] of the band; its path into path_x (canvas x).

    ``acc`` (S, 2, B) and ``back`` (R, B) are work space: the running sums of two rows per segment,
    and the step taken into each cell.
    """
    i, _k = wp.tid()
    s = row0 + i
    r0 = seg_first[s]
    r1 = seg_last[s]
    width = cost.shape[1]
    for j in range(width):
        v = cost[r0, j]
        if seg_start_x[s] >= 0 and band_x0[r0] + j != seg_start_x[s]:
            v = INF
        acc[s, 0, j] = v
    cur = int(0)
    for r in range(r0 + 1, r1 + 1):
        nxt = 1 - cur
        shift = band_x0[r] - band_x0[r - 1]
        j = int(0)
        while j < width:  # while loops, not range(): see the module docstring
            best = float(INF)
            best_d = int(0)
            # steps d from -max_step up, within the last row's cells (jp = j + shift - d in [0, width))
            d = wp.max(-max_step, j + shift - width + 1)
            last_d = wp.min(max_step, j + shift)
            while d <= last_d:
                v = acc[s, cur, j + shift - d] + step_cost * float(wp.abs(d))
                best_d = wp.where(v < best, d, best_d)  # without a branch: which step wins is data
                best = wp.where(v < best, v, best)
                d = d + 1
            acc[s, nxt, j] = best + cost[r, j]
            back[r, j] = wp.int8(best_d)
            j = j + 1
        cur = nxt
    j = int(0)
    if seg_end_x[s] >= 0:
        j = wp.clamp(seg_end_x[s] - band_x0[r1], 0, width - 1)
    else:
        best = float(INF)
        for jj in range(width):
            if acc[s, cur, jj] < best:
                best = acc[s, cur, jj]
                j = jj
    x = band_x0[r1] + j
    path_x[r1] = x
    for k in range(r1 - r0):
        r = r1 - k
        x = x - int(back[r, x - band_x0[r]])
        path_x[r - 1] = x
