"""SENA step 2 (second half): the ``G_x x G_y`` grid cells c_j over the overlap.

A uniform grid is laid over the bounding box of the overlap mask (paper, step 2); each cell keeps
the part of the overlap it contains. A cell stores only its window of the canvas and that window's
mask, never a full-canvas mask, so memory stays at one overlap bounding box in total.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .config import Config
from .overlap import Overlap


@dataclass(frozen=True)
class Cell:
    """One grid cell c_j.

    ``grid_index``: ``(row, col)`` in the grid; ``window_canvas``: ``(x0, y0, x1, y1)`` int canvas
    slice bounds of the grid cell (end-exclusive: ``canvas[y0:y1, x0:x1]``); ``mask_window``:
    ``(y1 - y0, x1 - x0)`` bool, the overlap inside that window; ``n_pixels``: its pixel count;
    ``centroid_tgt``: ``(2,)`` float64 ``(x, y)`` target-frame centroid of the cell's overlap pixels
    (image moments); ``bbox_tgt``: ``(x0, y0, x1, y1)`` float64 target-frame bounding box of those
    pixels' centres (inclusive); ``diag_px``: diagonal of ``bbox_tgt``, the ``diag(c_j)`` of step 3.
    """

    grid_index: tuple[int, int]
    window_canvas: tuple[int, int, int, int]
    mask_window: np.ndarray
    n_pixels: int
    centroid_tgt: np.ndarray
    bbox_tgt: np.ndarray
    diag_px: float


def _grid_edges(start: int, stop: int, count: int) -> np.ndarray:
    """``count + 1`` integer edges splitting ``[start, stop)`` into near-equal parts."""
    return np.round(np.linspace(start, stop, count + 1)).astype(int)


def _cell(overlap: Overlap, grid_index: tuple[int, int], window: tuple[int, int, int, int]) -> Cell | None:
    x0, y0, x1, y1 = window
    mask_window = overlap.mask_canvas[y0:y1, x0:x1]
    n_pixels = int(mask_window.sum())
    if n_pixels == 0:
        return None
    moments = cv2.moments(mask_window.astype(np.uint8), binaryImage=True)
    offset_window_tgt = np.array([x0, y0], dtype=np.float64) - np.asarray(overlap.canvas.offset_tgt)
    centroid_tgt = np.array([moments["m10"], moments["m01"]]) / moments["m00"] + offset_window_tgt
    rows = np.flatnonzero(mask_window.any(axis=1))
    cols = np.flatnonzero(mask_window.any(axis=0))
    bbox_tgt = np.array([cols[0], rows[0], cols[-1], rows[-1]], dtype=np.float64) + np.tile(offset_window_tgt, 2)
    return Cell(
        grid_index=grid_index,
        window_canvas=window,
        mask_window=mask_window.copy(),
        n_pixels=n_pixels,
        centroid_tgt=centroid_tgt,
        bbox_tgt=bbox_tgt,
        diag_px=float(np.hypot(bbox_tgt[2] - bbox_tgt[0], bbox_tgt[3] - bbox_tgt[1])),
    )


def grid_cells(overlap: Overlap, cfg: Config) -> list[Cell]:
    """``cfg.grid_x x cfg.grid_y`` cells over the overlap's bounding box, row-major, empty ones dropped.

    The bounding box is that of the overlap mask's pixels on the canvas; a cell's own bounding box
    and diagonal are those of its overlap pixels (a cell cut by the polygon's edge is smaller).
    """
    rows = np.flatnonzero(overlap.mask_canvas.any(axis=1))
    cols = np.flatnonzero(overlap.mask_canvas.any(axis=0))
    if rows.size == 0:
        return []
    edges_x = _grid_edges(int(cols[0]), int(cols[-1]) + 1, cfg.grid_x)
    edges_y = _grid_edges(int(rows[0]), int(rows[-1]) + 1, cfg.grid_y)
    cells = []
    for row in range(cfg.grid_y):
        for col in range(cfg.grid_x):
            window = (int(edges_x[col]), int(edges_y[row]), int(edges_x[col + 1]), int(edges_y[row + 1]))
            cell = _cell(overlap, (row, col), window)
            if cell is not None:
                cells.append(cell)
    return cells
