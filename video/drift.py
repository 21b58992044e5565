"""Static rig: has a camera moved since its maps were made? (issue 14: "a floodlit pitch ... slight drift").

A static rig's maps are estimated once, but a camera on a pole or a loose mount creeps: on the shared
pitch one camera's view moves up by 25 px and the other's sideways by 10 px in 8 s, and maps made in
the first second leave the curb stepped by 15-25 px at the seam. Re-estimating on a schedule would
cost an estimate every period and move a truly fixed rig's seam with estimation noise (the map change
between two estimates of the fixed office and lecture-hall rigs is 2.4-4.5 px median); so each
camera's view is compared with its view when the maps were made instead, now and then, and only a
camera that moved by more than ``video_drift_px`` asks for a new estimate.

The comparison is a phase correlation (OpenCV) of small greyscale copies (:data:`THUMB_WIDTH_PX`
wide, a Hann window against the borders): it finds the one shift of the whole view, and people
walking through a fixed view barely move its peak (the fixed rigs measure 0.5-3.3 px over their
recordings).
"""

from __future__ import annotations

import cv2
import numpy as np

THUMB_WIDTH_PX = 320  # views are compared at this width (a 1080p frame: 1/6)


def thumbnail(y: np.ndarray) -> tuple[np.ndarray, float]:
    """A view's luma (H, W) uint8 as a small float32 copy :data:`THUMB_WIDTH_PX` wide, and the input px
    per thumbnail px."""
    height, width = y.shape
    scale = width / THUMB_WIDTH_PX
    size = (THUMB_WIDTH_PX, max(1, int(round(height / scale))))
    return cv2.resize(y, size, interpolation=cv2.INTER_AREA).astype(np.float32), scale


def view_shift_px(reference: np.ndarray, now: np.ndarray, scale: float) -> float:
    """How far a view moved (input px) between two :func:`thumbnail` copies of it (phase correlation)."""
    window = cv2.createHanningWindow((reference.shape[1], reference.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(reference, now, window)
    return float(np.hypot(dx, dy) * scale)


class DriftWatch:
    """Each camera's view as it was when the maps in use were made, and how far it has moved since."""

    def __init__(self, y_src: np.ndarray, y_tgt: np.ndarray):
        self._references = [thumbnail(y) for y in (y_src, y_tgt)]

    def shift_px(self, y_src: np.ndarray, y_tgt: np.ndarray) -> float:
        """The larger of the two cameras' moves (input px) from their reference views to these."""
        return max(view_shift_px(reference, thumbnail(y)[0], scale)
                   for (reference, scale), y in zip(self._references, (y_src, y_tgt)))
