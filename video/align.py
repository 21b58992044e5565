"""A moving rig's alignment, every frame: where the warped source shows the target's corners, and the warp
corrected to that on a lattice, filtered over time.

A moving rig's two views keep their geometry only roughly: parallax changes as the rig passes near
things, two hand-held phones drift apart, and an estimate a second old no longer fits. So the source
map of every frame is the last full estimate's (the *key* map, ``M_key``) plus a smooth correction
``C`` on a coarse lattice over the canvas (``video_align_lattice_nodes``, upsampled bicubically as the
estimate's own field is, ``ffd.field_from_lattice``). The planes are seen :func:`reduction` times
smaller (area average: 1 up to 540 rows, 2 at 720p).

1. *Points* (:class:`TargetPoints`): up to ``video_align_points`` corners of the target's Y plane where
   both views overlap (:class:`OverlapGrid`), tracked from frame to frame (pyramidal Lucas-Kanade) and
   topped up with new corners when fewer than ``video_align_min_share`` of them remain (they leave the
   overlap as the rig turns). A track that slips only moves a point: what it is measured against is
   found anew every frame (step 2).
2. *Residual* (:func:`residual_flow`): the overlap's box as the current map warps the source there,
   against the target on the same box, both with the frame's gains: Lucas-Kanade from the target to
   the warped source at each point, kept where the backward run returns, gives how far off the warp is
   there (canvas px); the source pixel the point should show is the current map at the point plus
   that flow.
3. *Fit* (:class:`CorrectionFit`): the lattice least squares of ``ffd.fit_lattice`` (the same bicubic
   taps and thin-plate bending energy, at ``video_align_bend``; Tukey weights at ``video_align_tukey_px``), warm-started from
   the filter's prediction: the points it leaves far off start down-weighted, and a pull of
   ``video_align_prior`` towards it keeps nodes without points where they were; one reweighting.
4. *Filter* (:class:`LagBoundedFilter`): each node's value follows the fits by an alpha-beta filter
   (``video_align_follow``: the share of a measured change taken at once; its velocity term follows a
   steady drift without lag) and never lags a fit by more than ``video_align_max_lag_px``.

Where the fit cannot follow a point (something near whose parallax differs from its surroundings'),
its two copies are apart on the canvas: :func:`copies_apart` gives both positions, for the per-frame
seam to keep them on one side.
Coordinates: the canvas is the output (input frame, ``x`` right, ``y`` down); maps hold source (x, y)
input px per canvas pixel; the target sits at ``canvas = target + o`` (``maps.target_offset``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from ..canvas import Canvas
from ..config import Config
from ..ffd import LatticeTerms, bending_regulariser, lattice_shape, tukey_weights
from .maps import sampled_mask

LK_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 10, 0.01)
TRACK_LEVELS = 2  # pyramid levels of the frame-to-frame track in the target
FLOW_LEVELS = 2  # ... and of the residual flow (the warp is off by a few px at most)
RETURN_PX = 0.5  # a flow counts where its backward run returns within this (small px)
CORNER_QUALITY = 0.01  # corners: at least this x the strongest one's response
BORDER_PX = 8  # corners keep this far inside the overlap (small px: their window must lie in both views)
CROP_MARGIN_PX = 4  # a corner search reads this far past its mask (its gradients and their 3 x 3 sums: 2 px)
OVERLAP_FRAMES = 10  # where the views overlap is found anew every this many frames (it moves slowly)
SEED_FRAMES = 5  # corners are topped up at most every this many frames (a search costs as much as a track)


def reduction(shapes: tuple[tuple[int, int], ...], cfg: Config) -> int:
    """How many times smaller the alignment sees Y planes of (rows, cols) ``shapes``: their short side
    near ``video_align_short_px``."""
    short = min(min(shape) for shape in shapes)
    return max(1, int(round(short / max(1, cfg.video_align_short_px))))


def small_plane(y: np.ndarray, factor: int) -> np.ndarray:
    """A Y plane ``factor`` times smaller (area average: small pixel j is the mean of full pixels
    ``factor j .. factor j + factor - 1``, so it sits at full ``factor j + (factor - 1) / 2``)."""
    if factor == 1:
        return y
    return cv2.resize(y, (y.shape[1] // factor, y.shape[0] // factor), interpolation=cv2.INTER_AREA)


def small_to_full(pts_small: np.ndarray, factor: int) -> np.ndarray:
    """Full-plane (x, y) of small-plane points (:func:`small_plane`), float64."""
    return np.asarray(pts_small, np.float64) * factor + 0.5 * (factor - 1)


def sample_map(map_canvas: np.ndarray, pts_canvas: np.ndarray) -> np.ndarray:
    """The map (Hc, Wc, 2) at canvas points (N, 2) or on a grid (H, W, 2) of them (bilinear; NaN outside
    the canvas or where the map is NaN), float64 of the points' shape."""
    pts = np.asarray(pts_canvas, np.float32)
    if not pts.size:  # no points (a frame whose tracks all failed): OpenCV takes no empty grid
        return np.zeros(pts.shape)
    grid = pts.reshape(-1, 1, 2) if pts.ndim < 3 else pts
    sampled = cv2.remap(map_canvas, np.ascontiguousarray(grid[..., 0]), np.ascontiguousarray(grid[..., 1]),
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan, np.nan))
    return sampled.reshape(pts.shape).astype(np.float64)


class OverlapGrid:
    """Where the small target plane (:func:`small_plane`) overlaps the source under a map.

    ``mask`` (small rows, cols) uint8: 255 where the map takes the pixel into the source, at least
    :data:`BORDER_PX` from where it does not; ``box`` (x0, y0, x1, y1) the overlap's bounding box in
    small target px (x1 <= x0: none), within the canvas. ``map_canvas`` (Hc, Wc, 2) the source map,
    ``offset_tgt`` the target's canvas offset (whole px), ``shape_src`` (rows, cols) of the full source
    plane, ``factor`` the reduction."""

    def __init__(self, map_canvas: np.ndarray, offset_tgt: np.ndarray, shape_src: tuple[int, int],
                 shape_tgt_small: tuple[int, int], factor: int):
        self.factor = factor
        self.offset = tuple(int(round(v)) for v in offset_tgt)
        rows, cols = shape_tgt_small
        mapped = np.full((rows, cols, 2), np.nan, np.float32)
        x0, y0, x1, y1 = self._on_canvas((0, 0, cols, rows), map_canvas.shape[:2])
        if x1 > x0 and y1 > y0:
            mapped[y0:y1, x0:x1] = self.small_map(map_canvas, (x0, y0, x1, y1))
        inside = sampled_mask(small_to_full(mapped, factor), shape_src)
        self.mask = cv2.erode(np.where(inside, 255, 0).astype(np.uint8), np.ones((2 * BORDER_PX + 1,) * 2, np.uint8))
        found_rows, found_cols = np.flatnonzero(inside.any(axis=1)), np.flatnonzero(inside.any(axis=0))
        self.box = (0, 0, 0, 0) if not found_rows.size else (
            int(found_cols[0]), int(found_rows[0]), int(found_cols[-1]) + 1, int(found_rows[-1]) + 1)

    @property
    def empty(self) -> bool:
        return self.box[2] <= self.box[0]

    def _on_canvas(self, box: tuple[int, int, int, int], canvas_shape: tuple[int, int]) -> tuple[int, int, int, int]:
        """A small target ``box`` clipped to the small pixels whose blocks lie on a canvas of ``canvas_shape``."""
        f, (ox, oy) = self.factor, self.offset
        x0, y0, x1, y1 = box
        return (max(x0, -(ox // f) if ox < 0 else x0), max(y0, -(oy // f) if oy < 0 else y0),
                min(x1, (canvas_shape[1] - ox) // f), min(y1, (canvas_shape[0] - oy) // f))

    def small_map(self, map_canvas: np.ndarray, box: tuple[int, int, int, int] | None = None) -> np.ndarray:
        """The map (Hc, Wc, 2) over a small target ``box`` (default: the overlap's), in *small* source px:
        each small pixel's f x f block of canvas px averaged (the map at the block's centre), float32."""
        f, (ox, oy) = self.factor, self.offset
        x0, y0, x1, y1 = self.box if box is None else box
        block = map_canvas[oy + f * y0:oy + f * y1, ox + f * x0:ox + f * x1]
        if f == 1:
            return block
        mean = cv2.resize(block, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
        return ((mean - 0.5 * (f - 1)) / f).astype(np.float32)


def lucas_kanade(before: np.ndarray, after: np.ndarray, pts: np.ndarray, window_px: int, levels: int,
                 both_ways: bool) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) float32 of ``before`` tracked into ``after`` (uint8 images): (where, kept (N,) bool),
    kept where found, and with ``both_ways`` where the backward track returns within :data:`RETURN_PX`."""
    if not len(pts):
        return np.zeros((0, 2), np.float32), np.zeros(0, bool)
    window = (window_px, window_px)
    start = np.ascontiguousarray(pts, np.float32).reshape(-1, 1, 2)
    moved, found, _ = cv2.calcOpticalFlowPyrLK(before, after, start, None, winSize=window, maxLevel=levels,
                                               criteria=LK_CRITERIA)
    kept = found[:, 0] == 1
    if both_ways:
        back, returned, _ = cv2.calcOpticalFlowPyrLK(after, before, moved, None, winSize=window, maxLevel=levels,
                                                     criteria=LK_CRITERIA)
        kept &= (returned[:, 0] == 1) & (np.hypot(*(back - start).reshape(-1, 2).T) <= RETURN_PX)
    return moved.reshape(-1, 2), kept


class TargetPoints:
    """The target's corners in the overlap, tracked from frame to frame (module docstring, step 1), in the
    small target plane. ``pts`` (N, 2) float32 (x, y) of the points now; ``seeded``: how many corners
    the last :meth:`update` added."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.pts = np.zeros((0, 2), np.float32)
        self.seeded = 0
        self._last: np.ndarray | None = None
        self._since_seed = SEED_FRAMES

    def update(self, tgt_small: np.ndarray, mask: np.ndarray, near: Callable[[], np.ndarray] | None = None
               ) -> np.ndarray:
        """The points on the small target plane ``tgt_small`` (h, w) uint8: the last frame's tracked, those
        outside ``mask`` (h, w) uint8 (255: the overlap) dropped, topped up when too few remain (at most
        every :data:`SEED_FRAMES` frames, unless fewer than ``video_align_min_points`` are left): half of
        them within ``near()`` (h, w) uint8 (255: by the seam; asked for only then) where given, the rest
        anywhere."""
        cfg = self.cfg
        pts = self.pts
        if self._last is not None and len(pts):
            pts, kept = lucas_kanade(self._last, tgt_small, pts, cfg.video_align_window_px, TRACK_LEVELS, False)
            pts = pts[kept]
        cols, rows = np.rint(pts).astype(np.int64).T
        on = (rows >= 0) & (cols >= 0) & (rows < mask.shape[0]) & (cols < mask.shape[1])
        on[on] = mask[rows[on], cols[on]] > 0
        pts = pts[on]
        self.seeded = 0
        self._since_seed += 1
        thin = len(pts) < cfg.video_align_min_share * cfg.video_align_points
        if thin and (self._since_seed >= SEED_FRAMES or len(pts) < cfg.video_align_min_points):
            before, wanted = len(pts), cfg.video_align_points - len(pts)
            if near is not None:
                by_seam = self._corners(tgt_small, cv2.bitwise_and(mask, near()), pts, wanted // 2)
                pts = np.concatenate([pts, by_seam])
            pts = np.concatenate([pts, self._corners(tgt_small, mask, pts, cfg.video_align_points - len(pts))])
            self.seeded, self._since_seed = len(pts) - before, 0
        self.pts = pts.astype(np.float32)
        self._last = tgt_small
        return self.pts

    def keep(self, kept: np.ndarray) -> None:
        """Keep only the points ``kept`` (N,) bool marks (the others are not tracked on)."""
        self.pts = self.pts[kept]

    def _corners(self, tgt_small: np.ndarray, mask: np.ndarray, existing: np.ndarray, count: int) -> np.ndarray:
        """Up to ``count`` new corners in ``mask``, :func:`spacing` away from the ``existing`` points."""
        gap = spacing(mask, self.cfg.video_align_points)
        free = mask.copy()
        for x, y in np.rint(existing).astype(int):
            cv2.circle(free, (int(x), int(y)), gap, 0, -1)
        return corners_in(tgt_small, free, count, gap)


def corners_in(plane: np.ndarray, mask: np.ndarray, count: int, gap: int) -> np.ndarray:
    """Up to ``count`` Shi-Tomasi corners (N, 2) float32 of ``plane`` (h, w) uint8 within ``mask`` (255),
    ``gap`` px apart: OpenCV's search on the mask's bounding box and :data:`CROP_MARGIN_PX` around it
    only (the corner response of a pixel reads its 3 x 3 neighbours' gradients; the corners are the whole
    plane's, found in a third of the time where the mask is the strip by the seam)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not rows.size or count < 1:
        return np.zeros((0, 2), np.float32)
    y0, y1 = max(0, rows[0] - CROP_MARGIN_PX), min(plane.shape[0], rows[-1] + 1 + CROP_MARGIN_PX)
    x0, x1 = max(0, cols[0] - CROP_MARGIN_PX), min(plane.shape[1], cols[-1] + 1 + CROP_MARGIN_PX)
    found = cv2.goodFeaturesToTrack(np.ascontiguousarray(plane[y0:y1, x0:x1]), count, CORNER_QUALITY, gap,
                                    mask=np.ascontiguousarray(mask[y0:y1, x0:x1]))
    if found is None:
        return np.zeros((0, 2), np.float32)
    return (found.reshape(-1, 2) + np.float32([x0, y0])).astype(np.float32)


def spacing(mask: np.ndarray, count: int) -> int:
    """Corner spacing (px) that lets ``count`` corners spread over the mask's area, at least 4 px."""
    area = float(np.count_nonzero(mask))
    return max(4, int(0.5 * np.sqrt(area / max(count, 1))))


def gained(y: np.ndarray, gain: float, bias: float) -> np.ndarray:
    """``gain * y + bias``, rounded into uint8: a view as it enters the output (its affine gains)."""
    return cv2.convertScaleAbs(y, alpha=float(gain), beta=float(bias))


def residual_flow(src_small: np.ndarray, tgt_small: np.ndarray, map_canvas: np.ndarray, overlap: OverlapGrid,
                  pts_small: np.ndarray, gains: tuple[float, float, float, float], factor: int,
                  window_px: int) -> tuple[np.ndarray, np.ndarray]:
    """How far the warp ``map_canvas`` is off at target points (module docstring, step 2): (flow (N, 2)
    canvas px, kept (N,) bool); the target's content at a point's canvas position ``u`` shows in the
    warped source at ``u + flow``. ``src_small``, ``tgt_small``: the Y planes ``factor`` times smaller
    (:func:`small_plane`), ``pts_small`` (N, 2) the points in the small target plane, ``overlap`` their
    :class:`OverlapGrid`; ``gains``: (gain, bias) of the source and of the target luma as the compositor
    applies them; ``window_px``: the Lucas-Kanade window."""
    x0, y0, x1, y1 = overlap.box
    gain_src, bias_src, gain_tgt, bias_tgt = gains
    positions = np.ascontiguousarray(overlap.small_map(map_canvas))
    warped = cv2.remap(src_small, positions[..., 0], positions[..., 1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT)
    src = gained(warped, gain_src, bias_src)
    tgt = gained(np.ascontiguousarray(tgt_small[y0:y1, x0:x1]), gain_tgt, bias_tgt)
    in_box = np.asarray(pts_small, np.float32) - np.float32([x0, y0])
    moved, kept = lucas_kanade(tgt, src, in_box, window_px, FLOW_LEVELS, True)
    return (moved - in_box).astype(np.float64) * factor, kept


class CorrectionFit:
    """The correction lattice's warm-started least squares over a canvas (module docstring, step 3).

    ``shape``: (Ny, Nx) nodes (``ffd.lattice_shape`` at ``video_align_lattice_nodes``); ``lattice``
    (Ny, Nx, 2) float64 the last fit (zeros before the first); ``weights`` (N,) the last fit's Tukey
    weights of its points (None before the first)."""

    def __init__(self, canvas_shape: tuple[int, int], cfg: Config):
        self.cfg = cfg
        height, width = canvas_shape
        self.canvas = Canvas(width, height, (0.0, 0.0))
        diag_px = float(np.hypot(width, height))
        self.shape = lattice_shape(self.canvas, diag_px, cfg.replace(lattice_nodes=cfg.video_align_lattice_nodes))
        nodes = self.shape[0] * self.shape[1]
        self._regulariser = (bending_regulariser(self.canvas, self.shape, diag_px, cfg.video_align_bend)
                             + cfg.video_align_prior * np.eye(nodes))
        self.lattice = np.zeros((*self.shape, 2))
        self.weights: np.ndarray | None = None

    def fit(self, pts_canvas: np.ndarray, residual_src: np.ndarray, prior: np.ndarray,
            importance: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lattice fitted to residuals (N, 2) (source px the map must move by) at canvas points (N, 2),
        warm-started from and pulled towards ``prior`` (Ny, Nx, 2): the points start with Tukey weights
        of how far the prior leaves them, at twice the scale. ``importance`` (N,): each point's weight
        beside its Tukey weight (ones by default). Two solves, the second reweighted. Returns (lattice
        (Ny, Nx, 2) float64, |fit - residual| (N,), Tukey weights (N,)); ``lattice`` and ``weights`` keep
        them."""
        cfg = self.cfg
        terms = LatticeTerms(pts_canvas, self.canvas, self.shape)
        prior_flat = np.asarray(prior, np.float64).reshape(-1, 2)
        importance = np.ones(len(pts_canvas)) if importance is None else np.asarray(importance, np.float64)
        error = np.hypot(*(terms.values(prior_flat) - residual_src).T)
        weights = tukey_weights(error, 2.0 * cfg.video_align_tukey_px)
        solution = prior_flat
        for _ in range(2):
            w = weights * importance
            w = w / max(w.sum(), 1e-12)
            normal, rhs = terms.normal(w, residual_src)
            ok, solution = cv2.solve(normal + self._regulariser, rhs + self.cfg.video_align_prior * prior_flat,
                                     flags=cv2.DECOMP_CHOLESKY)
            if not ok:
                solution = prior_flat
                break
            error = np.hypot(*(terms.values(solution) - residual_src).T)
            weights = tukey_weights(error, cfg.video_align_tukey_px)
            if weights.sum() <= 0:
                break
        self.lattice = solution.reshape(*self.shape, 2)
        self.weights = weights
        return self.lattice, error, weights


class LagBoundedFilter:
    """An alpha-beta filter on an array (module docstring, step 4): ``follow`` (alpha) of each innovation
    taken into the value, ``follow**2 / (2 - follow)`` (beta, critically damped) into its velocity; the
    value never more than ``max_lag`` from the last measurement. Causal: a value depends on the
    measurements until now only."""

    def __init__(self, follow: float, max_lag: float):
        self.alpha = float(follow)
        self.beta = self.alpha**2 / (2.0 - self.alpha)
        self.max_lag = float(max_lag)
        self.value: np.ndarray | None = None
        self._velocity: np.ndarray | None = None

    def predict(self) -> np.ndarray | None:
        """The value expected at the next measurement (None before the first)."""
        return None if self.value is None else self.value + self._velocity

    def update(self, measured: np.ndarray) -> np.ndarray:
        measured = np.asarray(measured, np.float64)
        if self.value is None:
            self.value, self._velocity = measured.copy(), np.zeros_like(measured)
            return self.value
        predicted = self.predict()
        innovation = measured - predicted
        value = predicted + self.alpha * innovation
        self._velocity = self._velocity + self.beta * innovation
        self.value = np.clip(value, measured - self.max_lag, measured + self.max_lag)
        return self.value

    def reset(self, value: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Hold ``value`` from now on, at rest (a new key map's correction) or moving by ``velocity`` a
        measurement."""
        self.value = np.asarray(value, np.float64).copy()
        self._velocity = np.zeros_like(self.value) if velocity is None else np.asarray(velocity, np.float64).copy()


@dataclass(frozen=True)
class Alignment:
    """One frame's alignment: ``lattice`` (Ny, Nx, 2) float64 the correction (source px) to add to the key
    map; ``pts_canvas`` (N, 2) where the points were measured and ``targets_src`` (N, 2) the source
    positions they should show (both NaN-free); ``weights`` (N,) their Tukey weights in the fit (0: the
    warp does not follow them); ``error_px`` (N,) how far the fit leaves each (source px); ``seeded``:
    corners added this frame."""

    lattice: np.ndarray
    pts_canvas: np.ndarray
    targets_src: np.ndarray
    weights: np.ndarray
    error_px: np.ndarray
    seeded: int

    @property
    def inlier_share(self) -> float:
        return float((self.weights > 0).mean()) if self.weights.size else 0.0


@dataclass(frozen=True)
class Seam:
    """A frame's seam on the canvas: ``positions`` (L,) one per line, lines rows (x positions) when
    ``lines_are_rows``, else columns (y positions)."""

    positions: np.ndarray
    lines_are_rows: bool

    def distance(self, pts_canvas: np.ndarray) -> np.ndarray:
        """(N,) |position - seam| of canvas points (N, 2) (x, y) along their lines; inf off the lines."""
        pts = np.asarray(pts_canvas, np.float64)
        line, position = (pts[:, 1], pts[:, 0]) if self.lines_are_rows else (pts[:, 0], pts[:, 1])
        index = np.rint(line).astype(np.int64)
        on = (index >= 0) & (index < len(self.positions))
        out = np.full(len(pts), np.inf)
        out[on] = np.abs(position[on] - self.positions[index[on]])
        return out

    def mask_small(self, shape_small: tuple[int, int], offset_tgt: np.ndarray, factor: int, half_px: float) -> np.ndarray:
        """(h, w) uint8 over the small target plane (:func:`small_plane`, at canvas ``offset_tgt``): 255
        within ``half_px`` canvas px of the seam."""
        rows, cols = shape_small
        xs = small_to_full(np.arange(cols), factor) + offset_tgt[0]
        ys = small_to_full(np.arange(rows), factor) + offset_tgt[1]
        lines, along = (ys, xs) if self.lines_are_rows else (xs, ys)
        index = np.rint(lines).astype(np.int64)
        on = (index >= 0) & (index < len(self.positions))
        near = np.zeros((len(lines), len(along)), bool)
        near[on] = np.abs(along[None, :] - self.positions[index[on]][:, None].astype(np.float64)) <= half_px
        return np.where(near if self.lines_are_rows else near.T, 255, 0).astype(np.uint8)


class FrameAlignment:
    """Per-frame alignment of a moving rig's source map to the target (module docstring).

    ``key_map`` (Hc, Wc, 2) float32: the source map of the last full estimate on the fixed canvas;
    ``offset_tgt`` (x, y) whole px: the target's canvas offset; ``shapes``: (rows, cols) of the source's
    and the target's Y planes. :meth:`step` aligns a frame pair; ``map_src`` is then the map to
    composite it with. Where the views overlap is found anew every :data:`OVERLAP_FRAMES` frames.
    """

    def __init__(self, key_map: np.ndarray, offset_tgt: np.ndarray, shapes: tuple[tuple[int, int], tuple[int, int]],
                 cfg: Config):
        self.cfg = cfg
        self.key_map = key_map
        self.offset_tgt = np.asarray(offset_tgt, np.float64)
        self.shapes = shapes
        self.factor = reduction(shapes, cfg)
        self.points = TargetPoints(cfg)
        self.fit = CorrectionFit(key_map.shape[:2], cfg)
        self.filter = LagBoundedFilter(cfg.video_align_follow, cfg.video_align_max_lag_px)
        self.filter.reset(np.zeros((*self.fit.shape, 2)))
        self.map_src = key_map
        self._overlap: OverlapGrid | None = None
        self._frames = 0

    def correction_field(self, lattice: np.ndarray, shape: tuple[int, int] | None = None) -> np.ndarray:
        """(H, W, 2) float32 the correction (source px) over the canvas (``ffd.field_from_lattice``), or
        resampled onto a grid of ``shape`` (H, W) spanning the canvas as well."""
        height, width = shape or self.key_map.shape[:2]
        return cv2.resize(np.asarray(lattice, np.float32), (width, height), interpolation=cv2.INTER_CUBIC)

    def step(self, y_src: np.ndarray, y_tgt: np.ndarray, gains: tuple[float, float, float, float],
             seam: Seam | None = None) -> Alignment:
        """Align the frame pair ``y_src``, ``y_tgt`` (full Y planes) whose luma ``gains`` are (gain, bias) of
        the source and of the target. The flow is measured against the last frame's map (any map serves:
        the source pixel a point should show is the map plus its flow); the fit starts from the filter's
        prediction. ``seam``: where the last frame's seam ran: half the new corners are sought within
        ``video_align_seam_px`` of it, and the points there weigh ``video_align_seam_weight`` times as
        much in the fit (alignment shows at the seam only)."""
        cfg, factor = self.cfg, self.factor
        src_small, tgt_small = small_plane(y_src, factor), small_plane(y_tgt, factor)
        if self._overlap is None or self._frames % OVERLAP_FRAMES == 0:
            self._overlap = OverlapGrid(self.map_src, self.offset_tgt, self.shapes[0], tgt_small.shape, factor)
        self._frames += 1
        near = None if seam is None else (
            lambda: seam.mask_small(tgt_small.shape, self.offset_tgt, factor, cfg.video_align_seam_px))
        pts_small = self.points.update(tgt_small, self._overlap.mask, near)
        prior = self.filter.predict()
        current = self.map_src
        if self._overlap.empty or not len(pts_small):
            flow, kept = np.zeros((len(pts_small), 2)), np.zeros(len(pts_small), bool)
        else:
            flow, kept = residual_flow(src_small, tgt_small, current, self._overlap, pts_small, gains, factor,
                                       cfg.video_align_window_px)
        self.points.keep(kept)  # a point whose flow did not return shows the two views differently: dropped
        pts_canvas = small_to_full(pts_small, factor) + self.offset_tgt
        targets_src = sample_map(current, pts_canvas + flow)
        key_src = sample_map(self.key_map, pts_canvas)
        usable = kept & np.isfinite(targets_src).all(axis=1) & np.isfinite(key_src).all(axis=1)
        pts_canvas, targets_src = pts_canvas[usable], targets_src[usable]
        if len(pts_canvas) >= cfg.video_align_min_points:
            importance = np.ones(len(pts_canvas)) if seam is None else \
                1.0 + (cfg.video_align_seam_weight - 1.0) * (seam.distance(pts_canvas) <= cfg.video_align_seam_px)
            lattice, error, weights = self.fit.fit(pts_canvas, targets_src - key_src[usable], prior, importance)
        else:  # too few points this frame: the warp carries on as predicted
            lattice, error, weights = prior, np.zeros(len(pts_canvas)), np.zeros(len(pts_canvas))
        value = self.filter.update(lattice)
        self.map_src = cv2.add(self.key_map, self.correction_field(value))
        return Alignment(value, pts_canvas, targets_src, weights, error, self.points.seeded)


def copies_apart(alignment: Alignment, map_src_canvas: np.ndarray, min_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The two copies on the canvas of each point the warp ``map_src_canvas`` leaves more than ``min_px``
    off: (the target's (M, 2), the source's (M, 2)) canvas (x, y). The source's copy sits where the map
    takes the source pixel the point should show: the point plus the map's error there through the map's
    local inverse Jacobian (finite differences over a pixel)."""
    pts = alignment.pts_canvas
    shown = sample_map(map_src_canvas, pts)
    jacobian = np.stack([sample_map(map_src_canvas, pts + [1.0, 0.0]) - shown,
                         sample_map(map_src_canvas, pts + [0.0, 1.0]) - shown], axis=2)  # (N, 2 src, 2 canvas)
    error_src = alignment.targets_src - shown
    known = np.isfinite(jacobian).all(axis=(1, 2)) & np.isfinite(error_src).all(axis=1)
    known[known] &= np.abs(np.linalg.det(jacobian[known])) > 1e-6
    off_canvas = np.full_like(pts, np.nan)
    off_canvas[known] = np.linalg.solve(jacobian[known], error_src[known][:, :, None])[:, :, 0]
    apart = known & (np.hypot(*np.nan_to_num(off_canvas).T) > min_px)
    return pts[apart], pts[apart] + off_canvas[apart]
