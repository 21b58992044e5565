"""The output canvas: its size and where the target image sits on it (docs/method.md step 2).

A target pixel ``p_tgt`` (x, y) sits at ``u = p_tgt + o`` on the canvas, ``o = offset_tgt``. The
canvas grid is indexed ``canvas_img[y, x]`` like every image in the package.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Canvas:
    """Output pixel grid of ``height`` rows by ``width`` columns.

    ``offset_tgt`` = o = (ox, oy): canvas position (x, y) of target pixel (0, 0), in pixels.
    """

    width: int
    height: int
    offset_tgt: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) = (rows, columns), the leading shape of every canvas map."""
        return (self.height, self.width)

    def tgt_to_canvas(self, pts_tgt: np.ndarray) -> np.ndarray:
        """(N, 2) float64 (x, y) target pixels -> (N, 2) float64 (x, y) canvas pixels."""
        return np.asarray(pts_tgt, dtype=np.float64) + np.asarray(self.offset_tgt, dtype=np.float64)

    def canvas_to_tgt(self, pts_canvas: np.ndarray) -> np.ndarray:
        """(N, 2) float64 (x, y) canvas pixels -> (N, 2) float64 (x, y) target pixels."""
        return np.asarray(pts_canvas, dtype=np.float64) - np.asarray(self.offset_tgt, dtype=np.float64)
