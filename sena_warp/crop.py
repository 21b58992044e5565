"""Optional crop of a panorama to the largest axis-aligned rectangle that is fully covered (the
paper, step 9: "cropping to the largest inner rectangle is optional")."""

from __future__ import annotations

import cv2
import numpy as np

from .imageio import check_image

SEARCH_LONG_SIDE_PX = 400  # the rectangle is searched on a mask shrunk to this long side


def largest_inner_rectangle(coverage: np.ndarray) -> tuple[int, int, int, int]:
    """(x, y, w, h) of a large rectangle inside ``coverage`` ((H, W) bool/uint8, nonzero = covered).

    Searched on a downscaled mask where a cell counts as covered only if all of it is, so the
    rectangle scaled back never includes an uncovered pixel. Maximal rectangle in a histogram, row by
    row: O(H * W) on the small mask.
    """
    covered = (np.asarray(coverage) > 0).astype(np.float32)
    h, w = covered.shape
    scale = max(1.0, max(h, w) / SEARCH_LONG_SIDE_PX)
    small_w, small_h = max(1, int(w // scale)), max(1, int(h // scale))
    cell_x, cell_y = w / small_w, h / small_h
    small = cv2.resize(covered, (small_w, small_h), interpolation=cv2.INTER_AREA) >= 1.0 - 1e-6
    best = (0, 0, 0, 0, 0)  # area, x, y, w, h in small cells
    heights = np.zeros(small_w, np.int64)
    for row in range(small_h):
        heights = np.where(small[row], heights + 1, 0)
        best = max(best, _largest_in_histogram(heights, row))
    _, x, y, rw, rh = best
    if rw == 0:
        return (0, 0, 0, 0)
    x0, y0 = int(np.ceil(x * cell_x)), int(np.ceil(y * cell_y))
    x1, y1 = int(np.floor((x + rw) * cell_x)), int(np.floor((y + rh) * cell_y))
    return (x0, y0, x1 - x0, y1 - y0)


def crop_to_covered(image_bgra: np.ndarray) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """A BGRA panorama (``Panorama.image``) cut to :func:`largest_inner_rectangle` of its alpha; and that
    (x, y, w, h) in panorama pixels. InputError for anything but a BGRA uint8 array."""
    check_image(image_bgra, "crop_to_covered", channels=4)
    x, y, w, h = largest_inner_rectangle(image_bgra[:, :, 3])
    return image_bgra[y:y + h, x:x + w], (x, y, w, h)


def _largest_in_histogram(heights: np.ndarray, row: int) -> tuple[int, int, int, int, int]:
    """Largest rectangle under a histogram whose bars end at ``row``: (area, x, y, w, h)."""
    best = (0, 0, 0, 0, 0)
    stack: list[int] = []
    for i in range(len(heights) + 1):
        current = int(heights[i]) if i < len(heights) else 0
        while stack and heights[stack[-1]] >= current:
            bar = int(heights[stack.pop()])
            left = stack[-1] + 1 if stack else 0
            width = i - left
            if bar * width > best[0]:
                best = (bar * width, left, row - bar + 1, width, bar)
        stack.append(i)
    return best
