"""Which input is the source (warped, left) and which the target (reference), and rig orientation.

Roles (``docs/method.md``): source = left view, target = right view; which input is left is found from the
sign of the median x-disparity of the matches, and a vertical rig (|dy| > |dx|) is handled by
transposing internally. The pipeline works in a *working frame* where the source is always left;
for a vertical rig that frame is the transpose of the input (x and y swapped). Maps built in the
working frame are turned back into the input frame once, so the compositor never transposes frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError

REFERENCES = ("auto", "a", "b")


@dataclass(frozen=True)
class Rig:
    source: str  # "a" or "b": the input that is warped
    vertical: bool  # True: the views are stacked top/bottom; work transposed
    median_dx_px: float  # median of x_a - x_b over the matches (input frame)
    median_dy_px: float  # median of y_a - y_b

    @property
    def target(self) -> str:
        return "b" if self.source == "a" else "a"

    def pick(self, item_a, item_b) -> tuple:
        """Order a pair of per-input things as (source, target)."""
        return (item_a, item_b) if self.source == "a" else (item_b, item_a)


def detect_rig(pts_a: np.ndarray, pts_b: np.ndarray, reference: str = "auto") -> Rig:
    """Find the left (or top) view from matched points, (N, 2) xy in each input's pixels.

    A scene point seen by both views lies further right in the left view than in the right one,
    so ``median(x_a - x_b) > 0`` means ``a`` is left. ``reference`` ("a" or "b") forces which input
    is the unwarped target; "auto" makes the right (bottom) view the target.
    """
    if reference not in REFERENCES:
        raise InputError(f"--reference must be one of {', '.join(REFERENCES)}, not {reference!r}")
    dx = float(np.median(pts_a[:, 0] - pts_b[:, 0])) if len(pts_a) else 0.0
    dy = float(np.median(pts_a[:, 1] - pts_b[:, 1])) if len(pts_a) else 0.0
    vertical = abs(dy) > abs(dx)
    a_first = (dy if vertical else dx) >= 0.0
    if reference == "auto":
        source = "a" if a_first else "b"
    else:
        source = "b" if reference == "a" else "a"
    return Rig(source=source, vertical=vertical, median_dx_px=dx, median_dy_px=dy)


def image_to_working(img: np.ndarray, rig: Rig) -> np.ndarray:
    """An input image in the working frame (transposed for a vertical rig), contiguous."""
    return np.ascontiguousarray(img.transpose(1, 0, *range(2, img.ndim))) if rig.vertical else img


def points_to_working(pts: np.ndarray, rig: Rig) -> np.ndarray:
    """(N, 2) xy points of an input in the working frame (x and y swapped for a vertical rig)."""
    return np.ascontiguousarray(pts[:, ::-1]) if rig.vertical else pts


def matches_to_working(pts_a: np.ndarray, pts_b: np.ndarray, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """Matched (N, 2) xy points of inputs a and b as (pts_src, pts_tgt) in the working frame, in a
    canonical order: by source x, then source y, then target x and y.

    The order of the matches depends on which input came first (``image a b`` vs ``image b a``), and
    RANSAC samples in that order: sorted, both orders give the same model and the same maps.
    """
    pts_src, pts_tgt = (points_to_working(pts, rig) for pts in rig.pick(pts_a, pts_b))
    order = np.lexsort((pts_tgt[:, 1], pts_tgt[:, 0], pts_src[:, 1], pts_src[:, 0]))
    return np.ascontiguousarray(pts_src[order]), np.ascontiguousarray(pts_tgt[order])


def map_from_working(map_canvas: np.ndarray, rig: Rig) -> np.ndarray:
    """A working-frame canvas map, (H, W, 2) xy or (H, W) scalar, expressed in the input frame."""
    if not rig.vertical:
        return map_canvas
    if map_canvas.ndim == 3:
        return np.ascontiguousarray(map_canvas.transpose(1, 0, 2)[:, :, ::-1])
    return np.ascontiguousarray(map_canvas.T)
