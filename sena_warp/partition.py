"""Step 9: partition the canvas at the seam and build the seam maps (docs/method.md step 9, paper
"Partitioning and Reconstruction").

The seam (``seam_path.SeamPath``: one x per canvas row, through the anchors) splits every row: the
source left of it, the target right of it, mixed by an alpha of width ``cfg.transition_px``
(Gaussian-smoothed with ``cfg.seam_smooth_sigma_px``, ``kernels/seam.py``'s ``source_alpha``, the
same rule the compositor applies). The source is resampled so that each source anchor lands on its
target anchor: per row, the anchor residual (dx, dy) = anchor_src - anchor_tgt is interpolated over
the rows, applied in full inside the transition and faded out (smootherstep) over
``cfg.seam_fade_px`` beyond it, so the source far from the seam keeps its step-6 shape. The paper
interpolates the residual linearly between anchors, which kinks lines that cross the seam at every
anchor; with ``cfg.seam_model == "path"`` it is a smoothing spline through them
(``smooth_curve``). The per-pixel part is ``kernels/seam.py``.

What is left of an exposure difference after the gains is hidden by the seam blend's low-frequency
part (``seam_offsets``): per row, half the mean difference of the two views next to the seam is taken
off the brighter side and added to the darker one, fading to nothing ``cfg.seam_blend_ratio`` x the
image diagonal away, while detail still switches sides within the narrow transition. Beyond the
seam's ends the canvas also switches views, along the target's top and bottom borders where the source
goes on beyond them; ``border_offsets`` does the same there, per canvas column (``cfg.border_blend``).
The source goes on there only as far along each border as the two views agree just inside it
(``past_target_src``): beyond, the border would cut other content.
Convention: the source is the LEFT view on the canvas (the caller transposes/flips other rigs).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import warp as wp

from sena_warp.canvas import Canvas
from sena_warp.composite import lf_weights
from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.ffd import cubic_weights
from sena_warp.kernels import runtime, transfer
from sena_warp.kernels.seam import seam_maps_kernel
from sena_warp.seam_path import SeamPath
from sena_warp.warp_map import CanvasViews

CURVE_STEP_ROWS = 8  # smooth_curve: one unknown every this many rows


@dataclass(frozen=True)
class SeamRows:
    """Per canvas row y (all (H,) float32): seam x ``s(y)``, the source row ``y + dy(y)`` that
    row y samples at the seam, and the x shift ``dx(y)`` applied there."""

    seam_x: np.ndarray
    src_row_y: np.ndarray
    shift_x: np.ndarray


@dataclass
class SeamMaps:
    """The three per-pixel maps of the stitch and the anchors they were built from, in the working
    frame (``stitch.StitchMaps`` holds them in the input frame).

    map_src_canvas, map_tgt_canvas: (H, W, 2) float32 (x, y) sample positions in the working-frame
    source and target images, per working-canvas pixel (map_tgt = u - o); alpha_canvas: (H, W)
    float32 weight of the source; seam_x_canvas: (H,) float32 seam x per canvas row;
    anchors_*_canvas: (K, 2) float64 (x, y) on the working canvas.
    """

    map_src_canvas: np.ndarray
    map_tgt_canvas: np.ndarray
    alpha_canvas: np.ndarray
    seam_x_canvas: np.ndarray
    anchors_src_canvas: np.ndarray
    anchors_tgt_canvas: np.ndarray


def curve_taps(y: np.ndarray, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, 4) node indices and cubic-convolution weights (``ffd.cubic_weights``) of rows ``y`` on a
    curve with a node every ``CURVE_STEP_ROWS`` rows."""
    g = np.clip(np.asarray(y, np.float64) / CURVE_STEP_ROWS, 0, nodes - 1)
    i0 = np.floor(g).astype(np.int64)
    return np.clip(i0[:, None] + np.arange(-1, 3)[None, :], 0, nodes - 1), cubic_weights(g - i0)


def smooth_curve(y_knots: np.ndarray, values: np.ndarray, height: int, smoothing: float) -> np.ndarray:
    """(height,) float64: a smooth curve over rows 0..height-1 that follows ``values`` at ``y_knots``.

    Node values every ``CURVE_STEP_ROWS`` rows, interpolated bicubically (no kink at the nodes),
    minimising the squared misfit at the knots plus ``smoothing`` x the squared second differences of
    the nodes (a discrete smoothing spline); constant beyond the first and last knot, zero without knots.
    """
    y_knots = np.asarray(y_knots, np.float64)
    values = np.asarray(values, np.float64)
    if y_knots.size == 0:
        return np.zeros(height)
    nodes = int(np.ceil(max(height - 1, 1) / CURVE_STEP_ROWS)) + 1
    # The normal equations summed tap by tap (a banded system of a few hundred nodes): no BLAS call,
    # whose idle threads cost more CPU time than the sums themselves.
    index, weight = curve_taps(y_knots, nodes)
    system = 1e-9 * np.eye(nodes)
    np.add.at(system, (index[:, :, None], index[:, None, :]), weight[:, :, None] * weight[:, None, :])
    rhs = np.zeros(nodes)
    np.add.at(rhs, index, weight * values[:, None])
    second = np.arange(max(nodes - 2, 0))[:, None] + np.arange(3)  # the second differences' taps
    step = np.array([1.0, -2.0, 1.0])
    np.add.at(system, (second[:, :, None], second[:, None, :]), smoothing * np.outer(step, step))
    solution = cv2.solve(system, rhs[:, None], flags=cv2.DECOMP_CHOLESKY)[1][:, 0]
    rows = np.clip(np.arange(height, dtype=np.float64), y_knots.min(), y_knots.max())  # constant beyond the ends
    index, weight = curve_taps(rows, nodes)
    return np.einsum("nk,nk->n", weight, solution[index])


def seam_rows(path: SeamPath, height: int, cfg: Config) -> SeamRows:
    """The seam and the anchor correction per canvas row 0..height-1.

    The residual of the anchors (source minus target copy) is interpolated linearly between them
    (``cfg.seam_model == "paper"``) or by ``smooth_curve`` (``"path"``), constant beyond the ends,
    zero without anchors.
    """
    anchors_src = np.asarray(path.anchors_src_canvas, np.float64).reshape(-1, 2)
    anchors_tgt = np.asarray(path.anchors_tgt_canvas, np.float64).reshape(-1, 2)
    rows = np.arange(height, dtype=np.float64)
    residual = anchors_src - anchors_tgt
    y = anchors_tgt[:, 1]
    if cfg.seam_model == "paper":
        dx, dy = (np.interp(rows, y, residual[:, k]) for k in range(2))
    else:
        dx, dy = (smooth_curve(y, residual[:, k], height, cfg.correction_smooth) for k in range(2))
    return SeamRows(seam_x=np.asarray(path.seam_x_canvas, np.float32), src_row_y=(rows + dy).astype(np.float32),
                    shift_x=dx.astype(np.float32))


def seam_maps(map_src_canvas: np.ndarray, canvas: Canvas, path: SeamPath, cfg: Config) -> SeamMaps:
    """SENA step 9: source map, target map and alpha of the stitch (Warp kernel ``seam_maps_kernel``).

    map_src_canvas: (H, W, 2) float32 step-6 source sampling map; canvas: its size and target offset;
    path: the seam of ``seam_path.seam_line``. Runs on ``cfg.device`` (resolved,
    ``runtime.resolve_config``) with ``cfg.cpu_threads``.
    """
    if map_src_canvas.shape != (canvas.height, canvas.width, 2):
        raise InputError(f"source map shape {map_src_canvas.shape} does not match the canvas {canvas.shape}")
    if cfg.transition_px < 1 or cfg.seam_fade_px <= 0:
        raise InputError("transition_px must be >= 1 and seam_fade_px > 0")
    rows = seam_rows(path, canvas.height, cfg)
    shape = canvas.shape
    device = cfg.device
    map_src_out = wp.empty(shape, dtype=wp.vec2, device=device)
    map_tgt_out = wp.empty(shape, dtype=wp.vec2, device=device)
    alpha_out = wp.empty(shape, dtype=float, device=device)
    inputs = [
        transfer.to_device(np.ascontiguousarray(map_src_canvas, np.float32), wp.vec2, device, "seam_maps"),
        transfer.to_device(rows.seam_x, float, device, "seam_maps"),
        transfer.to_device(rows.src_row_y, float, device, "seam_maps"),
        transfer.to_device(rows.shift_x, float, device, "seam_maps"),
        wp.vec2(*canvas.offset_tgt),
        float(cfg.transition_px),
        float(cfg.seam_smooth_sigma_px),
        float(cfg.seam_fade_px),
        map_src_out,
        map_tgt_out,
        alpha_out,
    ]
    runtime.launch_rows(seam_maps_kernel, canvas.height, canvas.width, inputs, device, cfg.cpu_threads)
    return SeamMaps(
        map_src_canvas=transfer.download(map_src_out, "seam_maps").reshape(*shape, 2),
        map_tgt_canvas=transfer.download(map_tgt_out, "seam_maps").reshape(*shape, 2),
        alpha_canvas=transfer.download(alpha_out, "seam_maps"),
        seam_x_canvas=rows.seam_x,
        anchors_src_canvas=np.asarray(path.anchors_src_canvas, np.float64),
        anchors_tgt_canvas=np.asarray(path.anchors_tgt_canvas, np.float64),
    )


def thin_strips(label: np.ndarray, max_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(source, target): (H, W) bool pixels of a view the panorama shows only in a strip thinner than
    ``max_px`` along the canvas's edge of what it covers, before the other view takes over: the source
    a few px beyond the target's top, bottom or far border, the target a few px beyond the warped
    source's edge. A strip that thin shows nothing whole, only content the switch cuts, and what is
    left of the parallax shifts it against the other view all along.

    label: (H, W) uint8 the view shown per canvas pixel (``switch_align.shown_labels``: 1 source, 2
    target, 0 none). Per column from the top and from the bottom, per row from the left and the right:
    the first run of one view, where the other view follows it directly and it is shorter than max_px
    (only the first ``ceil(max_px) + 1`` pixels of each line are read: a longer run is no strip).
    """
    thin = np.zeros(label.shape, bool)
    for flip_rows, transpose in ((False, False), (True, False), (False, True), (True, True)):
        lab = label.T if transpose else label
        lab = lab[::-1] if flip_rows else lab
        lines, cols = lab.shape[0], np.arange(lab.shape[1])
        first = np.argmax(lab > 0, axis=0)
        view = lab[first, cols]
        rows = first[None, :] + np.arange(min(int(np.ceil(max_px)) + 1, lines))[:, None]
        window = np.take_along_axis(lab, np.minimum(rows, lines - 1), axis=0)
        run = np.cumprod((window == view) & (rows < lines), axis=0).astype(bool)
        length = run.sum(axis=0)
        after = lab[np.minimum(first + length, lines - 1), cols]
        strip = run & ((length < max_px) & (first + length < lines) & (after > 0) & (after != view))[None, :]
        mask = np.zeros(lab.shape, bool)
        mask[rows[strip], np.broadcast_to(cols, rows.shape)[strip]] = True
        mask = mask[::-1] if flip_rows else mask
        thin |= mask.T if transpose else mask
    return thin & (label == 1), thin & (label == 2)


def past_target_src(views: CanvasViews, seam_x_canvas: np.ndarray, offset_tgt: tuple[float, float],
                    shape_tgt: tuple[int, ...], cfg: Config) -> np.ndarray:
    """(H, W) bool: the canvas pixels on the target's side of the seam (x > the seam's x, where the seam
    maps' alpha is below 0.5) outside the target where the source is left out.

    Past the seam's ends the source goes on beyond the target's top and bottom borders, and meets the
    target along a straight border the seam did not choose. Along each border, from the seam outward,
    it is kept as far as it goes on beyond the border without a gap and the two views agree just inside
    the border: per block of ``cfg.seam_blend_rows`` columns of the ``cfg.seam_blend_strip_px`` rows
    inside, the median absolute deviation of their grey difference at most ``cfg.past_target_mad_grey``
    as it is or smoothed by ``cfg.past_target_sigma_px`` (more in both: they show other content there,
    which the border would cut; ``agreeing_end``). From the first block that fails on, and past the
    target's far edge, it is left out: the strip ends with the panorama's outline, not with a cut
    through content, and a detached piece (beyond a gap) is never shown. Every such pixel, whether or
    not step 6's source reaches it (step 9's correction moves the source's edge by a few px).

    views: the gain-compensated canvas views; seam_x_canvas: (H,) the seam's x per canvas row (NaN: no
    seam in that row, nothing left out); offset_tgt: the target's (x, y) on the canvas; shape_tgt: its
    (rows, columns, ...).
    """
    height, width = views.both.shape
    seam_x = np.asarray(seam_x_canvas, np.float32)
    cols = np.arange(width, dtype=np.float32)[None, :]
    with np.errstate(invalid="ignore"):
        past = (cols > seam_x[:, None]) & ~views.valid_tgt
    ox, oy = (int(round(v)) for v in offset_tgt)
    rows_tgt, cols_tgt = shape_tgt[:2]
    strip = max(1, cfg.seam_blend_strip_px)
    kept = np.zeros_like(past)
    for inside, beyond, edge in ((slice(max(oy, 0), max(oy + strip, 0)), slice(0, max(oy, 0)), oy - 1),
                                 (slice(max(oy + rows_tgt - strip, 0), max(oy + rows_tgt, 0)), slice(oy + rows_tgt, height),
                                  oy + rows_tgt)):
        if not 0 <= edge < height or not np.isfinite(seam_x[edge]):
            continue
        start = int(np.floor(seam_x[edge])) + 1
        shown_tgt = views.both[inside] & (cols > seam_x[inside, None] + 0.5 * cfg.transition_px)
        used = shown_tgt & cv2.erode(views.both[inside].astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        end = agreeing_end(views.valid_src[edge], band_differences(views, inside, cfg.past_target_sigma_px), used, start,
                           min(width, ox + cols_tgt), cfg)
        kept[beyond, :end] = True
    return past & ~kept


def agreeing_end(goes_on: np.ndarray, diffs: tuple[np.ndarray, np.ndarray], used: np.ndarray, start: int, stop: int,
                 cfg: Config) -> int:
    """The first column from ``start`` (before ``stop``) where a source strip beyond a target's border
    ends: where it stops going on (``goes_on`` (W,) bool, the source's validity beyond the border), or the
    start of the first block of ``cfg.seam_blend_rows`` columns inside the border whose used pixels
    (``used`` (R, W)) are under a third of the block or whose grey differences spread too much: the
    median absolute deviation above ``cfg.past_target_mad_grey`` both as they are and smoothed
    (``diffs``: (R, W) each). A fine texture shifted by a pixel spreads only the first, a strong edge
    shifted by a pixel mostly the second; other content both. ``stop`` when none."""
    block = max(1, cfg.seam_blend_rows)
    for x0 in range(max(start, 0), stop, block):
        x1 = min(x0 + block, stop)
        mask = used[:, x0:x1]
        if mask.sum() < mask.size / 3:
            return x0
        spreads = [mad(diff[:, x0:x1][mask]) for diff in diffs]
        if min(spreads) > cfg.past_target_mad_grey:
            return x0
        gap = np.flatnonzero(~goes_on[x0:x1])
        if gap.size:
            return x0 + int(gap[0])
    return max(start, stop, 0)


def band_differences(views: CanvasViews, rows: slice, sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(R, W) float32 each: the grey difference source minus target on canvas rows ``rows`` (0 where a
    view is not defined) as it is and ``smoothed_over`` the overlap by ``sigma_px``, from those rows and
    the few beyond them the smoothing reaches (the rest of the canvas is not converted)."""
    reach = int(np.ceil(4.0 * sigma_px)) + 1
    lo, hi = max(rows.start - reach, 0), min(rows.stop + reach, views.both.shape[0])
    band = CanvasViews(views.src[lo:hi], views.tgt[lo:hi], views.valid_src[lo:hi], views.valid_tgt[lo:hi])
    grey_src, grey_tgt = band.grey()
    diff = np.nan_to_num(grey_src - grey_tgt)
    inside = slice(rows.start - lo, rows.stop - lo)
    return diff[inside], smoothed_over(diff, band.both, sigma_px)[inside]


def smoothed_over(values: np.ndarray, known: np.ndarray, sigma_px: float) -> np.ndarray:
    """(H, W) float32: ``values`` smoothed by a Gaussian of ``sigma_px`` over the pixels where ``known``
    alone (a normalised blur: nothing outside them is mixed in); as they are where sigma_px is 0."""
    if sigma_px <= 0:
        return values.astype(np.float32)
    weight = cv2.GaussianBlur(known.astype(np.float32), (0, 0), sigma_px)
    total = cv2.GaussianBlur(np.where(known, values, 0).astype(np.float32), (0, 0), sigma_px)
    return np.where(weight > 1e-6, total / np.maximum(weight, 1e-6), 0.0).astype(np.float32)


def mad(values: np.ndarray) -> float:
    """The median absolute deviation of ``values`` (any shape, at least one value) from their median."""
    return float(np.median(np.abs(values - np.median(values))))


LEVEL_MIN_GREY = 16.0  # relative offsets: a view's level is taken as at least this (dark rows: no huge gains)
BLEND_LOG_SPREAD = 0.1  # seam blend as a gain: a row whose log ratio's median absolute deviation is larger ...
BLEND_LOG_MAX = 0.3  # ... or whose ratio is further than this from 1 (log) shows other content, not an exposure
BLEND_COLOUR_MAX = 0.1  # seam blend in colour: a channel's log ratio departs from the grey one by at most this


@dataclass(frozen=True)
class SeamOffsets:
    """The seam blend's low-frequency part: per canvas row, grey levels added to each view near the
    seam (``src``, ``tgt``: (H, C) float32, full at the seam, fading linearly to 0 at ``fade_px``).
    ``level_src``, ``level_tgt``: (H,) float32 each view's mean grey level next to the seam, where the
    offsets were measured (None: not measured), for :meth:`relative`."""

    src: np.ndarray
    tgt: np.ndarray
    fade_px: float
    level_src: np.ndarray | None = None
    level_tgt: np.ndarray | None = None

    def relative(self) -> tuple[np.ndarray, np.ndarray]:
        """The offsets as relative changes of each view's gain ((H, C) float32 each): the offset over the
        level it was measured at (at least ``LEVEL_MIN_GREY``), what a ``FrameState`` with ``relative_offsets``
        applies."""
        return relative_to(self.src, self.level_src), relative_to(self.tgt, self.level_tgt)


def relative_to(offsets: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Offsets in grey levels as relative gains at ``level`` (per channel, or one per line broadcast
    against them), float32, within
    exp(+-``BLEND_LOG_MAX``) - 1: a larger ratio is not an exposure the blend should spread."""
    level = np.asarray(level)
    relative = offsets / np.maximum(level if level.ndim == offsets.ndim else level[..., None], LEVEL_MIN_GREY)
    return np.clip(relative, np.expm1(-BLEND_LOG_MAX), np.expm1(BLEND_LOG_MAX)).astype(np.float32)


def running_mean(values: np.ndarray, known: np.ndarray, window: int) -> np.ndarray:
    """Mean over ``window`` rows of (H, C) ``values`` where ``known`` (H,); rows without any known row in
    their window take the nearest row that has one."""
    kernel = np.ones(max(1, window))
    count = np.convolve(known.astype(np.float64), kernel, "same")
    total = np.stack([np.convolve(np.where(known, values[:, c], 0.0), kernel, "same") for c in range(values.shape[1])], 1)
    have = count > 0
    if not have.any():
        return np.zeros_like(values, dtype=np.float64)
    mean = total[have] / count[have][:, None]
    rows = np.arange(len(values))
    return np.stack([np.interp(rows, rows[have], mean[:, c]) for c in range(values.shape[1])], 1)


def seam_offsets(views: CanvasViews, seam_x_canvas: np.ndarray, diag_px: float, cfg: Config) -> SeamOffsets:
    """Offsets that take half the two views' mean difference next to the seam off one side and add it
    to the other (module docstring), with each view's mean level there; zero when
    ``cfg.seam_blend_ratio`` is 0. With ``cfg.seam_blend_gain`` it is a ratio: per row the median log
    ratio of the grey views, from the rows where it is one ratio (``BLEND_LOG_SPREAD``) near 1
    (``BLEND_LOG_MAX``): elsewhere the views show other things there, not one thing at two exposures,
    and those rows follow their neighbours. With ``cfg.seam_blend_colour`` each channel's median log
    ratio departs from the grey one by up to ``BLEND_COLOUR_MAX`` (the views' colours differ smoothly:
    a sky bluer in one view), else every channel takes the grey one. Each side then moves half of it
    as a gain: offsets of (exp(-+ r / 2) - 1) x its level, which :meth:`SeamOffsets.relative` turns
    back into those gains (a gain, not grey levels added: dark texture is not lifted into a haze).

    views: the gain-compensated canvas views; seam_x_canvas: (H,) seam x per row.
    """
    height, width = views.both.shape
    channels = views.src.shape[2]
    if cfg.seam_blend_ratio <= 0:
        zeros = np.zeros((height, channels), np.float32)
        level = np.full(height, 255.0, np.float32)
        return SeamOffsets(zeros, zeros.copy(), 0.0, level, level.copy())
    seam_x = np.asarray(seam_x_canvas, np.float64)
    reach = cfg.seam_blend_strip_px
    # Only the columns within reach of each row's seam: (H, 2 reach + 2) of them, not the whole canvas.
    cols = np.ceil(np.nan_to_num(seam_x, nan=-2.0 * reach - 2) - reach).astype(np.int64)[:, None] + np.arange(2 * reach + 2)
    inside = (cols >= 0) & (cols < width)
    cols = np.clip(cols, 0, width - 1)
    rows = np.arange(height)[:, None]
    strip = inside & views.both[rows, cols] & (np.abs(cols - seam_x[:, None]) <= reach)
    src = views.src[rows, cols].astype(np.float32) * strip[:, :, None]
    tgt = views.tgt[rows, cols].astype(np.float32) * strip[:, :, None]
    count = np.maximum(strip.sum(axis=1), 1)[:, None]
    means = np.concatenate([src.sum(axis=1) / count, tgt.sum(axis=1) / count], axis=1)
    known = strip.any(axis=1)
    if not cfg.seam_blend_gain:
        per_row = running_mean(means, known, cfg.seam_blend_rows).astype(np.float32)
        delta = per_row[:, :channels] - per_row[:, channels:]
        return SeamOffsets(-0.5 * delta, 0.5 * delta, float(cfg.seam_blend_ratio * diag_px),
                           per_row[:, :channels].mean(axis=1), per_row[:, channels:].mean(axis=1))
    # As a gain: the log ratio of the grey views, from the rows where it is one exposure ratio (small
    # spread, not far from 1); elsewhere the views show other things there (parallax), not measured.
    ratio = np.log((src.mean(axis=2) + 1.0) / (tgt.mean(axis=2) + 1.0))
    median, spread = np.zeros(height), np.zeros(height)
    ratio = np.where(strip, ratio, np.nan)[known]
    median[known] = np.nanmedian(ratio, axis=1)
    spread[known] = np.nanmedian(np.abs(ratio - median[known, None]), axis=1)
    colour = np.zeros((height, channels))
    if cfg.seam_blend_colour:  # each channel's ratio less the grey one, within BLEND_COLOUR_MAX
        ratios = np.log((src + 1.0) / (tgt + 1.0))
        ratios = np.where(strip[:, :, None], ratios, np.nan)[known]
        colour[known] = np.clip(np.nanmedian(ratios, axis=1) - median[known, None], -BLEND_COLOUR_MAX, BLEND_COLOUR_MAX)
    known &= (spread <= BLEND_LOG_SPREAD) & (np.abs(median) <= BLEND_LOG_MAX)
    per_row = running_mean(np.concatenate([means, median[:, None] + colour], axis=1), known, cfg.seam_blend_rows)
    level_src, level_tgt = per_row[:, :channels].mean(axis=1), per_row[:, channels:2 * channels].mean(axis=1)
    half = 0.5 * per_row[:, 2 * channels:]
    # Grey levels at each side's level, so that ``relative`` gives the gains exp(-+ half) - 1 per channel.
    off_src = (np.exp(-half) - 1.0) * np.maximum(level_src, LEVEL_MIN_GREY)[:, None]
    off_tgt = (np.exp(half) - 1.0) * np.maximum(level_tgt, LEVEL_MIN_GREY)[:, None]
    return SeamOffsets(off_src.astype(np.float32), off_tgt.astype(np.float32), float(cfg.seam_blend_ratio * diag_px),
                       level_src.astype(np.float32), level_tgt.astype(np.float32))


@dataclass(frozen=True)
class BorderOffsets:
    """The seam blend along the target's two borders (its top and bottom edges on the working canvas):
    ``lines`` the two borders' y (between the target's first row and the one above it, between its
    last and the one below); ``src``, ``tgt``: (2, W, C) float32 grey levels added to each view per
    canvas column at that border, fading linearly to 0 at ``fade_px`` from it; ``on``: False when
    off (all zero). ``level_src``, ``level_tgt``: (2, W, C) float32 each view's mean level just
    inside the border (grey in every channel, or each channel's with ``seam_blend_colour``; None: not
    measured), for :meth:`relative`."""

    lines: tuple[float, float]
    src: np.ndarray
    tgt: np.ndarray
    on: bool
    level_src: np.ndarray | None = None
    level_tgt: np.ndarray | None = None

    def relative(self) -> tuple[np.ndarray, np.ndarray]:
        """The offsets as relative changes of each view's gain ((2, W, C) float32 each), as
        :meth:`SeamOffsets.relative`."""
        return relative_to(self.src, self.level_src), relative_to(self.tgt, self.level_tgt)


def with_seam_offsets(img: np.ndarray, rows: slice, seam_x_canvas: np.ndarray, per_row: np.ndarray,
                      fade_px: float) -> np.ndarray:
    """(R, W, C) float32: rows ``rows`` of a canvas view with the seam blend's offsets ``per_row`` (H, C)
    added as the compositor adds them (full at the seam, fading linearly to 0 at ``fade_px`` > 0)."""
    cols = np.arange(img.shape[1], dtype=np.float32)[None, :]
    weight = lf_weights(cols - seam_x_canvas[rows, None], fade_px)
    return img[rows].astype(np.float32) + weight[:, :, None] * per_row[rows, None, :]


def block_medians(diff: np.ndarray, used: np.ndarray, block: int, mad_limit: float,
                  colour: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Per block of ``block`` columns of a strip: (centres (K,), medians (K, C)) of the differences
    ``diff`` (R, W, C) where ``used`` (R, W): the median of the channel mean in every channel (a
    brightness residual: the gains took the colour), or with ``colour`` each channel's own median. For
    the blocks where at least a third of the strip is used and every channel's median absolute
    deviation of the differences is at most ``mad_limit`` (above it the two views show different
    things there, not one thing at two exposures)."""
    channels = diff.shape[2]
    centres, medians = [], []
    for x0 in range(0, diff.shape[1], block):
        mask = used[:, x0:x0 + block]
        if mask.sum() < mask.size / 3:
            continue
        values = diff[:, x0:x0 + block][mask]
        if np.median(np.abs(values - np.median(values, axis=0)), axis=0).max() > mad_limit:
            continue
        centres.append(x0 + 0.5 * (mask.shape[1] - 1))
        medians.append(np.median(values, axis=0) if colour else np.full(channels, np.median(values.mean(axis=1))))
    return np.asarray(centres), np.asarray(medians).reshape(-1, channels)


def border_offsets(views: CanvasViews, seam_x_canvas: np.ndarray, offsets: SeamOffsets, offset_tgt: tuple[float, float],
                   height_tgt: int, cfg: Config) -> BorderOffsets:
    """Offsets that take half the two views' difference along each of the target's horizontal borders
    off one side and add it to the other, per canvas column, where the panorama switches from the
    target to the source across that border (the target shown inside it, the source going on beyond
    it): from 0 at the seam (where the seam blend has met the views) to the measured difference, fading
    to nothing over ``cfg.seam_blend_rows`` columns where the source does not go on.

    The difference is measured on the ``cfg.seam_blend_strip_px`` rows just inside the border, after
    the seam offsets, as the median of each block of ``cfg.seam_blend_rows`` columns (of the grey
    difference, or with ``cfg.seam_blend_colour`` of each channel's, within ``BLEND_COLOUR_MAX`` of the
    grey one as a ratio), and interpolated between blocks; a block whose views show different things (``block_medians``,
    ``cfg.border_blend_mad_grey``) follows its neighbours. All zero when ``cfg.border_blend`` is off or
    the seam blend is.

    views: the gain-compensated canvas views; seam_x_canvas: (H,) seam x per row; offsets: the seam
    blend's; offset_tgt: the target's (x, y) on the canvas; height_tgt: its rows.
    """
    height, width = views.both.shape
    channels = views.src.shape[2]
    oy = int(round(offset_tgt[1]))
    lines = (oy - 0.5, oy + height_tgt - 0.5)
    zeros = np.zeros((2, width, channels), np.float32)
    levels = np.full((2, 2, width, channels), 255.0, np.float32)  # (view, border, column, channel)
    colour = cfg.seam_blend_gain and cfg.seam_blend_colour
    if not cfg.border_blend or offsets.fade_px <= 0:
        return BorderOffsets(lines, zeros, zeros.copy(), False, *levels)
    strip = max(1, cfg.seam_blend_strip_px)
    block = max(1, cfg.seam_blend_rows)
    inside_rows = (slice(max(oy, 0), min(oy + strip, height)),
                   slice(max(oy + height_tgt - strip, 0), min(oy + height_tgt, height)))
    beyond_rows = (oy - 1, oy + height_tgt)
    seam_x = np.asarray(seam_x_canvas, np.float32)
    cols = np.arange(width)
    delta = zeros.copy()
    for k, (rows, beyond) in enumerate(zip(inside_rows, beyond_rows)):
        if not 0 <= beyond < height or rows.start >= rows.stop:
            continue
        shown_tgt = views.both[rows] & (cols[None, :] > seam_x[rows, None] + 0.5 * cfg.transition_px)
        diff = (with_seam_offsets(views.src, rows, seam_x, offsets.src, offsets.fade_px)
                - with_seam_offsets(views.tgt, rows, seam_x, offsets.tgt, offsets.fade_px))
        used = shown_tgt & views.valid_src[beyond][None, :]
        for side, img in enumerate((views.src, views.tgt)):
            levels[side, k] = column_level(img[rows], used, block, colour)
        centres, medians = block_medians(diff, used, block, cfg.border_blend_mad_grey, colour)
        seam_at = float(seam_x[rows.start if k == 0 else rows.stop - 1])
        if not len(centres) or not np.isfinite(seam_at):
            continue
        right = centres > seam_at  # at the seam the seam blend has met the views already: the offsets start at 0 there
        along = np.stack([np.interp(cols, np.r_[seam_at, centres[right]], np.r_[0.0, medians[right, c]], left=0.0)
                          for c in range(channels)], axis=1)
        goes_on = np.convolve(views.valid_src[beyond].astype(np.float64), np.ones(block) / block, "same")
        if colour:  # each channel within BLEND_COLOUR_MAX (as a ratio) of the grey difference, as the seam's
            grey = along.mean(axis=1, keepdims=True)
            limit = BLEND_COLOUR_MAX * levels[:, k].mean(axis=(0, 2))[:, None]
            along = grey + np.clip(along - grey, -limit, limit)
        delta[k] = along * goes_on[:, None]
    return BorderOffsets(lines, -0.5 * delta, 0.5 * delta, True, *levels)


def column_level(img: np.ndarray, used: np.ndarray, block: int, colour: bool = False) -> np.ndarray:
    """(W, C) float32: the mean grey level of a strip (R, W, C) per column where ``used`` (R, W), in
    every channel, or with ``colour`` each channel's own mean, averaged over ``block`` columns; columns
    without any used pixel near take the nearest that has one (255 where none has)."""
    values = img.astype(np.float32)
    channels = values.shape[2]
    count = used.sum(axis=0)
    if not count.any():
        return np.full((len(count), channels), 255.0, np.float32)
    mean = (values * used[:, :, None]).sum(axis=0) / np.maximum(count, 1)[:, None]
    if not colour:
        mean = np.repeat(mean.mean(axis=1, keepdims=True), channels, axis=1)
    return running_mean(mean, count > 0, block).astype(np.float32)
