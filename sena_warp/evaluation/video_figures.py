"""Figures of a stitched video over time, measured by an observer of the frame loop.

:class:`VideoFigures` is a :data:`~sena_warp.video.stitch.FrameObserver`: ``stitch_videos(...,
observer=VideoFigures(cfg))`` calls it with every composited frame, and :meth:`VideoFigures.figures`
gives the JSON-ready figures afterwards (``sena-warp video --figures`` puts them into the report).
Everything is measured on the luma plane, per seam *line* (a canvas row; a column for a vertical
rig), in a band of :data:`BAND_MARGIN_PX` beyond the per-frame seam's reach around the estimate's seam.

* *Seam motion* (px per frame): the largest |change| over the lines of the seam as composited,
  frame to frame. *Where nothing moves*: the same over the lines where neither view changed in the
  band (a box-blurred frame difference below :data:`STILL_GREY` everywhere within
  :data:`STILL_LINES` lines x the band width), frames whose maps did not change.
* *Exposure step* (grey levels per frame): ``naturalness.seam_step`` on the band: the output luma
  just before the seam minus just after, less the two views' own change across those pixels (the
  views as they enter the output: warped, with the frame's gains; the seam blend's offsets are part
  of the output, not of the views; on a line where one view alone covers both strips, a seam at the
  overlap's edge, that view's own change), on the lines where the views are aligned at the seam (the median
  flow of the misalignment below at its textured cells within ``naturalness.STEP_FAR_PX`` of the seam
  at most :data:`STEP_ALIGNED_PX`, as last measured): where they are not, the two strips show each view
  something else (a near door in one, the room behind it in the other), the step is the scene's and
  the misalignment figure counts it; ``all_lines_mean`` the same over every line. Its
  *frame-to-frame change*: the mean over lines of |change of the row-averaged signed step|
  (``naturalness.seam_steps``). "Settled": from :data:`SETTLED_S` on. The settled step is also given
  per run of seam lines (where along the seam it is).
* *Misalignment at the seam* (px): DIS optical flow (OpenCV, medium preset) from the target's band
  to the source's (the band's cells within :data:`FLOW_MARGIN_PX` of the frame's seam), both with
  their gains, every :data:`FLOW_EVERY` frames; its magnitude (and its
  component across the seam) at cells within T/2 of the frame's seam (T = ``cfg.transition_px``)
  where both views are valid and the target is textured (the square root of the structure tensor's
  smaller eigenvalue, 7x7, at least :data:`TEXTURE_GREY_PER_PX`): median and 95th percentile pooled
  over those cells of all sampled frames, and the worst frame's median.
* *Stability* (StabStitch, Nie et al. ECCV 2024, and their code's ``smooth_loss``): a 7x9 lattice of
  source pixels mapped to the canvas through the frame's source map (numeric inverse,
  ``warp_map.forward_points``), the path P_t scaled as if the source frame were 480x360;
  ``sum_d w_d mean((P_{t-d} - P_t)^2 + (P_{t+d} - P_t)^2)`` over d = 1, 2, 3 with w = 0.9, 0.3, 0.1,
  the mean over t = 3 .. T-4, the lattice points on the canvas in every frame and both coordinates.
  This is the warp's own shake: maps that never change (a static rig) score 0 whatever the cameras do.
* *Uncovered share* (% of the output): the output pixels neither view samples (where the output is
  black: off the canvas, or canvas pixels the frame's maps leave unsampled), per frame from the frame's
  maps and its window on the canvas; its largest frame-to-frame change says whether black areas flash
  in or out.
* *Output shake* (output px): how the picture as shown moves from frame to frame (phase correlation of
  the canvas's Y, made about ``steady.PATH_SHORT_PX`` rows small, less the frame's window's move on the
  canvas), summed into a path; its second
  difference ``|P_{t-1} - 2 P_t + P_{t+1}|`` (mean and 95th percentile): 0 for a still picture and for
  a steady pan, large where the picture shakes (a moving rig's steady canvas, ``video/steady.py``, is
  what lowers it).

:class:`FrameClock` is a second, nearly free observer: the process's CPU time per frame (every
thread: decoding, stitching, encoding), for a run apart from the figures' (they cost more than the
stitch).

Cost: the band views are two small remaps per frame; the flow runs every :data:`FLOW_EVERY` frames;
the lattice is inverted only when the maps change. (What a crossing clip's figure looks like in each
frame is measured by ``crossing.CrossingFigures``.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import cv2
import numpy as np

from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.gains import tone_curve
from sena_warp.video.frame_seam import lines_near
from sena_warp.video.maps import sampled_mask
from sena_warp.video.steady import frame_shift, small_y
from sena_warp.video.stitch import CompositedFrame
from sena_warp.warp_map import forward_points

from . import naturalness

BAND_MARGIN_PX = naturalness.STEP_FAR_PX + 4  # the band reaches this beyond where the seam may go
STILL_GREY = 6.0  # a view changed at a band cell when its 5x5 box-blurred frame difference exceeds this
STILL_BOX_PX = 5
STILL_LINES = 1.0  # lines within this x the band width of a changed line are not still either
SETTLED_S = 1.0  # "once settled": frames from this time on (cameras settle in their first half second)
STEP_LINE_GROUPS = 16  # the settled exposure step is also given per this many runs of seam lines
FLOW_EVERY = 2  # the optical flow runs on every this-th frame
STEP_ALIGNED_PX = naturalness.STEP_NEAR_PX  # a line's views are aligned at the seam when their flow there is this
# at most: the step's strips start this far from the seam, so farther apart they show each view other content
FLOW_MARGIN_PX = 32  # ... on the band's cells within this of the frame's seam (not the whole band: DIS's
# result at a cell depends on how far the image reaches, and the band's width is a setting)
TEXTURE_GREY_PER_PX = 3.0  # misalignment is read where the target is this textured (sqrt of min eigenvalue)
TEXTURE_BOX_PX = 7
LATTICE_ROWS, LATTICE_COLS = 7, 9  # StabStitch's mesh: 6 x 8 cells, 7 x 9 vertices
STABILITY_SIZE = (480, 360)  # (width, height) StabStitch resizes its frames to
STABILITY_WEIGHTS = {1: 0.9, 2: 0.3, 3: 0.1}  # frame distance d -> weight
STRIP_EVERY = 10  # the band of every this-th output frame is kept for a seam-over-time strip
AFFINE_STEP_PX = 8  # the map is sampled every this many canvas px to fit the inversion's start affine


@dataclass(frozen=True)
class SeamBand:
    """The canvas cells within ``half`` of the estimate's seam on every line, and where each view samples them:
    the rectangle of the canvas from ``half`` before the seam's lowest position to ``half`` past its highest.

    Arrays are (L, W): line by cell across the seam (the source at low cells). ``x0`` (L,) int:
    the first cell's position on its line (the same on every line); ``index``: (rows, cols) canvas indices of the cells
    (clipped); ``valid_src`` / ``valid_tgt``: a view's bilinear footprint is inside its plane (and
    the cell on the canvas); ``map_src`` / ``map_tgt``: (L, W, 2) float32 input (x, y), -1
    where not valid.
    """

    x0: np.ndarray
    index: tuple[np.ndarray, np.ndarray]
    valid_src: np.ndarray
    valid_tgt: np.ndarray
    map_src: np.ndarray
    map_tgt: np.ndarray

    @classmethod
    def around(cls, frame: CompositedFrame, half: int) -> "SeamBand":
        map_src, map_tgt = frame.maps.map_src_luma, frame.maps.map_tgt_luma
        height, width = map_src.shape[:2]
        # One rectangle of the canvas, every line's cells at the same positions: a band that followed a
        # slanted home line by line would be sheared, and the flow along the lines read across them.
        home = np.rint(frame.seam_home).astype(np.int64)
        x0 = np.full(len(home), home.min() - half, np.int64)
        cells = x0[:, None] + np.arange(int(home.max() - home.min()) + 2 * half + 1)[None, :]
        lines = np.broadcast_to(np.arange(len(x0))[:, None], cells.shape)
        rows, cols, extent = (lines, cells, width) if frame.lines_are_rows else (cells, lines, height)
        on_canvas = (cells >= 0) & (cells < extent)
        index = (np.clip(rows, 0, height - 1), np.clip(cols, 0, width - 1))
        sampled_src, sampled_tgt = map_src[index], map_tgt[index]
        valid_src = on_canvas & sampled_mask(sampled_src, frame.planes_src[0].shape)
        valid_tgt = on_canvas & sampled_mask(sampled_tgt, frame.planes_tgt[0].shape)
        return cls(x0, index, valid_src, valid_tgt, np.where(valid_src[..., None], sampled_src, -1).astype(np.float32),
                   np.where(valid_tgt[..., None], sampled_tgt, -1).astype(np.float32))

    def views(self, y_src: np.ndarray, y_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both Y planes sampled on the band (bilinear), float32 (L, W), 0 where not valid."""
        def one(plane: np.ndarray, positions: np.ndarray, valid: np.ndarray) -> np.ndarray:
            sampled = cv2.remap(plane, positions[..., 0], positions[..., 1], cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE)
            return np.where(valid, sampled.astype(np.float32), np.float32(0.0))
        return one(y_src, self.map_src, self.valid_src), one(y_tgt, self.map_tgt, self.valid_tgt)

    def output(self, y_out: np.ndarray) -> np.ndarray:
        """The output Y on the band, float32 (L, W)."""
        return y_out[self.index].astype(np.float32)


def stability_per_point(paths: np.ndarray) -> np.ndarray:
    """StabStitch's stability of each of N (T, N, 2) paths: (N,) float64, all NaN with fewer than 7 frames.

    Each term is the mean over frames t = 3 .. T-4 and both coordinates of the squared difference to
    frame t - d plus that to t + d; :func:`stability` is their mean over the points.
    """
    paths = np.asarray(paths, np.float64)
    frames = len(paths)
    if frames < 7:
        return np.full(paths.shape[1], np.nan)
    mid = paths[3:frames - 3]
    total = np.zeros(paths.shape[1])
    for d, weight in STABILITY_WEIGHTS.items():
        before, after = paths[3 - d:frames - 3 - d], paths[3 + d:frames - 3 + d]
        total += weight * (np.mean((before - mid) ** 2, axis=(0, 2)) + np.mean((after - mid) ** 2, axis=(0, 2)))
    return total


def stability(paths: np.ndarray) -> float:
    """StabStitch's stability of (T, N, 2) paths (module docstring); NaN with fewer than 7 frames."""
    return float(np.mean(stability_per_point(paths)))


def forward_on_canvas(map_src_canvas: np.ndarray, pts_src: np.ndarray, cfg: Config) -> np.ndarray:
    """Canvas (x, y) (N, 2) float64 where the source map (Hc, Wc, 2) takes the source points (N, 2);
    NaN where it never does. ``warp_map.forward_points`` started from the affine fitted to the map
    (least squares on a grid every :data:`AFFINE_STEP_PX` canvas px): a video's maps carry no affine."""
    height, width = map_src_canvas.shape[:2]
    rows, cols = np.mgrid[0:height:AFFINE_STEP_PX, 0:width:AFFINE_STEP_PX]
    sampled = map_src_canvas[rows, cols].reshape(-1, 2).astype(np.float64)
    canvas_xy = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
    known = np.isfinite(sampled).all(axis=1)
    pts_src = np.asarray(pts_src, np.float64).reshape(-1, 2)
    if known.sum() < 3:
        return np.full_like(pts_src, np.nan)
    design = np.hstack([sampled[known], np.ones((known.sum(), 1))])
    affine_src_to_canvas = np.linalg.lstsq(design, canvas_xy[known], rcond=None)[0].T
    return forward_points(map_src_canvas, affine_src_to_canvas, Canvas(width, height, (0.0, 0.0)), pts_src, cfg)


def source_lattice(shape_src: tuple[int, int]) -> np.ndarray:
    """(63, 2) float64 (x, y): the 7 x 9 lattice over a source plane of ``shape_src`` (rows, cols), corners included."""
    xs = np.linspace(0.0, shape_src[1] - 1.0, LATTICE_COLS)
    ys = np.linspace(0.0, shape_src[0] - 1.0, LATTICE_ROWS)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def texture(grey: np.ndarray) -> np.ndarray:
    """Square root of the smaller eigenvalue of the 7x7 structure tensor, grey levels per px, (H, W) float32."""
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    box = (TEXTURE_BOX_PX, TEXTURE_BOX_PX)
    jxx, jyy, jxy = (cv2.blur(v, box) for v in (gx * gx, gy * gy, gx * gy))
    smaller = 0.5 * (jxx + jyy) - np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy ** 2)
    return np.sqrt(np.maximum(smaller, 0.0))


def band_flow(src: np.ndarray, tgt: np.ndarray, valid_src: np.ndarray, valid_tgt: np.ndarray) -> np.ndarray:
    """DIS flow (L, W, 2) float32 (across, along) from the target band to the source band: the target's
    content at cell c is in the source at c + flow. Cells a view lacks take the other view's value."""
    src8 = np.clip(np.rint(np.where(valid_src, src, tgt)), 0, 255).astype(np.uint8)
    tgt8 = np.clip(np.rint(np.where(valid_tgt, tgt, src)), 0, 255).astype(np.uint8)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(tgt8, src8, None)


def aligned_lines(flow: np.ndarray, cells: np.ndarray, seam: np.ndarray, both: np.ndarray) -> np.ndarray:
    """(L,) bool: the lines whose views are aligned at the seam (``seam`` (L,) positions): the median
    magnitude of the ``flow`` (L, W, 2) over the cells at ``cells`` (1, W) within
    ``naturalness.STEP_FAR_PX`` of the seam where ``both`` (L, W) holds (both views, textured: the flow
    of a flat sky is DIS's guess), at most :data:`STEP_ALIGNED_PX`; True on a line without such a cell
    (nothing says otherwise: a step on a flat line is the exposure's)."""
    strips = (np.abs(cells - np.asarray(seam, np.float64)[:, None]) <= naturalness.STEP_FAR_PX) & both
    magnitude = np.where(strips, np.hypot(flow[..., 0], flow[..., 1]), np.nan)
    any_cell = strips.any(axis=1)
    median = np.zeros(len(strips))
    median[any_cell] = np.nanmedian(magnitude[any_cell], axis=1)
    return median <= STEP_ALIGNED_PX


def covered_canvas(frame: CompositedFrame) -> np.ndarray:
    """(Hc, Wc) bool: the canvas pixels a view samples with the frame's maps."""
    maps = frame.maps
    return (sampled_mask(maps.map_src_luma, frame.planes_src[0].shape)
            | sampled_mask(maps.map_tgt_luma, frame.planes_tgt[0].shape))


def uncovered_pct(covered: np.ndarray, window: tuple[int, int, int, int]) -> float:
    """% of the output window (x, y, width, height) on the canvas (x, y to the nearest pixel) that no view
    samples (``covered``: the canvas's :func:`covered_canvas`; off the canvas counts as uncovered): where
    the output is the fill."""
    x, y = (int(round(v)) for v in window[:2])
    width, height = window[2:]
    rows, cols = covered.shape
    inside = covered[max(y, 0):min(y + height, rows), max(x, 0):min(x + width, cols)]
    return 100.0 * (1.0 - float(inside.sum()) / float(width * height))


def second_difference(path: np.ndarray) -> np.ndarray:
    """(T - 2,) float64: ``|P_{t-1} - 2 P_t + P_{t+1}|`` of a (T, 2) path (empty below 3 frames)."""
    path = np.asarray(path, np.float64).reshape(-1, 2)
    if len(path) < 3:
        return np.zeros(0)
    return np.linalg.norm(path[:-2] - 2.0 * path[1:-1] + path[2:], axis=1)


def _stats(values, percentile: float | None = None) -> float | None:
    values = np.asarray([v for v in values if v is not None and np.isfinite(v)], np.float64)
    if not values.size:
        return None
    return round(float(np.percentile(values, percentile) if percentile is not None else values.mean()), 4)


class VideoFigures:
    """The observer measuring a stitched video (module docstring); :meth:`figures` when the run is done.

    ``cfg``: the stitch's settings (transition width, inversion tolerances). ``strip_every``: keep the output's
    band of every this-th frame (``strips``: (index, band (L, W) uint8, seam (L,) in band cells, the
    band's first cell per line (L,))) for a
    seam-over-time picture; ``keep_frames``: output frame indices whose (y, u, v) planes are kept
    (``frames``: index -> (planes, seam (L,) canvas positions)).
    """

    def __init__(self, cfg: Config, strip_every: int = 0,
                 keep_frames: tuple[int, ...] = (), flow_every: int = FLOW_EVERY):
        self.cfg = cfg
        self.strip_every = strip_every
        self.keep_frames = set(keep_frames)
        self.flow_every = max(1, flow_every)
        self.strips: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.frames: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._maps = None
        self._band: SeamBand | None = None
        self._half = 0
        self._last: dict | None = None  # the previous frame: seam, band views, steps, whether maps changed
        self._lattice: np.ndarray | None = None
        self._scale = np.ones(2)
        self._path: np.ndarray | None = None
        self._covered: np.ndarray | None = None  # the canvas pixels the current maps sample
        self._shown: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # the last canvas's small Y, its
        # Hanning window and the output window's corner
        self.shown_path: list[np.ndarray] = []  # the output picture's path (output shake), output px
        self.per_frame: dict[str, list] = {name: [] for name in (
            "time_s", "maps_changed", "seam_motion_px", "seam_motion_still_px", "still_lines_pct",
            "exposure_step", "exposure_step_all", "exposure_step_change", "misalignment_px", "uncovered_pct")}
        self.paths: list[np.ndarray] = []
        self._flow_cells: list[np.ndarray] = []
        self._flow_cross: list[np.ndarray] = []
        self._steps: list[np.ndarray] = []  # every frame's signed step per seam line (NaN where undefined)
        self._aligned: np.ndarray | None = None  # (L,) bool: lines whose views were aligned at the seam when last measured
        self._step_lines = (0, 0)  # (frame, line) with a defined step: all of them, those where the views were aligned

    def __call__(self, frame: CompositedFrame) -> None:
        changed = frame.maps is not self._maps
        if changed:
            self._new_maps(frame)
        band = self._band
        canvas = frame.canvas()
        y_src, y_tgt, y_out = frame.planes_src[0], frame.planes_tgt[0], canvas[0]
        src, tgt = band.views(y_src, y_tgt)
        out = band.output(y_out)
        gain_src, bias_src, gain_tgt, bias_tgt = (float(v[0]) for v in frame.gains_luma)
        knee, white = frame.knee_luma or (math.inf, math.inf)  # no knee: the affine gains
        src_g = np.where(band.valid_src, tone_curve(src, gain_src, bias_src, knee, white), 0.0).astype(np.float32)
        tgt_g = np.where(band.valid_tgt, tone_curve(tgt, gain_tgt, bias_tgt, knee, white), 0.0).astype(np.float32)
        seam_band = np.asarray(frame.seam, np.float64) - band.x0
        steps = naturalness.seam_steps(out, src_g, tgt_g, band.valid_src, band.valid_tgt, seam_band, one_view=True)
        last = self._last
        record = self.per_frame
        record["time_s"].append(frame.time_s)
        record["maps_changed"].append(bool(changed))
        motion = still_motion = still_pct = change = None
        if last is not None:
            delta = np.abs(np.asarray(frame.seam, np.float64) - last["seam"])
            motion = float(delta.max())
            if not changed:
                still = self._still_lines(src, tgt, last["src"], last["tgt"])
                still_pct = 100.0 * float(still.mean())
                still_motion = float(delta[still].max()) if still.any() else 0.0
            both = np.isfinite(steps) & np.isfinite(last["steps"])
            change = float(np.mean(np.abs(steps[both] - last["steps"][both]))) if both.any() else None
        record["seam_motion_px"].append(motion)
        record["seam_motion_still_px"].append(still_motion)
        record["still_lines_pct"].append(still_pct)
        known = np.isfinite(steps)
        record["exposure_step_all"].append(float(np.mean(np.abs(steps[known]))) if known.any() else None)
        record["misalignment_px"].append(
            self._misalignment(src_g, tgt_g, band, seam_band) if frame.index % self.flow_every == 0 else None)
        defined = int(known.sum())
        if self._aligned is not None and len(self._aligned) == len(steps):
            known &= self._aligned
        self._step_lines = (self._step_lines[0] + defined, self._step_lines[1] + int(known.sum()))
        record["exposure_step"].append(float(np.mean(np.abs(steps[known]))) if known.any() else None)
        self._steps.append(np.where(known, steps, np.nan).astype(np.float32))
        record["exposure_step_change"].append(change)
        record["uncovered_pct"].append(uncovered_pct(self._covered, frame.window))
        self._follow_output(y_out, frame.window)
        self.paths.append(self._path)
        if self.strip_every and frame.index % self.strip_every == 0:
            self.strips.append((frame.index, np.clip(np.rint(out), 0, 255).astype(np.uint8), seam_band.copy(),
                                band.x0.copy()))
        if frame.index in self.keep_frames:
            self.frames[frame.index] = (tuple(p.copy() for p in canvas), np.asarray(frame.seam).copy())
        self._last = {"seam": np.asarray(frame.seam, np.float64).copy(), "src": src, "tgt": tgt, "steps": steps}

    def _new_maps(self, frame: CompositedFrame) -> None:
        """A new map set: the band, the lattice's path, the views' validity on the canvas."""
        self._maps = frame.maps
        self._half = max(self._half, int(math.ceil(frame.seam_reach_px)) + BAND_MARGIN_PX)
        self._band = SeamBand.around(frame, self._half)
        shape_src = frame.planes_src[0].shape
        if self._lattice is None:
            self._lattice = source_lattice(shape_src)
            self._scale = np.array([STABILITY_SIZE[0] / shape_src[1], STABILITY_SIZE[1] / shape_src[0]])
        self._path = forward_on_canvas(frame.maps.map_src_luma, self._lattice, self.cfg) * self._scale
        self._covered = covered_canvas(frame)

    def _follow_output(self, y_canvas: np.ndarray, window: tuple[float, float, int, int]) -> None:
        """The output picture's path (module docstring, output shake) one frame on: the canvas's move less
        the window's."""
        small = small_y(y_canvas)
        factor = np.array([y_canvas.shape[1] / small.shape[1], y_canvas.shape[0] / small.shape[0]])
        corner = np.asarray(window[:2], np.float64)
        if self._shown is None or self._shown[0].shape != small.shape:
            self._shown = (small, cv2.createHanningWindow(small.shape[::-1], cv2.CV_32F), corner)
            self.shown_path.append(np.zeros(2) if not self.shown_path else self.shown_path[-1])
            return
        moved, _ = frame_shift(self._shown[0], small, self._shown[1])
        self.shown_path.append(self.shown_path[-1] + moved * factor - (corner - self._shown[2]))
        self._shown = (small, self._shown[1], corner)

    def _still_lines(self, src, tgt, last_src, last_tgt) -> np.ndarray:
        """(L,) bool: lines where neither view changed within the band, nor within the dilation."""
        band = self._band
        box = (STILL_BOX_PX, STILL_BOX_PX)
        moved = np.zeros(len(src), bool)
        for now, before, valid in ((src, last_src, band.valid_src), (tgt, last_tgt, band.valid_tgt)):
            diff = cv2.blur(np.abs(now - before), box)
            moved |= ((diff > STILL_GREY) & valid).any(axis=1)
        return ~lines_near(moved, int(math.ceil(STILL_LINES * src.shape[1])))

    def _misalignment(self, src_g, tgt_g, band: SeamBand, seam_band: np.ndarray) -> float | None:
        """The frame's median flow magnitude at the seam's textured cells; their values are pooled. Also
        which lines' views are aligned at the seam (``_aligned``, :func:`aligned_lines`)."""
        lo = max(0, int(np.floor(seam_band.min())) - FLOW_MARGIN_PX)
        hi = min(src_g.shape[1], int(np.ceil(seam_band.max())) + FLOW_MARGIN_PX + 1)
        src_g, tgt_g, valid_src, valid_tgt = (a[:, lo:hi] for a in (src_g, tgt_g, band.valid_src, band.valid_tgt))
        flow = band_flow(src_g, tgt_g, valid_src, valid_tgt)
        cells = np.arange(lo, hi)[None, :]
        near = np.abs(cells - seam_band[:, None]) <= 0.5 * self.cfg.transition_px
        textured = valid_src & valid_tgt & (texture(tgt_g) >= TEXTURE_GREY_PER_PX)
        self._aligned = aligned_lines(flow, cells, seam_band, textured)
        chosen = near & textured
        if not chosen.any():
            return None
        magnitude = np.hypot(flow[..., 0], flow[..., 1])[chosen]
        self._flow_cells.append(magnitude)
        self._flow_cross.append(np.abs(flow[..., 0][chosen]))
        return float(np.median(magnitude))

    def _aligned_pct(self) -> float | None:
        """% of the (frame, line) whose step is defined where the views were aligned at the seam."""
        defined, aligned = self._step_lines
        return round(100.0 * aligned / defined, 2) if defined else None

    def _steps_by_lines(self, settled: list[bool]) -> list[dict]:
        """Where along the seam the settled exposure step is: the mean |step| over the settled frames in
        :data:`STEP_LINE_GROUPS` runs of seam lines, with the share of (line, frame) where it is defined."""
        steps = np.array([s for s, keep in zip(self._steps, settled) if keep and len(s) == len(self._steps[-1])])
        if steps.size == 0:
            return []
        groups = []
        for lines in np.array_split(np.arange(steps.shape[1]), STEP_LINE_GROUPS):
            part = steps[:, lines]
            known = np.isfinite(part)
            groups.append({"lines": [int(lines[0]), int(lines[-1])],
                           "mean": round(float(np.abs(part[known]).mean()), 4) if known.any() else None,
                           "known_pct": round(100.0 * float(known.mean()), 1)})
        return groups

    def stability(self) -> tuple[float, np.ndarray]:
        """(StabStitch stability, each lattice point's (63,), NaN for the points not on the canvas in
        every frame, which do not count)."""
        if not self.paths or any(p is None for p in self.paths):
            return math.nan, np.full(LATTICE_ROWS * LATTICE_COLS, np.nan)
        paths = np.stack(self.paths)
        kept = np.isfinite(paths).all(axis=(0, 2))
        per_point = np.where(kept, stability_per_point(np.where(kept[None, :, None], paths, 0.0)), np.nan)
        return (float(np.mean(per_point[kept])) if kept.any() else math.nan), per_point

    def figures(self) -> dict:
        """The run's figures, JSON-ready (module docstring); ``per_frame`` holds the series."""
        record = self.per_frame
        times = [t if t is not None else math.nan for t in record["time_s"]]
        t0 = next((t for t in times if np.isfinite(t)), 0.0)
        settled = [np.isfinite(t) and t - t0 >= SETTLED_S for t in times]

        def only(name: str, keep) -> list:
            return [v for v, k in zip(record[name], keep) if k]

        motion = record["seam_motion_px"]
        still = [v for v in record["seam_motion_still_px"] if v is not None]
        pooled = np.concatenate(self._flow_cells) if self._flow_cells else np.zeros(0)
        cross = np.concatenate(self._flow_cross) if self._flow_cross else np.zeros(0)
        value, per_point = self.stability()
        shake = second_difference(np.asarray(self.shown_path))
        figures = {
            "frames": len(times),
            "band_half_px": self._half,
            "settled_from_s": SETTLED_S,
            "seam_motion_px": {
                "mean": _stats(motion), "p99": _stats(motion, 99), "max": _stats(motion, 100),
                "frames_moving": int(sum(1 for v in motion if v is not None and v > 0)),
                "still_lines_pct_mean": _stats(record["still_lines_pct"]),
                "where_still_max": _stats(still, 100) if still else None,
                "frames_moving_where_still": int(sum(1 for v in still if v > 0)),
                "frames_with_still_lines": len(still),
            },
            "exposure_step_grey": {
                "mean": _stats(record["exposure_step"]), "p99": _stats(record["exposure_step"], 99),
                "all_lines_mean": _stats(record["exposure_step_all"]),
                "aligned_lines_pct": self._aligned_pct(),
                "settled_mean": _stats(only("exposure_step", settled)),
                "settled_p99": _stats(only("exposure_step", settled), 99),
                "settled_by_lines": self._steps_by_lines(settled),
            },
            "exposure_step_change_grey": {
                "p99": _stats(record["exposure_step_change"], 99),
                "max": _stats(record["exposure_step_change"], 100),
                "settled_p99": _stats(only("exposure_step_change", settled), 99),
            },
            "misalignment_px": {
                "every": self.flow_every, "measure": "DIS flow magnitude (and |across-seam component|) at textured seam cells",
                "frames": int(sum(1 for v in record["misalignment_px"] if v is not None)), "cells": int(pooled.size),
                "median": round(float(np.median(pooled)), 4) if pooled.size else None,
                "p95": round(float(np.percentile(pooled, 95)), 4) if pooled.size else None,
                "across_median": round(float(np.median(cross)), 4) if cross.size else None,
                "across_p95": round(float(np.percentile(cross, 95)), 4) if cross.size else None,
                "worst_frame_median": _stats(record["misalignment_px"], 100),
            },
            "uncovered_pct": {"mean": _stats(record["uncovered_pct"]), "max": _stats(record["uncovered_pct"], 100),
                              "largest_change": _stats(np.abs(np.diff(record["uncovered_pct"])), 100) or 0.0},
            "output_shake_px": {"mean": _stats(shake), "p95": _stats(shake, 95), "max": _stats(shake, 100)},
            "stability": {"value": None if not np.isfinite(value) else round(value, 4),
                          "points": int(np.isfinite(per_point).sum()), "scale_to": list(STABILITY_SIZE),
                          "map_sets": int(sum(record["maps_changed"])),
                          "per_point": [None if not np.isfinite(v) else round(float(v), 5) for v in per_point]},
            "per_frame": {name: [None if v is None else (round(v, 4) if isinstance(v, float) else v) for v in values]
                          for name, values in record.items()},
        }
        return figures


class FrameClock:
    """An observer reading the process's CPU time (all its threads) as each frame reaches it: what a frame
    costs end to end, decoding and encoding included. Nearly free, so a run measured for its CPU carries
    no other observer (``benchmarks/video_figures.py --cpu``)."""

    def __init__(self) -> None:
        self.cpu_s: list[float] = []
        self.time_s: list[float | None] = []

    def __call__(self, frame: CompositedFrame) -> None:
        self.cpu_s.append(time.process_time())
        self.time_s.append(frame.time_s)

    def figures(self) -> dict:
        """CPU ms per frame from :data:`SETTLED_S` on (the first estimate's set-up left out): the mean
        (total over frames) and the median and p95 of single frames; None with fewer than two frames."""
        t0 = next((t for t in self.time_s if t is not None), 0.0)
        settled = [c for c, t in zip(self.cpu_s, self.time_s) if t is not None and t - t0 >= SETTLED_S]
        steps = 1000.0 * np.diff(settled)
        if steps.size == 0:
            return {"frames": 0, "mean_ms": None, "median_ms": None, "p95_ms": None}
        return {"frames": int(steps.size), "mean_ms": round(float(steps.mean()), 3),
                "median_ms": round(float(np.median(steps)), 3), "p95_ms": round(float(np.percentile(steps, 95)), 3)}
