"""The bilinear sampling rule of the host (numpy) side: one sampler for maps, images and feature grids.

It is the rule of the Warp kernels (``kernels/remap.py``): a position (x, y) samples ``grid[y, x]``
at integer positions and blends the four taps around it; it is defined only where all four lie in
the grid, i.e. on [0, W-1] x [0, H-1], and NaN elsewhere (no clamping: a point that left the grid
must not silently read its border).
"""

from __future__ import annotations

import numpy as np


def sample_bilinear(grid: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear sample of ``grid`` (H, W) or (H, W, C), any real dtype, at (N, 2) float64 (x, y) positions.

    Returns (N,) or (N, C) float64; NaN for positions outside [0, W-1] x [0, H-1] (and for NaN positions).
    """
    height, width = grid.shape[:2]
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    x, y = pts[:, 0], pts[:, 1]
    inside = (x >= 0) & (x <= width - 1) & (y >= 0) & (y <= height - 1)
    # The last column / row is reached from the tap before it with a weight of 1.
    x0 = np.clip(np.floor(np.where(inside, x, 0)).astype(np.int64), 0, max(width - 2, 0))
    y0 = np.clip(np.floor(np.where(inside, y, 0)).astype(np.int64), 0, max(height - 2, 0))
    x1 = np.minimum(x0 + 1, width - 1)
    y1 = np.minimum(y0 + 1, height - 1)
    fx, fy = x - x0, y - y0
    if grid.ndim == 3:
        fx, fy, inside = fx[:, None], fy[:, None], inside[:, None]
    top = (1 - fx) * grid[y0, x0].astype(np.float64) + fx * grid[y0, x1].astype(np.float64)
    bottom = (1 - fx) * grid[y1, x0].astype(np.float64) + fx * grid[y1, x1].astype(np.float64)
    return np.where(inside, (1 - fy) * top + fy * bottom, np.nan)
