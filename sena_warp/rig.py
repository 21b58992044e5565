"""Which input is the source (warped, left) and which the target (reference), and rig orientation.

Roles (``docs/method.md``): source = left view, target = right view. Which input is left (or top),
and whether the views lie side by side or one above the other, is found from how the view as a whole
shifts from one input to the other (:func:`view_shift`): the median of the matches' shifts per region
of the view, then the median over the regions, each region one vote. That is where the views' own
strips lie (the left view's own strip on its left). A near object's matches, many and clustered, shift
further than the background and may shift up or down too (cameras at slightly different heights); by
count they would decide, by area they do not. A vertical rig is handled by transposing internally.
The pipeline works in a *working frame* where the source is always left; for a vertical rig that
frame is the transpose of the input (x and y swapped). Maps built in the working frame are turned
back into the input frame once, so the compositor never transposes frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError

REFERENCES = ("auto", "a", "b")
SHIFT_GRID = 8  # the view is cut into this x this regions, each one vote on how it shifts
SHIFT_MIN_MATCHES = 3  # a region votes with this many matches at least
MIN_SHIFT_PX = 10.0  # a view shifting less than this both ways cannot tell how the views lie


@dataclass(frozen=True)
class Rig:
    source: str  # "a" or "b": the input that is warped
    vertical: bool  # True: the views are stacked top/bottom; work transposed
    median_dx_px: float  # median of x_a - x_b over the matches (input frame)
    median_dy_px: float  # median of y_a - y_b
    shift_x_px: float  # how the view as a whole shifts in x from a to b (view_shift; the median's where
    shift_y_px: float  # both are under MIN_SHIFT_PX) in x and y: > 0, a is left (top)

    @property
    def target(self) -> str:
        return "b" if self.source == "a" else "a"

    def pick(self, item_a, item_b) -> tuple:
        """Order a pair of per-input things as (source, target)."""
        return (item_a, item_b) if self.source == "a" else (item_b, item_a)


def view_shift(pts_a: np.ndarray, pts_b: np.ndarray, shape_a: tuple[int, ...]) -> np.ndarray:
    """(2,) float64 (dx, dy): how the view as a whole shifts from a to b (``pts_a - pts_b``, matched
    (N, 2) (x, y) points of an image a of ``shape_a`` (rows, cols, ...)): the median shift of the
    matches in each of :data:`SHIFT_GRID` x :data:`SHIFT_GRID` regions of a that hold
    :data:`SHIFT_MIN_MATCHES` of them, then the median over those regions; the matches' median where no
    region does."""
    height, width = shape_a[:2]
    shifts = pts_a - pts_b
    col = np.clip((pts_a[:, 0] * SHIFT_GRID / width).astype(int), 0, SHIFT_GRID - 1)
    row = np.clip((pts_a[:, 1] * SHIFT_GRID / height).astype(int), 0, SHIFT_GRID - 1)
    region = row * SHIFT_GRID + col
    votes = [np.median(shifts[region == r], axis=0) for r in np.unique(region)
             if np.count_nonzero(region == r) >= SHIFT_MIN_MATCHES]
    return np.median(votes, axis=0) if votes else np.median(shifts, axis=0)


def detect_rig(pts_a: np.ndarray, pts_b: np.ndarray, shape_a: tuple[int, ...], reference: str = "auto") -> Rig:
    """Find the left (or top) view from matched points, (N, 2) xy in each input's pixels, image a of
    ``shape_a`` (rows, cols, ...) (module docstring).

    A scene point lies further right in the left view than in the right one: the view as a whole
    shifting right from a to b (:func:`view_shift`, dx > 0) makes a the left view; a larger shift in y
    than in x, a vertical rig. Where it shifts less than :data:`MIN_SHIFT_PX` both ways, the matches'
    median shift decides. ``reference`` ("a" or "b") forces which input is the unwarped target;
    "auto" makes the right (bottom) view the target.
    """
    if reference not in REFERENCES:
        raise InputError(f"--reference must be one of {', '.join(REFERENCES)}, not {reference!r}")
    dx = float(np.median(pts_a[:, 0] - pts_b[:, 0])) if len(pts_a) else 0.0
    dy = float(np.median(pts_a[:, 1] - pts_b[:, 1])) if len(pts_a) else 0.0
    shift_x, shift_y = (float(v) for v in view_shift(pts_a, pts_b, shape_a)) if len(pts_a) else (0.0, 0.0)
    if max(abs(shift_x), abs(shift_y)) < MIN_SHIFT_PX:  # views that share almost everything: the matches decide
        shift_x, shift_y = dx, dy
    vertical = abs(shift_y) > abs(shift_x)
    a_first = (shift_y if vertical else shift_x) >= 0.0
    if reference == "auto":
        source = "a" if a_first else "b"
    else:
        source = "b" if reference == "a" else "a"
    return Rig(source=source, vertical=vertical, median_dx_px=dx, median_dy_px=dy, shift_x_px=shift_x,
               shift_y_px=shift_y)


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
