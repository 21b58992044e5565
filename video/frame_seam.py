"""The seam of every video frame (issue 14): "cached warps, per-frame seam slicing".

The estimate fixes the maps and a seam; each frame the seam is re-optimised inside a band around it
(``band`` cells each side, ``video_seam_band_ratio`` x the canvas diagonal: room to go round an
object and its second copy) on that frame's luma difference (the compositor's ``band_difference``:
source minus target, gains applied), by the dynamic programming of ``seam_path`` with a temporal term:
a cell costs its difference beyond the noise floor, plus ``video_seam_stay_cost`` per pixel away from
the last frame's seam and ``video_seam_home_cost`` per pixel away from the estimate's.

*Glide and jump.* The seam glides: it moves at most ``video_seam_speed_px`` per line from the last
frame's. On a static rig, while something is in front of the background (below), a second path, free
in the band, is taken instead when the gliding one would cost ``video_seam_jump_cost`` per line more:
something moved across the seam and the seam steps round it at once. (On a moving rig everything
shifts a little every frame; there the seam only glides.) A new path replaces the last one only when
it is cheaper by ``video_seam_margin`` per line: while nothing moves the costs only carry noise.

*Still lines.* A line is still when no box of ``video_seam_still_box_px`` cells of the band's
difference changed by more than ``video_seam_noise`` since the last frame on it or within a band's
width of lines (room for the path to leave and come back); there every cell but the last frame's
seam is blocked, and a frame whose lines are all still solves nothing.

*In front of the background* (static rigs). The band keeps a background model: each cell's
source-plus-target luma as a running mean with time constant ``video_seam_background_s``, and its
mean absolute deviation. A cell is in front when it is off the model by more than twice the noise and
three deviations (leaves in the wind and a drifting camera's edges keep changing), beyond what one
gain and offset over the whole band explain (a camera's exposure step, a flickering light), in most
of a box twice ``video_seam_still_box_px`` wide (an object, not thin edges). Such cells cost
``video_seam_motion_cost`` more, so the seam goes round a moving object whole (both its copies), not
only round where the views differ: inside a smooth object its two copies differ little, and a seam
through it would lose a strip of it.

Only the compositor's seam positions and the seam blend's offsets change per frame; its plan stays.
Positions are per seam line of the luma plane (canvas rows, or columns for a vertical rig). The seam is
solved on every ``video_seam_line_step``-th line and interpolated between (half the work at 2; the
seam blend's transition is wider than the interpolation's rounding), and along a line on a grid of
cells ``cell`` px apart (:func:`cell_px`: 1 px on a 640-px pair's canvas, 2 px on a 720p pair's or a
1080p one's), so the work per frame grows less with the size; the boxes above are counted in cells.
"""

from __future__ import annotations

import cv2
import numpy as np
import warp as wp

from ..composite import Compositor
from ..config import Config
from ..partition import running_mean
from ..seam_path import BandPath
from sena_warp.kernels.composite import NOT_BOTH

FIT_STRIDE = 4  # the whole band's gain and offset are fitted on every this-th line and cell
SPREAD_FACTOR = 3.0  # a band cell is off its background beyond this x its mean absolute deviation there


def band_half_width(shape: tuple[int, int], cfg: Config) -> int:
    """Band half-width in luma pixels for a canvas of ``shape`` (H, W)."""
    return max(cfg.video_seam_band_min_px, int(round(cfg.video_seam_band_ratio * float(np.hypot(*shape)))))


def cell_px(band: int, cfg: Config) -> int:
    """The per-frame seam's cell width in px for a band half-width of ``band`` px: about
    ``video_seam_band_cells`` cells each side of the seam."""
    return max(1, int(round(band / max(1, cfg.video_seam_band_cells))))


class FrameSeam:
    """The per-frame seam of one luma compositor whose plan keeps both views within ``band`` of the
    estimate's seam ``home`` (L,) float32 (positions per line); ``jumps``: whether it may leave its
    gliding path and keeps a background model (a static rig); ``fps``: the video's frame rate.

    The seam is solved on every ``video_seam_line_step``-th line (and the last) and interpolated
    between them; ``positions``, ``shown`` and ``still`` are per line."""

    def __init__(self, home: np.ndarray, band: int, jumps: bool, fps: float, cfg: Config):
        self.cfg = cfg
        self.jumps = jumps
        self.band = band
        self.cell = cell_px(band, cfg)
        self.width = 2 * int(np.ceil(band / self.cell)) + 1  # cells
        count = len(home)
        step = max(1, cfg.video_seam_line_step)
        self._lines = np.unique(np.append(np.arange(0, count, step), count - 1)).astype(np.int32)
        solved = len(self._lines)
        self._max_step = int(np.ceil(cfg.seam_max_step_px * step / self.cell))  # cells between solved lines
        self._step_cost = cfg.seam_step_cost * self.cell  # per cell of sideways step
        self._solver = BandPath(solved, self.width, 1, cfg)
        self._glide_width = min(self.width, 2 * int(np.ceil(cfg.video_seam_speed_px / self.cell)) + 1)
        self._glide_solver = BandPath(solved, self._glide_width, 1, cfg)
        self._segment = np.array([[0, solved - 1, -1, -1]])
        self._lines_wp = wp.array(self._lines, dtype=int, device=cfg.device)
        self._x0_wp = wp.zeros(solved, dtype=int, device=cfg.device)  # the band's first cells, per reset
        self._diff = wp.zeros((solved, self.width), dtype=float, device=cfg.device)
        self._total = wp.zeros((solved, self.width), dtype=float, device=cfg.device)
        self._learn = 1.0 / max(1.0, fps * cfg.video_seam_background_s)  # the background's update per frame
        self._background: np.ndarray | None = None  # (K, width) source-plus-target luma of the background
        self._spread: np.ndarray | None = None  # (K, width) its mean absolute deviation
        self._shown: np.ndarray | None = None  # (K,) the solved lines' seam the last frame was composited with
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # the last frame's (difference, both)
        self._still = np.zeros(solved, bool)  # the solved lines the last frame found still (``still_lines``)
        self.home: np.ndarray | None = None  # (L,) the estimate's seam, the band's centre (``reset``)
        self._path: np.ndarray | None = None  # (K,) the solved lines' seam (px, on the grid of cells)
        self.reset(home)

    def reset(self, home: np.ndarray) -> None:
        """A new estimate's seam: the band follows it; the last path is kept where it still fits. The
        glide still starts from the seam last shown (``shown``), so a band that moves with a blend does
        not add its own step to the seam's. A seam that did not move (a static rig's maps moved with a
        camera's drift) keeps its band, its last difference and its background model: the band's
        content moved by a pixel or two, which the model's own learning follows."""
        home = np.asarray(home, np.float32)
        if self.home is not None and np.array_equal(home, self.home):
            return
        self.home = home
        half = self.width // 2
        self._x0 = ((np.floor_divide(np.rint(self.home[self._lines]).astype(np.int32), self.cell) - half)
                    * self.cell).astype(np.int32)  # on the grid of cells, so cells line up from line to line
        self._x0_wp.assign(self._x0)
        self._cells = self._x0[:, None] + self.cell * np.arange(self.width, dtype=np.int32)[None, :]
        self._home_term = (self.cfg.video_seam_home_cost
                           * np.abs(self._cells - self.home[self._lines, None])).astype(np.float32)
        self._last = None  # the band's cells moved: the last difference no longer lines up
        self._background = None
        self._path = self._on_grid(self.home[self._lines] if self._path is None else self._path)

    def _on_grid(self, path: np.ndarray) -> np.ndarray:
        """(K,) int32 the band cells' positions nearest to ``path`` (K,) px on the solved lines."""
        nearest = self._x0 + self.cell * np.rint((np.asarray(path, np.float64) - self._x0) / self.cell)
        return np.clip(nearest, self._x0, self._cells[:, -1]).astype(np.int32)

    def _solve_band(self, solver: BandPath, cost: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """(K,) int32 positions (px) of the cheapest path through ``cost`` (K, cells) whose cells start
        at ``x0`` (K,) px on the grid of cells."""
        first = x0 // self.cell
        return (solver.solve(cost, first, self._segment, self._max_step, self._step_cost) * self.cell).astype(np.int32)

    @property
    def positions(self) -> np.ndarray:
        """(L,) int32 the seam per line (the solved lines' path, interpolated)."""
        return self._per_line(self._path)

    @property
    def shown(self) -> np.ndarray | None:
        """(L,) int32 the seam the last frame was composited with, or None before the first frame."""
        return None if self._shown is None else self._per_line(self._shown)

    @property
    def still(self) -> np.ndarray:
        """(L,) bool the lines the last frame found still (both solved lines around them still)."""
        lines = np.arange(len(self.home))
        return np.interp(lines, self._lines, self._still.astype(np.float64)) == 1.0

    def _per_line(self, path: np.ndarray) -> np.ndarray:
        return np.rint(np.interp(np.arange(len(self.home)), self._lines, path)).astype(np.int32)

    def next(self, luma: Compositor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seam of the frame loaded in ``luma`` and its seam blend's offsets (``band_offsets``):
        (positions (L,) int32, offsets off the source (L, 1), onto the target (L, 1) float32)."""
        cfg = self.cfg
        diff, total = luma.band_difference(self._lines_wp, self._x0_wp, self.width, self._diff, self._total,
                                           self.cell)
        both = diff < 0.5 * NOT_BOTH
        self._still = self.still_lines(diff, both)
        self._last = (diff.copy(), both)
        last = self._path if self._shown is None else self._shown
        if not self._still.all():  # else nothing changed on any line: the seam and the background model stay
            moving = self.foreground(total, both) if self.jumps else None
            self._path = self._solve(diff, both, moving, last)
        self._shown = self._path.copy()
        offsets_src, offsets_tgt = band_offsets(self._path, self._cells, diff, both, self._lines, cfg)
        return self.positions, offsets_src, offsets_tgt

    def _solve(self, diff: np.ndarray, both: np.ndarray, moving: np.ndarray | None, last: np.ndarray) -> np.ndarray:
        """The solved lines' new path (module docstring)."""
        cfg = self.cfg
        change = np.maximum(np.abs(diff) - np.float32(cfg.video_seam_noise), np.float32(0.0))
        if moving is not None:
            change += np.float32(cfg.video_seam_motion_cost) * moving
        change[~both] = cfg.video_seam_blocked_cost
        cost = change + self._home_term
        cost += np.float32(cfg.video_seam_stay_cost) * np.abs(self._cells - last[:, None]).astype(np.float32)
        glide = self._glide(cost, last)
        lines = np.arange(len(self._lines))

        def along(path: np.ndarray) -> float:
            return float(change[lines, (path - self._x0) // self.cell].sum())

        limit = len(lines)
        path = glide
        jump = cfg.video_seam_jump_cost * limit
        # Something in front of the background, and a path cheaper than the glide's by a jump may exist
        # (no path costs less than each line's cheapest cell): it may jump round it.
        if moving is not None and moving.any() and along(glide) - float(change.min(axis=1).sum()) > jump:
            block = np.float32(cfg.video_seam_blocked_cost * 10)
            cost[self._still[:, None] & (self._cells != last[:, None])] += block  # still lines keep their seam
            free = self._solve_band(self._solver, cost, self._x0)
            path = free if along(glide) - along(free) > jump else glide
        if along(self._path) - along(path) > cfg.video_seam_margin * limit:
            return path.astype(np.int32)
        return self._path

    def _glide(self, cost: np.ndarray, last: np.ndarray) -> np.ndarray:
        """The cheapest path through ``cost`` (K, width) that moves at most ``video_seam_speed_px`` per
        solved line from ``last`` (K,) and not at all on still lines, solved on the few cells it may take."""
        cfg = self.cfg
        reach = self._glide_width // 2
        first = np.clip((last - self._x0) // self.cell - reach, 0, self.width - self._glide_width)
        taken = first[:, None] + np.arange(self._glide_width)[None, :]
        glide_x0 = (self._x0 + self.cell * first).astype(np.int32)
        cells = np.take_along_axis(self._cells, taken, axis=1)
        # Where the band has moved past the last seam (rounding of a blend's step), its nearest cell is near enough.
        outside = np.maximum(np.maximum(self._x0 - last, last - self._cells[:, -1]), 0)
        far = np.abs(cells - last[:, None]) > np.maximum(cfg.video_seam_speed_px, outside)[:, None]
        blocked = far | (self._still[:, None] & (cells != last[:, None]))
        sub = np.take_along_axis(cost, taken, axis=1) + blocked * np.float32(cfg.video_seam_blocked_cost * 10)
        return self._solve_band(self._glide_solver, sub, glide_x0)

    def foreground(self, total: np.ndarray, both: np.ndarray) -> np.ndarray:
        """(K, width) float32 over the solved lines' band ``total`` (source plus target), 1 on cells off
        the background model (module docstring), grown by ``video_seam_still_box_px``; none on the first
        frame of an estimate. Updates the model."""
        noise = np.float32(2.0 * self.cfg.video_seam_noise)
        if self._background is None:
            self._background = total.copy()
            self._spread = np.full(total.shape, noise / SPREAD_FACTOR, np.float32)
        change = total - self._background
        change[~both] = 0.0
        deviation = np.abs(change - whole_band_change(self._background, total, both, float(noise)))
        off = both & (deviation > np.maximum(noise, np.float32(SPREAD_FACTOR) * self._spread))
        learn = np.float32(self._learn)
        self._background += learn * change
        deviation -= self._spread
        deviation[~both] = 0.0
        self._spread += learn * deviation
        box = 2 * max(1, self.cfg.video_seam_still_box_px) + 1
        solid = (cv2.blur(off.view(np.uint8), (box, box)) > 0).view(np.uint8)
        return cv2.dilate(solid, np.ones((box, box), np.uint8)).astype(np.float32)

    def still_lines(self, diff: np.ndarray, both: np.ndarray) -> np.ndarray:
        """(K,) bool: solved lines where nothing changed since the last frame (module docstring); none
        without one."""
        if self._last is None:
            return np.zeros(len(diff), bool)
        last_diff, last_both = self._last
        common = both & last_both
        delta = np.where(common, np.abs(diff - last_diff), 0.0).astype(np.float32)
        box = max(1, self.cfg.video_seam_still_box_px)
        moved = (cv2.blur(delta, (box, box)) > self.cfg.video_seam_noise).any(axis=1)
        return ~lines_near(moved, int(np.ceil(self.width * self.cell / max(1, self.cfg.video_seam_line_step))))


def whole_band_change(background: np.ndarray, total: np.ndarray, both: np.ndarray, noise: float) -> np.ndarray:
    """(L, width) float32 the change of ``total`` from ``background`` that a gain and an offset over the
    whole band explain (a camera's exposure step, a flickering light): their least-squares fit on the
    cells in ``both``, every :data:`FIT_STRIDE`-th line and cell, fitted again without the cells more
    than ``noise`` (and twice the median residual) off the first fit (an object in front)."""
    fit = both[::FIT_STRIDE, ::FIT_STRIDE]
    x = background[::FIT_STRIDE, ::FIT_STRIDE][fit].astype(np.float64)
    y = total[::FIT_STRIDE, ::FIT_STRIDE][fit].astype(np.float64)
    gain, offset = _gain_offset(x, y)
    residual = np.abs(y - gain * x - offset)
    kept = residual <= max(noise, 2.0 * float(np.median(residual))) if residual.size else residual > 0
    gain, offset = _gain_offset(x[kept], y[kept])
    return np.float32(gain - 1.0) * background + np.float32(offset)


def _gain_offset(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least squares y = gain x + offset; gain 1 where x does not vary, (1, 0) without points."""
    if x.size == 0:
        return 1.0, 0.0
    if x.size < 2 or x.var() <= 1e-6:
        return 1.0, float(y.mean() - x.mean())
    gain = float(np.mean((x - x.mean()) * (y - y.mean())) / x.var())
    return gain, float(y.mean() - gain * x.mean())


def lines_near(flags: np.ndarray, reach: int) -> np.ndarray:
    """(L,) bool: the lines within ``reach`` lines of a flagged one (``flags`` (L,) bool)."""
    count = np.concatenate([[0], np.cumsum(flags, dtype=np.int64)])
    lines = np.arange(len(flags))
    return count[np.minimum(lines + reach + 1, len(flags))] > count[np.maximum(lines - reach, 0)]


def band_offsets(path: np.ndarray, cells: np.ndarray, diff: np.ndarray, both: np.ndarray, lines: np.ndarray,
                 cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """The seam blend's low-frequency offsets of one frame (``partition.seam_offsets`` on the band):
    per solved line (seam line ``lines`` (K,), ascending, the last line last), half the mean
    difference ``diff`` (K, width) within ``seam_blend_strip_px`` of the seam ``path`` (K,) (the band
    cells' positions ``cells`` (K, width)), averaged over ``seam_blend_rows`` lines, off the source and
    onto the target, interpolated to every line: ((L, 1), (L, 1)) float32."""
    strip = both & (np.abs(cells - path[:, None]) <= cfg.seam_blend_strip_px)
    count = strip.sum(axis=1)
    per_line = np.where(strip, diff, 0.0).sum(axis=1) / np.maximum(count, 1)
    step = max(1, cfg.video_seam_line_step)
    solved = running_mean(per_line[:, None], count > 0, max(1, round(cfg.seam_blend_rows / step)))[:, 0]
    delta = np.interp(np.arange(int(lines[-1]) + 1), lines, solved).astype(np.float32)[:, None]
    return -0.5 * delta, 0.5 * delta
