"""The output canvas: its size and where the unwarped target sits on it.

A target pixel ``p_tgt = (x, y)`` sits at canvas position ``u = p_tgt + offset_tgt`` (SENA.md,
"Frames and conventions"). Points are float64 ``(N, 2)`` arrays of ``(x, y)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Canvas:
    """Canvas of ``width x height`` pixels; the target's origin is at ``offset_tgt = (ox, oy)``."""

    width: int
    height: int
    offset_tgt: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``, numpy order, for allocating canvas-sized arrays."""
        return (self.height, self.width)

    def tgt_to_canvas(self, pts_tgt: np.ndarray) -> np.ndarray:
        """Target ``(x, y)`` points ``(N, 2)`` -> canvas points ``(N, 2)`` float64."""
        return np.asarray(pts_tgt, dtype=np.float64) + np.asarray(self.offset_tgt, dtype=np.float64)

    def canvas_to_tgt(self, pts_canvas: np.ndarray) -> np.ndarray:
        """Canvas ``(x, y)`` points ``(N, 2)`` -> target points ``(N, 2)`` float64."""
        return np.asarray(pts_canvas, dtype=np.float64) - np.asarray(self.offset_tgt, dtype=np.float64)
