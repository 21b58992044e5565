"""SENA step 2: the overlap polygon of the two views and the canvas that holds them.

The source rectangle is projected into the target with ``A_glob``; the resulting parallelogram is
clipped to the target rectangle with Sutherland-Hodgman (paper, step 2) to give the overlap
polygon, and the canvas is the integer bounding box of the target rectangle and the projected
source. A canvas that would be far larger than the inputs means the model is wrong: it is refused
before any canvas-sized array is allocated.

Convention: an image of ``W x H`` pixels spans the pixel centres ``x in [0, W-1], y in [0, H-1]``;
a canvas pixel belongs to a polygon when its centre lies inside it. Points are float64 ``(N, 2)``
arrays of ``(x, y)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .canvas import Canvas
from .config import Config
from .errors import GeometryError
from .affine import apply_affine

# Pixel centres this close (px) to a polygon edge count as inside: intersection vertices carry
# round-off, and a centre exactly on the target's border must stay in the overlap.
_EDGE_TOL_PX = 1e-6


def polygon_area(polygon: np.ndarray) -> float:
    """Unsigned area (px^2) of a simple polygon ``(K, 2)`` of ``(x, y)`` vertices (shoelace)."""
    return abs(_signed_area(polygon))


def _signed_area(polygon: np.ndarray) -> float:
    polygon = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    if len(polygon) < 3:
        return 0.0
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _cross_edge(edge_start: np.ndarray, edge_end: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """z of (edge_end - edge_start) x (pts - edge_start); >= 0 on the inside of a positive-area polygon."""
    edge = edge_end - edge_start
    rel = pts - edge_start
    return edge[0] * rel[..., 1] - edge[1] * rel[..., 0]


def clip_polygon(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the part of polygon ``subject`` inside the CONVEX polygon ``clip``.

    ``subject``: ``(N, 2)``, ``clip``: ``(M, 2)`` float ``(x, y)`` vertices, either orientation.
    Returns ``(K, 2)`` float64 vertices (``(0, 2)`` when the polygons do not intersect), with
    consecutive duplicate vertices removed.
    """
    clip = np.asarray(clip, dtype=np.float64).reshape(-1, 2)
    if _signed_area(clip) < 0:
        clip = clip[::-1]
    output = [p for p in np.asarray(subject, dtype=np.float64).reshape(-1, 2)]
    for i in range(len(clip)):
        edge_start, edge_end = clip[i], clip[(i + 1) % len(clip)]
        polygon, output = output, []
        for k, current in enumerate(polygon):
            previous = polygon[k - 1]
            side_cur = _cross_edge(edge_start, edge_end, current)
            side_prev = _cross_edge(edge_start, edge_end, previous)
            if side_cur >= 0:
                if side_prev < 0:
                    output.append(previous + (current - previous) * side_prev / (side_prev - side_cur))
                output.append(current)
            elif side_prev >= 0:
                output.append(previous + (current - previous) * side_prev / (side_prev - side_cur))
        if not output:
            return np.zeros((0, 2), dtype=np.float64)
    result = np.array(output, dtype=np.float64)
    keep = np.any(np.abs(result - np.roll(result, 1, axis=0)) > 0, axis=1)
    return result[keep] if keep.any() else result[:1]


def convex_polygon_mask(polygon: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Boolean ``(H, W)`` mask of the pixels whose centre lies in the CONVEX ``polygon`` ``(K, 2)``.

    The polygon is in the mask's own ``(x, y)`` pixel frame; pixel ``(x, y)`` is ``mask[y, x]``.
    Only the polygon's bounding box is tested, half-plane by half-plane.
    """
    height, width = shape
    mask = np.zeros((height, width), dtype=bool)
    polygon = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    if polygon_area(polygon) == 0.0:
        return mask
    if _signed_area(polygon) < 0:
        polygon = polygon[::-1]
    x0 = max(0, int(np.floor(polygon[:, 0].min())))
    x1 = min(width, int(np.ceil(polygon[:, 0].max())) + 1)
    y0 = max(0, int(np.floor(polygon[:, 1].min())))
    y1 = min(height, int(np.ceil(polygon[:, 1].max())) + 1)
    if x0 >= x1 or y0 >= y1:
        return mask
    xs = np.arange(x0, x1, dtype=np.float64)[None, :]
    ys = np.arange(y0, y1, dtype=np.float64)[:, None]
    inside = np.ones((y1 - y0, x1 - x0), dtype=bool)
    for i in range(len(polygon)):
        edge_start, edge_end = polygon[i], polygon[(i + 1) % len(polygon)]
        edge_x, edge_y = edge_end - edge_start
        edge_len = float(np.hypot(edge_x, edge_y))
        if edge_len > 0:
            # Signed distance of each pixel centre to the edge's line (positive inside), separable in x and y.
            dist = (edge_x * (ys - edge_start[1]) - edge_y * (xs - edge_start[0])) / edge_len
            inside &= dist >= -_EDGE_TOL_PX
    mask[y0:y1, x0:x1] = inside
    return mask


def rectangle_corners(width: int, height: int) -> np.ndarray:
    """The 4 corner pixel centres ``(4, 2)`` of a ``width x height`` image, clockwise on screen from (0, 0)."""
    return np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], dtype=np.float64)


@dataclass(frozen=True)
class Overlap:
    """Result of step 2 (overlap part).

    ``canvas``: the output grid; ``polygon_tgt`` / ``polygon_canvas``: ``(K, 2)`` float64 overlap
    polygon in target / canvas ``(x, y)``; ``mask_canvas``: ``(H, W)`` bool overlap mask on the
    canvas (``mask[y, x]``); ``corners_src_canvas``: ``(4, 2)`` float64 source corners projected
    with ``A_glob`` onto the canvas, in ``rectangle_corners`` order.
    """

    canvas: Canvas
    polygon_tgt: np.ndarray
    polygon_canvas: np.ndarray
    mask_canvas: np.ndarray
    corners_src_canvas: np.ndarray


def _check_global_affine(affine_src_to_tgt: np.ndarray, cfg: Config) -> None:
    det = float(np.linalg.det(np.asarray(affine_src_to_tgt, dtype=np.float64)[:, :2]))
    if det < 0:
        raise GeometryError(
            f"the global model mirrors the source (det {det:.3g} < 0): the matches are wrong; check that the "
            f"images overlap or try the other detector (--features sift / xfeat)"
        )
    if det < cfg.min_global_det:
        raise GeometryError(
            f"the global model shrinks the source to {det:.3g} of its area (limit {cfg.min_global_det}): the "
            f"matches are wrong; check that the images overlap or try the other detector (--features sift / xfeat)"
        )


def plan_overlap(
    shape_src: tuple[int, ...], shape_tgt: tuple[int, ...], affine_src_to_tgt: np.ndarray, cfg: Config
) -> Overlap:
    """Overlap polygon, mask and canvas for a source warped by ``A_glob`` onto a fixed target.

    ``shape_src``, ``shape_tgt``: image shapes ``(H, W[, C])``; ``affine_src_to_tgt``: ``(2, 3)``
    ``A_glob``. The canvas offset is integer, so the target is pasted without resampling.
    Raises ``GeometryError`` for a mirroring or collapsing ``A_glob``, a canvas larger than
    ``cfg.max_canvas_area_ratio`` x (area_src + area_tgt) (checked before allocating anything
    canvas-sized), or an overlap smaller than ``cfg.min_overlap_area_px``.
    """
    height_src, width_src = shape_src[:2]
    height_tgt, width_tgt = shape_tgt[:2]
    _check_global_affine(affine_src_to_tgt, cfg)
    corners_src_tgt = apply_affine(affine_src_to_tgt, rectangle_corners(width_src, height_src))
    rect_tgt = rectangle_corners(width_tgt, height_tgt)
    extent_tgt = np.vstack([corners_src_tgt, rect_tgt])
    lo = np.floor(extent_tgt.min(axis=0))
    hi = np.ceil(extent_tgt.max(axis=0))
    canvas_w, canvas_h = (hi - lo + 1).tolist()
    inputs_area = float(width_src * height_src + width_tgt * height_tgt)
    if canvas_w * canvas_h > cfg.max_canvas_area_ratio * inputs_area:
        raise GeometryError(
            f"the global model needs a {canvas_w:.0f} x {canvas_h:.0f} px canvas, "
            f"{canvas_w * canvas_h / inputs_area:.1f}x the inputs' area (limit {cfg.max_canvas_area_ratio}x): "
            f"the matches are probably wrong; check that the images overlap or try the other detector "
            f"(--features sift / xfeat)"
        )
    polygon_tgt = clip_polygon(corners_src_tgt, rect_tgt)
    overlap_area = polygon_area(polygon_tgt)
    if overlap_area < cfg.min_overlap_area_px:
        raise GeometryError(
            f"no overlap: the source, placed by the global model, covers {overlap_area:.0f} px^2 of the target "
            f"(need {cfg.min_overlap_area_px:.0f}); check that the images show the same scene"
        )
    canvas = Canvas(width=int(canvas_w), height=int(canvas_h), offset_tgt=(0.0 - float(lo[0]), 0.0 - float(lo[1])))
    polygon_canvas = canvas.tgt_to_canvas(polygon_tgt)
    return Overlap(
        canvas=canvas,
        polygon_tgt=polygon_tgt,
        polygon_canvas=polygon_canvas,
        mask_canvas=convex_polygon_mask(polygon_canvas, canvas.shape),
        corners_src_canvas=canvas.tgt_to_canvas(corners_src_tgt),
    )


def source_only_mask(overlap: Overlap) -> np.ndarray:
    """(H, W) bool canvas pixels covered by the globally placed source but not by the target.

    There the source is shown alone with its global-affine shape, so the overlap's border with this
    region is the only one across which the warp must stay continuous (the gate's ramp, step 5).
    """
    return convex_polygon_mask(overlap.corners_src_canvas, overlap.canvas.shape) & ~overlap.mask_canvas

