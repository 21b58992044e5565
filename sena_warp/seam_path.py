"""Steps 8-9 (ours): the seam follows the cheapest path through the overlap, pinned at keypoint anchors.

Between anchors the paper's seam is a straight line; where it crosses something at another depth the
two halves come from different parallax, and objects are doubled or cut. Here the seam is
a path, one x per canvas row of the working frame (source left), that minimises a cost summed along
it (dynamic programming, Warp kernel ``kernels/seam_path.py``, on the host where the cost is):

* the colour and gradient difference of the warped source and the target (both gain-compensated),
  so it runs where the two agree;
* the edge strength there, so it prefers plain regions to cutting structure;
* for every match whose two copies land apart, a cost on every x between them, since a seam there
  shows the point twice or not at all (a person who moved between the shots, a near object);
* where one view shows structure the other lacks (an object in one view only), the cost of hiding
  that structure, so objects are shown whole by the view that has them;
* per row, ``seam_step_cost`` per pixel of sideways step (at most ``seam_max_step_px``), so it
  avoids near-horizontal runs (the step limit is per canvas row at both resolutions).

It is found on a reduced canvas (long side ``seam_coarse_px``) across the adequate zone, the anchors
are the brightness-consistent matches next to that path (the paper's chain, but chosen along the
path instead of by a nearest-next walk that can step sideways across an object), and the path is
refined at full resolution in a narrow band, passing exactly through the anchors, where step 9
makes each anchor's two copies meet (the one-to-one guarantee).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import warp as wp

from .chain import brightness_consistent, keypoint_chain
from .config import Config
from .errors import GeometryError, InputError
from .warp_map import CanvasViews
from .zone import Zone
from sena_warp.kernels import runtime
from sena_warp.kernels.seam_path import DEVICE, seam_dp_kernel
from sena_warp.kernels.transfer import host_array

BLOCKED = 1.0e4  # cost of a pixel outside the overlap: a path crosses one only where nothing else is possible


@dataclass(frozen=True)
class SeamPath:
    """The seam of one stitch in the working frame.

    ``seam_x_canvas`` (H,) float32: seam x per canvas row (constant above and below ``rows``);
    ``rows``: (first, last) canvas rows where it was optimised; ``coarse_x_canvas`` (H,) float32 the
    reduced-canvas path it was refined from; ``anchors_src_canvas``, ``anchors_tgt_canvas``: (K, 2)
    float64 (x, y) of the anchors it passes through, top to bottom.
    """

    seam_x_canvas: np.ndarray
    rows: tuple[int, int]
    coarse_x_canvas: np.ndarray
    anchors_src_canvas: np.ndarray
    anchors_tgt_canvas: np.ndarray


def _grey(img: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 and img.shape[2] == 3 else img.reshape(img.shape[:2])


def _gradient(grey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sobel derivatives of a float32 image, in grey levels per pixel."""
    return cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3) / 8.0, cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3) / 8.0


def separation_spans(copies_src_canvas: np.ndarray, copies_tgt_canvas: np.ndarray, cfg: Config
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, lo, hi) float64 (M,) of every match whose two copies land apart on the canvas: the row between
    them and the x span a seam must not cross (module ``separation_cost``). copies_*_canvas: (N, 2)
    float64 canvas (x, y) of each match's source copy (warped) and target copy (NaN where undefined).
    Copies closer than ``cfg.seam_separation_min_px`` count as one point; farther than
    ``cfg.seam_separation_max_px``, as a wrong match."""
    copies_src_canvas = np.asarray(copies_src_canvas, np.float64)
    copies_tgt_canvas = np.asarray(copies_tgt_canvas, np.float64)
    apart = np.hypot(*(copies_src_canvas - copies_tgt_canvas).T)
    use = np.isfinite(apart) & (apart > cfg.seam_separation_min_px) & (apart <= cfg.seam_separation_max_px)
    # A seam within a quarter transition (and the smoothing) of a copy mixes it in at a quarter or more: a ghost.
    reach = 0.25 * cfg.transition_px + cfg.seam_smooth_sigma_px
    lo = np.minimum(copies_src_canvas[use, 0], copies_tgt_canvas[use, 0]) - reach
    hi = np.maximum(copies_src_canvas[use, 0], copies_tgt_canvas[use, 0]) + reach
    return 0.5 * (copies_src_canvas[use, 1] + copies_tgt_canvas[use, 1]), lo, hi


def separation_cost(shape: tuple[int, int], copies_src_canvas: np.ndarray, copies_tgt_canvas: np.ndarray,
                    cfg: Config) -> np.ndarray:
    """(H, W) float32: for every match whose two copies land apart on the canvas, a seam between them
    shows the point twice (both copies visible) or not at all, so every x between the copies, and within
    a quarter transition plus the smoothing beyond them, costs ``cfg.seam_separation_weight`` on the rows
    within ``cfg.seam_separation_rows`` of the match (:func:`separation_spans`)."""
    height, width = shape
    mid, lo_x, hi_x = separation_spans(copies_src_canvas, copies_tgt_canvas, cfg)
    lo = np.clip(np.floor(lo_x), 0, width).astype(np.int64)
    hi = np.clip(np.ceil(hi_x), 0, width).astype(np.int64)
    row = np.rint(mid).astype(np.int64)
    edges = np.zeros((height, width + 1), np.float32)
    for dy in range(-cfg.seam_separation_rows, cfg.seam_separation_rows + 1):
        r = row + dy
        ok = (r >= 0) & (r < height) & (hi > lo)
        np.add.at(edges, (r[ok], lo[ok]), cfg.seam_separation_weight)
        np.add.at(edges, (r[ok], hi[ok]), -cfg.seam_separation_weight)
    return np.cumsum(edges, axis=1)[:, :width]


def hidden_structure_cost(grey_src: np.ndarray, grey_tgt: np.ndarray, both: np.ndarray, canvas_width: int,
                          cfg: Config) -> np.ndarray:
    """(H, W) float32, per seam position x in a row: the structure that a seam there would hide.

    Where the views differ strongly (blurred |src - tgt| above ``seam_unique_diff``), the view with
    more edge energy there is taken to show an object the other lacks; a seam at x shows the source
    left of x and the target right of it, so it hides the target's extra structure left of x and the
    source's right of x: prefix and suffix sums along the row, normalised by the canvas's width.
    """
    sigma = cfg.seam_unique_sigma_px

    def energy(grey: np.ndarray) -> np.ndarray:
        gx, gy = _gradient(grey)
        return cv2.GaussianBlur(np.hypot(gx, gy), (0, 0), sigma)

    energy_src, energy_tgt = energy(grey_src), energy(grey_tgt)
    differ = cv2.GaussianBlur(np.abs(grey_src - grey_tgt), (0, 0), sigma)
    strong = np.clip((differ - cfg.seam_unique_diff) / cfg.seam_unique_diff, 0.0, 1.0) * both
    src_only = strong * np.maximum(energy_src - energy_tgt, 0.0)
    tgt_only = strong * np.maximum(energy_tgt - energy_src, 0.0)
    hidden = np.cumsum(tgt_only, axis=1) + np.cumsum(src_only[:, ::-1], axis=1)[:, ::-1]
    return (hidden / np.float32(max(1.0, cfg.seam_unique_norm * canvas_width))).astype(np.float32)


def seam_cost_canvas(warped_src: np.ndarray, placed_tgt: np.ndarray, both: np.ndarray,
                     copies_src_canvas: np.ndarray, copies_tgt_canvas: np.ndarray, cfg: Config) -> np.ndarray:
    """(H, W) float32 cost of the seam passing through each canvas pixel; ``BLOCKED`` outside the overlap.

    warped_src, placed_tgt: (H, W, C) uint8 canvas images, gain-compensated; both: (H, W) bool where
    both are valid; copies_*_canvas: (N, 2) float64 (x, y) canvas positions of every match's source
    and target copy (NaN where undefined), for ``separation_cost``.
    """
    out = np.full(both.shape, BLOCKED, np.float32)
    rows, cols = np.flatnonzero(both.any(axis=1)), np.flatnonzero(both.any(axis=0))
    if not rows.size:
        return out
    # The cost is only read inside the overlap: work on its bounding box, widened by the filters' reach
    # so every value inside is the whole canvas's (the prefix sums gather nothing outside the overlap).
    reach = int(np.ceil(4.0 * cfg.seam_unique_sigma_px)) + 2
    box = (slice(max(rows[0] - reach, 0), rows[-1] + reach + 1), slice(max(cols[0] - reach, 0), cols[-1] + reach + 1))
    src_box, tgt_box, both_box = warped_src[box], placed_tgt[box], both[box]
    colour = np.abs(src_box.astype(np.float32) - tgt_box.astype(np.float32)).reshape(*both_box.shape, -1).mean(axis=2)
    grey_src, grey_tgt = _grey(src_box).astype(np.float32), _grey(tgt_box).astype(np.float32)
    sx, sy = _gradient(grey_src)
    tx, ty = _gradient(grey_tgt)
    cost = colour + cfg.seam_gradient_weight * np.hypot(sx - tx, sy - ty)
    cost += cfg.seam_edge_weight * np.maximum(np.hypot(sx, sy), np.hypot(tx, ty))
    if cfg.seam_separation_weight > 0:
        cost += separation_cost(both.shape, copies_src_canvas, copies_tgt_canvas, cfg)[box]
    if cfg.seam_unique_weight > 0:
        cost += cfg.seam_unique_weight * hidden_structure_cost(grey_src, grey_tgt, both_box, both.shape[1], cfg)
    out[box] = np.where(both_box, cost, BLOCKED)
    return out


class BandPath:
    """The DP of ``kernels/seam_path.py`` for a band of fixed shape and fixed ``segments`` (S, 4) (see
    :func:`dp_segments`), its arrays allocated and its segments set once (a video solves the same band
    every frame), on the host (Warp's CPU device, :data:`~sena_warp.kernels.seam_path.DEVICE`) with
    ``threads`` launch threads: a path is one sequential walk per segment, work for a CPU thread."""

    def __init__(self, rows: int, width: int, segments: np.ndarray, threads: int):
        self.threads = threads
        self.shape = (rows, width)
        segments = np.asarray(segments, np.int32).reshape(-1, 4)
        self.segments = [host_array(np.ascontiguousarray(segments[:, k]), int) for k in range(4)]
        self.band_x0 = np.zeros(rows, np.int32)
        self.acc = wp.zeros((len(segments), 2, width), dtype=float, device=DEVICE)
        self.back = wp.zeros((rows, width), dtype=wp.int8, device=DEVICE)
        self.path = np.zeros(rows, np.int32)
        self._arrays = [host_array(self.band_x0, int), host_array(self.path, int)]

    def solve(self, cost_band: wp.array, band_x0: np.ndarray, max_step: int, step_cost: float) -> np.ndarray:
        """See :func:`dp_segments`; ``cost_band``: a (rows, width) float Warp array on the CPU device.
        The path returned is this solver's own array, overwritten by the next solve."""
        np.copyto(self.band_x0, band_x0, casting="unsafe")
        x0, path = self._arrays
        inputs = [cost_band, x0, *self.segments, int(max_step), float(step_cost), self.acc, self.back, path]
        runtime.launch_rows(seam_dp_kernel, self.acc.shape[0], 1, inputs, DEVICE, self.threads)
        return self.path


def dp_segments(cost_band: np.ndarray, band_x0: np.ndarray, segments: np.ndarray, max_step: int, step_cost: float,
                cfg: Config) -> np.ndarray:
    """Minimum-cost paths through a band of rows, one per segment (Warp kernel ``seam_dp_kernel``).

    cost_band: (R, B) float32, column j of band row r is canvas x = band_x0[r] + j; band_x0: (R,) int.
    segments: (S, 4) int (first row, last row, start x or -1 = free, end x or -1 = free); segments may
    share their end rows. Returns (R,) int32 canvas x of the path per band row. Runs on the host with
    ``cfg.cpu_threads``.
    """
    rows, width = cost_band.shape
    cost = host_array(np.ascontiguousarray(cost_band, np.float32), float)
    return BandPath(rows, width, segments, cfg.cpu_threads).solve(cost, band_x0, max_step, step_cost).copy()


def overlap_rows(both: np.ndarray) -> tuple[int, int]:
    """(first, last) rows holding an overlap pixel; GeometryError if there is none."""
    rows = np.flatnonzero(both.any(axis=1))
    if rows.size == 0:
        raise GeometryError("the warped views do not overlap on the canvas: no seam can be cut")
    return int(rows[0]), int(rows[-1])


def coarse_path(cost: np.ndarray, both: np.ndarray, x_range: tuple[float, float], cfg: Config
                ) -> tuple[np.ndarray, tuple[int, int]]:
    """The seam on a reduced canvas inside ``x_range`` (canvas x), as x per full-resolution row.

    Returns ((H,) float64 seam x, (first, last) full-resolution rows of the overlap it spans).
    """
    height, width = cost.shape
    factor = reduction_factor(cost.shape, cfg)
    x0, x1 = int(np.clip(np.floor(x_range[0]), 0, width)), int(np.clip(np.ceil(x_range[1]), 0, width))
    inside = np.zeros_like(both)
    inside[:, x0:x1] = both[:, x0:x1]
    small_shape = (max(1, height // factor), max(1, width // factor))
    small = cv2.resize(np.where(inside, cost, BLOCKED), small_shape[::-1], interpolation=cv2.INTER_AREA)
    small_both = cv2.resize(inside.astype(np.float32), small_shape[::-1], interpolation=cv2.INTER_AREA) > 0.5
    if not small_both.any():
        small_both = cv2.resize(both.astype(np.float32), small_shape[::-1], interpolation=cv2.INTER_AREA) > 0.5
    first, last = overlap_rows(small_both)
    path = dp_segments(small[first:last + 1], np.zeros(last - first + 1, np.int32),
                       np.array([[0, last - first, -1, -1]]), cfg.seam_max_step_px, cfg.seam_step_cost * factor, cfg)
    rows_full = (np.arange(first, last + 1) + 0.5) * factor - 0.5
    x_full = (path + 0.5) * factor - 0.5
    span = (int(np.ceil(rows_full[0])), int(np.floor(rows_full[-1])))
    first_full, last_full = overlap_rows(both)
    span = (max(span[0], first_full), min(span[1], last_full))
    return np.interp(np.arange(height), rows_full, x_full), span


def reduction_factor(shape: tuple[int, int], cfg: Config) -> int:
    """Integer factor that brings the canvas's long side to at most ``cfg.seam_coarse_px``."""
    return max(1, int(np.ceil(max(shape) / cfg.seam_coarse_px)))


def anchors_on_path(cand_src_canvas: np.ndarray, cand_tgt_canvas: np.ndarray, seam_x: np.ndarray, rows: tuple[int, int],
                    max_distance_px: float, cfg: Config) -> np.ndarray:
    """Indices of the candidates that become anchors, top to bottom.

    A candidate qualifies when its target copy lies within ``max_distance_px`` of the path and
    strictly inside ``rows``; walking down, a candidate is kept when it is at least
    ``cfg.seam_anchor_spacing_px`` below the last kept one in the target, lower in the source too,
    moves the same way in x in both (the paper's directional validation), and no more sideways than
    the path may step (``cfg.seam_max_step_px`` per row): a chain never steps across an object.
    """
    cand_src_canvas = np.asarray(cand_src_canvas, np.float64)
    cand_tgt_canvas = np.asarray(cand_tgt_canvas, np.float64)
    y = cand_tgt_canvas[:, 1]
    rows_index = np.clip(np.rint(y).astype(np.int64), 0, len(seam_x) - 1)
    near = (np.abs(cand_tgt_canvas[:, 0] - seam_x[rows_index]) <= max_distance_px) & (y > rows[0]) & (y < rows[1])
    near &= np.isfinite(cand_src_canvas).all(axis=1)
    order = np.flatnonzero(near)[np.argsort(y[near], kind="stable")]
    kept: list[int] = []
    for i in order:
        if kept:
            step_src = cand_src_canvas[i] - cand_src_canvas[kept[-1]]
            step_tgt = cand_tgt_canvas[i] - cand_tgt_canvas[kept[-1]]
            if (step_tgt[1] < cfg.seam_anchor_spacing_px or step_src[1] <= 0 or step_src[0] * step_tgt[0] < 0
                    or abs(step_tgt[0]) + 1.0 > cfg.seam_max_step_px * (step_tgt[1] - 1.0)):
                continue
        kept.append(int(i))
    return np.array(kept, np.int64)


def refine_path(cost: np.ndarray, coarse_x: np.ndarray, rows: tuple[int, int], anchors_tgt_canvas: np.ndarray,
                band_px: int, cfg: Config) -> np.ndarray:
    """The full-resolution seam within ``band_px`` of the coarse path, through the anchors: (H,) float32.

    Segments run from the first overlap row to the first anchor, between anchors, and from the last
    anchor to the last row; rows outside ``rows`` keep the nearest optimised x.
    """
    height, width = cost.shape
    first, last = rows
    band_rows = np.arange(first, last + 1)
    band_x0 = np.rint(coarse_x[band_rows]).astype(np.int32) - band_px
    cols = band_x0[:, None] + np.arange(2 * band_px + 1)[None, :]
    cost_band = np.where((cols >= 0) & (cols < width), cost[band_rows[:, None], np.clip(cols, 0, width - 1)], BLOCKED)
    knots = [(first, -1)] + [(int(round(y)), int(round(x))) for x, y in anchors_tgt_canvas] + [(last, -1)]
    segments = [(ya - first, yb - first, xa, xb) for (ya, xa), (yb, xb) in zip(knots[:-1], knots[1:]) if yb > ya]
    path = dp_segments(cost_band, band_x0, np.array(segments), cfg.seam_max_step_px, cfg.seam_step_cost, cfg)
    seam = np.empty(height, np.float32)
    seam[first:last + 1] = path
    seam[:first] = path[0]
    seam[last + 1:] = path[-1]
    return seam


def straight_path(anchors_src_canvas: np.ndarray, anchors_tgt_canvas: np.ndarray, height: int) -> SeamPath:
    """The paper's seam: straight between consecutive target anchors (sorted by y, edge anchors
    included), constant beyond the first and last."""
    rows = np.arange(height, dtype=np.float64)
    seam = np.interp(rows, anchors_tgt_canvas[:, 1], anchors_tgt_canvas[:, 0]).astype(np.float32)
    span = (int(np.ceil(anchors_tgt_canvas[0, 1])), int(np.floor(anchors_tgt_canvas[-1, 1])))
    return SeamPath(seam, span, seam, np.asarray(anchors_src_canvas, np.float64), np.asarray(anchors_tgt_canvas, np.float64))


def seam_line(zone: Zone, views: CanvasViews, pts_src_canvas: np.ndarray, pts_tgt_canvas: np.ndarray,
              copies_src_canvas: np.ndarray, copies_tgt_canvas: np.ndarray, cfg: Config,
              prior_x_canvas: np.ndarray | None = None) -> SeamPath:
    """Steps 8-9's seam of ``cfg.seam_model``: "path" (the module docstring) or "paper" (the keypoint
    chain of ``chain.py`` joined by straight lines).

    views: the gain-compensated canvas views; pts_*_canvas: (N, 2) float64 canvas (x, y) of the
    matches the warp follows (source copies warped by the step-6 map, target copies placed), the
    arrays ``zone`` indexes; copies_*_canvas: the same for every match (``separation_cost``).
    prior_x_canvas: (H,) float64 a seam to stay near (a video's current one; NaN rows: none), each
    pixel away from it costing ``cfg.seam_prior_weight``.
    """
    grey_src, grey_tgt = views.grey()
    if cfg.seam_model == "paper":
        anchors_src, anchors_tgt = keypoint_chain(zone, pts_src_canvas, pts_tgt_canvas, grey_src, grey_tgt, views.both, cfg)
        return straight_path(anchors_src, anchors_tgt, views.both.shape[0])
    if cfg.seam_model != "path":
        raise InputError(f"unknown seam model {cfg.seam_model!r}; choose path or paper")
    zone_pts = zone.point_indices
    candidates = zone_pts[brightness_consistent(grey_src, grey_tgt, pts_src_canvas[zone_pts], pts_tgt_canvas[zone_pts], cfg)]
    cost = seam_cost_canvas(views.src, views.tgt, views.both, copies_src_canvas, copies_tgt_canvas, cfg)
    if prior_x_canvas is not None:
        away = np.abs(np.arange(cost.shape[1])[None, :] - np.asarray(prior_x_canvas, np.float64)[:, None])
        cost = np.where(views.both, cost + cfg.seam_prior_weight * np.nan_to_num(away), cost).astype(np.float32)
    margin = cfg.seam_zone_margin * (zone.x1 - zone.x0)
    coarse, rows = coarse_path(cost, views.both, (zone.x0 - margin, zone.x1 + margin), cfg)
    factor = reduction_factor(cost.shape, cfg)
    kept = candidates[anchors_on_path(pts_src_canvas[candidates], pts_tgt_canvas[candidates], coarse, rows,
                                      cfg.seam_anchor_px * factor, cfg)]
    anchors_src, anchors_tgt = pts_src_canvas[kept], pts_tgt_canvas[kept]
    seam = refine_path(cost, coarse, rows, anchors_tgt, 2 * factor + cfg.seam_refine_px, cfg)
    return SeamPath(seam, rows, coarse.astype(np.float32), anchors_src, anchors_tgt)
