"""Static rig: how far has each camera's view moved since its maps were made?

A static rig's maps are estimated once, but a camera on a pole or a loose mount creeps: on the shared
pitch one camera's view moves up by 25 px and the other's sideways by 10 px in 8 s, and maps made in
the first second leave the curb stepped by 15-25 px at the seam. A small turn of a camera moves its
whole view by about one shift, so each view is compared with its view when the maps were made, now
and then, and the maps are moved by what the two views moved (``maps.drifted_maps``). A new estimate
would cost seconds and its noise: two estimates of the fixed office or lecture-hall rig differ by
2.4-4.5 px (median map change), and where the source view is extrapolated far from the overlap they
move its far side by tens of pixels.

The comparison is a phase correlation (OpenCV) of small greyscale copies (:data:`THUMB_WIDTH_PX`
wide, a Hann window against the borders) of the part of each view that the overlap shows
(:func:`overlap_boxes`, with a margin): where the seam is, a turn's shift is what matters (on the
pitch the whole views' shifts left the curb stepped by 4-5 grey levels at the seam). It finds one
shift of that part, and people
walking through a fixed view barely move its peak (the fixed rigs measure 0.5-3.3 px over their
recordings). Its peak's response says how alike the views still are: below :data:`MIN_RESPONSE` (a
hand-held camera that went elsewhere, the scene changed) the shift is not trusted and the maps stay;
so do they for a move larger or faster than a drift (:data:`MAX_SHARE`, :data:`MAX_STEP_SHARE` of the
width: a rig that moves needs ``--rig moving``, whose re-estimates follow turns and parallax, not
just a shift).
"""

from __future__ import annotations

import cv2
import numpy as np

from .maps import PlaneMaps, sampled_mask

THUMB_WIDTH_PX = 320  # views are compared at this width at most (a 1080p frame: 1/6)
BOX_MARGIN = 0.1  # the overlap's box in each view, widened by this x its size each side
MIN_RESPONSE = 0.15  # phase correlation peaks below this are not trusted (the pitch's views, 8 s on: 0.26)
MAX_SHARE = 0.05  # a move beyond this x the view's width is not a drift but a moving rig (the pitch: 0.023) ...
MAX_STEP_SHARE = 0.01  # ... nor one that changed by more since the last check (a pan; the pitch: 0.004)
HISTORY = 3  # the moves given are the median of this many last checks (people in the view jolt one check)


def overlap_boxes(maps: PlaneMaps, shape_src: tuple[int, int], shape_tgt: tuple[int, int]
                  ) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]]:
    """(x0, y0, x1, y1) of the part of the source's and of the target's Y plane (``shape_*`` = (rows,
    cols)) that the maps' overlap samples, widened by :data:`BOX_MARGIN`; whole views without one."""
    both = sampled_mask(maps.map_src_luma, shape_src) & sampled_mask(maps.map_tgt_luma, shape_tgt)
    boxes = []
    for map_canvas, (rows, cols) in ((maps.map_src_luma, shape_src), (maps.map_tgt_luma, shape_tgt)):
        if not both.any():
            boxes.append((0, 0, cols, rows))
            continue
        x, y = map_canvas[both, 0], map_canvas[both, 1]
        margin_x, margin_y = BOX_MARGIN * (x.max() - x.min()), BOX_MARGIN * (y.max() - y.min())
        boxes.append((int(max(0, x.min() - margin_x)), int(max(0, y.min() - margin_y)),
                      int(min(cols, np.ceil(x.max() + margin_x) + 1)), int(min(rows, np.ceil(y.max() + margin_y) + 1))))
    return boxes[0], boxes[1]


def thumbnail(y: np.ndarray) -> tuple[np.ndarray, float]:
    """A view's luma (H, W) uint8 as a small float32 copy at most :data:`THUMB_WIDTH_PX` wide, and the
    input px per thumbnail px."""
    height, width = y.shape
    scale = max(1.0, width / THUMB_WIDTH_PX)
    size = (max(1, int(round(width / scale))), max(1, int(round(height / scale))))
    return cv2.resize(y, size, interpolation=cv2.INTER_AREA).astype(np.float32), scale


def hann_window(thumb: np.ndarray) -> np.ndarray:
    """The Hann window for :func:`view_shift` on thumbnails of ``thumb``'s shape (made once per view)."""
    return cv2.createHanningWindow((thumb.shape[1], thumb.shape[0]), cv2.CV_32F)


def view_shift(reference: np.ndarray, now: np.ndarray, scale: float, window: np.ndarray) -> tuple[np.ndarray, float]:
    """How far a view's content moved (x, y input px) between two :func:`thumbnail` copies of it, and the
    phase correlation's peak response (1: the same picture moved; near 0: nothing in common);
    ``window``: :func:`hann_window` of them."""
    (dx, dy), response = cv2.phaseCorrelate(reference, now, window)
    return np.array([dx, dy]) * scale, float(response)


class DriftWatch:
    """Each camera's view (its part ``boxes``: (x0, y0, x1, y1) in the source's and the target's Y
    plane, :func:`overlap_boxes`) as it was when the maps were made, and how far each has moved since."""

    def __init__(self, y_src: np.ndarray, y_tgt: np.ndarray, boxes: tuple[tuple[int, int, int, int], ...]):
        self._boxes = boxes
        # Per view: its reference thumbnail, input px per thumbnail px, and the window for comparing it.
        self._references = [(thumb, scale, hann_window(thumb))
                            for thumb, scale in (thumbnail(part) for part in self._parts(y_src, y_tgt))]
        self._last = [np.zeros(2), np.zeros(2)]  # the moves the last comparable check found
        self._history: list[tuple[np.ndarray, np.ndarray]] = []  # the last HISTORY trusted (source, target) moves

    def _parts(self, y_src: np.ndarray, y_tgt: np.ndarray) -> list[np.ndarray]:
        return [y[y0:y1, x0:x1] for y, (x0, y0, x1, y1) in zip((y_src, y_tgt), self._boxes)]

    def shifts(self, y_src: np.ndarray, y_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(source's, target's) content moves (x, y) in input px from the reference views to these (the
        median of the last :data:`HISTORY` trusted checks, this one included), or None where either
        comparison is not trusted (:data:`MIN_RESPONSE`) or either move is too large or too fast for a
        drift (:data:`MAX_SHARE`, :data:`MAX_STEP_SHARE`: a rig that moved on and stays is followed from
        the next check on)."""
        moves = [view_shift(reference, thumbnail(part)[0], scale, window)
                 for (reference, scale, window), part in zip(self._references, self._parts(y_src, y_tgt))]
        if min(response for _, response in moves) < MIN_RESPONSE:
            return None
        widths = [y.shape[1] for y in (y_src, y_tgt)]
        steps = [float(np.abs(move - last).max()) for (move, _), last in zip(moves, self._last)]
        self._last = [move for move, _ in moves]
        if any(np.abs(move).max() > MAX_SHARE * width or step > MAX_STEP_SHARE * width
               for (move, _), step, width in zip(moves, steps, widths)):
            return None
        self._history = [*self._history, (moves[0][0], moves[1][0])][-HISTORY:]
        source, target = (np.median(np.array(side), axis=0) for side in zip(*self._history))
        return source, target
