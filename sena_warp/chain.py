"""Step 8: the keypoint chain that the seam follows (docs/method.md step 8, paper "Keypoint Chain Refinement"
and the directional validation of "Image Partitioning").

Inside the adequate zone: keep matches whose warped-source and target patches have the same
brightness, walk from the top-most point to the nearest remaining point further down (one point per
integer x), drop steps whose x-direction differs between source and target, and extend the ends to
the top and bottom edges of the overlap. All points are canvas (x, y) float64.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from sena_warp.config import Config
from sena_warp.errors import GeometryError
from sena_warp.zone import Zone, patch_values


class KeypointChain(NamedTuple):
    """Anchors sorted by target y, top to bottom (unpacks as ``anchors_src, anchors_tgt``).

    ``anchors_src_canvas``, ``anchors_tgt_canvas``: (K, 2) float64 (x, y) canvas positions of the
    warped source point and the target point of each anchor, edge extensions included.
    """

    anchors_src_canvas: np.ndarray
    anchors_tgt_canvas: np.ndarray


def brightness_consistent(
    grey_src_canvas: np.ndarray,
    grey_tgt_canvas: np.ndarray,
    pts_src_canvas: np.ndarray,
    pts_tgt_canvas: np.ndarray,
    cfg: Config,
) -> np.ndarray:
    """(N,) bool: |mean grey of the patch at the warped source point - that at the target point|
    <= ``cfg.brightness_max_diff``, patches of side ``cfg.flat_patch_px``.

    grey_*_canvas: (H, W) float32, NaN where not covered (a patch touching NaN fails the test).
    """
    mean_src = patch_values(grey_src_canvas, pts_src_canvas, cfg.flat_patch_px).mean(axis=1)
    mean_tgt = patch_values(grey_tgt_canvas, pts_tgt_canvas, cfg.flat_patch_px).mean(axis=1)
    return np.abs(mean_src - mean_tgt) <= cfg.brightness_max_diff


def walk_chain(pts_src_canvas: np.ndarray, pts_tgt_canvas: np.ndarray) -> np.ndarray:
    """Nearest-next walk down the target points; returns (K,) int64 indices in walk order.

    Starts at the point with the smallest target y (nearest the top edge) and repeatedly steps to
    the nearest (Euclidean, target canvas) remaining point with a strictly larger target y. A point
    whose rounded x (in the target or in the source) is already on the chain is skipped: the paper
    keeps one match per x position to prune ambiguous matches.
    """
    pts_tgt = np.asarray(pts_tgt_canvas, np.float64)
    if len(pts_tgt) == 0:
        return np.zeros(0, np.int64)
    x_tgt = np.rint(pts_tgt[:, 0]).astype(np.int64)
    x_src = np.rint(np.asarray(pts_src_canvas, np.float64)[:, 0]).astype(np.int64)
    order: list[int] = []
    current = int(np.argmin(pts_tgt[:, 1]))
    while True:
        order.append(current)
        free = (
            (pts_tgt[:, 1] > pts_tgt[current, 1])
            & ~np.isin(x_tgt, x_tgt[order])
            & ~np.isin(x_src, x_src[order])
        )
        if not free.any():
            return np.array(order, np.int64)
        candidates = np.flatnonzero(free)
        distances = np.hypot(*(pts_tgt[candidates] - pts_tgt[current]).T)
        current = int(candidates[np.argmin(distances)])


def validate_directions(anchors_src_canvas: np.ndarray, anchors_tgt_canvas: np.ndarray) -> np.ndarray:
    """(K,) bool keep-mask of an ordered chain after the paper's directional validation.

    Each step A -> B (A = last kept anchor) must move the same way in x in source and target
    (x_A > x_B and x_A' > x_B', or x_A < x_B and x_A' < x_B'); a step with opposite directions is
    rejected. A step that does not go down in the source is rejected too: the target y always
    increases along the walk, so such a step would fold the source band when it is resampled (step 9).
    """
    keep = np.zeros(len(anchors_tgt_canvas), bool)
    last = 0
    for i in range(len(anchors_tgt_canvas)):
        step_src = anchors_src_canvas[i] - anchors_src_canvas[last]
        step_tgt = anchors_tgt_canvas[i] - anchors_tgt_canvas[last]
        keep[i] = i == 0 or (step_src[0] * step_tgt[0] >= 0 and step_src[1] > 0)
        last = i if keep[i] else last
    return keep


def extend_to_edges(
    anchors_src_canvas: np.ndarray, anchors_tgt_canvas: np.ndarray, overlap_mask_canvas: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Add anchors at the top and bottom edges of the overlap, at the first/last anchor's x.

    The edge row is the first/last overlap row in the anchor's target column (the mask's bounding
    rows if that column is empty). The source edge anchor keeps its anchor's vertical residual
    (y_src - y_tgt), so the end bands are shifted, not stretched. Returns (src, tgt, is_edge) with
    is_edge (K',) bool; an end already on the edge gets no extra anchor.
    """
    src, tgt = anchors_src_canvas, anchors_tgt_canvas
    is_edge = np.zeros(len(tgt), bool)
    top_y = _overlap_rows(overlap_mask_canvas, tgt[0, 0])[0]
    if top_y < tgt[0, 1]:
        lift = np.array([0.0, top_y - tgt[0, 1]])
        src, tgt, is_edge = np.vstack([src[:1] + lift, src]), np.vstack([tgt[:1] + lift, tgt]), np.r_[True, is_edge]
    bottom_y = _overlap_rows(overlap_mask_canvas, tgt[-1, 0])[-1]
    if bottom_y > tgt[-1, 1]:
        drop = np.array([0.0, bottom_y - tgt[-1, 1]])
        src, tgt, is_edge = np.vstack([src, src[-1:] + drop]), np.vstack([tgt, tgt[-1:] + drop]), np.r_[is_edge, True]
    return src, tgt, is_edge


def _overlap_rows(overlap_mask_canvas: np.ndarray, x_canvas: float) -> np.ndarray:
    """Row indices (float64) of the overlap in the column nearest ``x_canvas``; all overlap rows if
    that column holds none."""
    col = int(np.clip(np.rint(x_canvas), 0, overlap_mask_canvas.shape[1] - 1))
    rows = np.flatnonzero(overlap_mask_canvas[:, col])
    return (rows if rows.size else np.flatnonzero(overlap_mask_canvas.any(axis=1))).astype(np.float64)


def keypoint_chain(
    zone: Zone,
    pts_src_canvas: np.ndarray,
    pts_tgt_canvas: np.ndarray,
    grey_src_canvas: np.ndarray,
    grey_tgt_canvas: np.ndarray,
    overlap_mask_canvas: np.ndarray,
    cfg: Config,
) -> KeypointChain:
    """SENA step 8: the anchors of the seam, from the matches inside ``zone``.

    pts_*_canvas: (N, 2) float64 (x, y), the same arrays given to ``adequate_zone``. Raises
    GeometryError when no match of the zone passes the brightness test.
    """
    pts_src_canvas = np.asarray(pts_src_canvas, np.float64)
    pts_tgt_canvas = np.asarray(pts_tgt_canvas, np.float64)
    candidates = zone.point_indices[
        brightness_consistent(
            grey_src_canvas, grey_tgt_canvas, pts_src_canvas[zone.point_indices], pts_tgt_canvas[zone.point_indices], cfg
        )
    ]
    if candidates.size == 0:
        raise GeometryError(
            f"no match in the seam zone x=[{zone.x0:.0f}, {zone.x1:.0f}) has consistent brightness; "
            f"try a larger brightness_max_diff (now {cfg.brightness_max_diff})"
        )
    walked = candidates[walk_chain(pts_src_canvas[candidates], pts_tgt_canvas[candidates])]
    chain = walked[validate_directions(pts_src_canvas[walked], pts_tgt_canvas[walked])]
    anchors_src, anchors_tgt, _ = extend_to_edges(pts_src_canvas[chain], pts_tgt_canvas[chain], overlap_mask_canvas)
    return KeypointChain(anchors_src, anchors_tgt)
