"""The seam of every video frame: "cached warps, per-frame seam slicing".

The estimate fixes the maps and a seam; each frame the seam is re-optimised inside a band around it
(``band`` cells each side, ``video_seam_band_ratio`` x the canvas diagonal: room to go round an
object and its second copy) on that frame's luma difference (the compositor's ``band_difference``:
source minus target, gains applied), by the dynamic programming of ``seam_path`` with a temporal term:
a cell costs its difference beyond the noise floor, plus ``video_seam_stay_cost`` per pixel away from
the last frame's seam and ``video_seam_home_cost`` per pixel away from the estimate's.

*Glide and jump.* The seam glides: it moves at most ``video_seam_speed_px`` per line from the last
frame's (one cell where cells are wider). On a static rig, while something is in front of the
background (below), a second path, free in the band, is taken instead when the gliding one would cost
``video_seam_jump_cost`` per line more: something moved across the seam and the seam steps round it
at once. (On a moving rig everything
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
solved on a grid of square cells: along a line every ``cell`` px (:func:`cell_px`: 1 px for inputs
up to 640x480, 2 px for 720p, 3 px for 1080p), on every ``video_seam_line_step``-th line or, where
cells are wider, every cell-th (:func:`line_step`), and interpolated between the solved lines (the
seam blend's transition is wider than the interpolation's rounding). The work per frame so grows
little with the size; the boxes above are counted in cells and solved lines.
"""

from __future__ import annotations

import cv2
import numpy as np
import warp as wp

from ..composite import Compositor
from ..config import Config
from ..partition import running_mean
from ..seam_path import BandPath
from sena_warp.kernels import runtime
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.kernels.frame_seam import background_kernel, band_cost_kernel, strip_mean_kernel

FIT_STRIDE = 4  # the whole band's gain and offset are fitted on every this-th line and cell
SPREAD_FACTOR = 3.0  # a band cell is off its background beyond this x its mean absolute deviation there


def band_half_width(shape: tuple[int, int], cfg: Config) -> int:
    """Band half-width in luma pixels for a canvas of ``shape`` (H, W)."""
    return max(cfg.video_seam_band_min_px, int(round(cfg.video_seam_band_ratio * float(np.hypot(*shape)))))


def cell_px(frame_shapes: tuple[tuple[int, int], ...], cfg: Config) -> int:
    """The per-frame seam's cell width in px for inputs of (rows, cols) ``frame_shapes``: their short
    side in ``video_seam_frame_cells`` cells, so that a cell covers the same share of the scene
    whatever the canvas's shape."""
    short = min(min(shape) for shape in frame_shapes)
    return max(1, int(round(short / max(1, cfg.video_seam_frame_cells))))


def line_step(cell: int, cfg: Config) -> int:
    """The per-frame seam is solved on every this-th line: ``video_seam_line_step``, or the cell
    width where cells are wider (square cells: the grid coarsens with the canvas both ways)."""
    return max(1, cfg.video_seam_line_step, cell)


class FrameSeam:
    """The per-frame seam of one luma compositor whose plan keeps both views within ``band`` of the
    estimate's seam ``home`` (L,) float32 (positions per line), on cells ``cell`` px wide
    (:func:`cell_px`); ``jumps``: whether it may leave its gliding path and keeps a background model (a
    static rig); ``fps``: the video's frame rate.

    The seam is solved on every ``step``-th line (:func:`line_step`, and the last) and interpolated
    between them; ``positions``, ``shown`` and ``still`` are per line. The band's cells live in Warp
    arrays (K solved lines, ``width`` cells) that the kernels of ``kernels/frame_seam.py`` fill (on
    ``runtime.BAND_THREADS`` CPU threads)."""

    def __init__(self, home: np.ndarray, band: int, cell: int, jumps: bool, fps: float, cfg: Config):
        self.cfg = cfg
        self.jumps = jumps
        self.band = band
        self.cell = cell
        self.width = 2 * int(np.ceil(band / self.cell)) + 1  # cells
        count = len(home)
        self._every_line = np.arange(count)
        box = 2 * max(1, cfg.video_seam_still_box_px) + 1
        self._object_box = (box, np.ones((box, box), np.uint8))  # an object's box (``foreground``): size, kernel
        self.step = line_step(self.cell, cfg)
        step = self.step
        self._lines = np.unique(np.append(np.arange(0, count, step), count - 1)).astype(np.int32)
        solved = len(self._lines)
        self._solved = np.arange(solved)
        self._max_step = int(np.ceil(cfg.seam_max_step_px * step / self.cell))  # cells between solved lines
        self._step_cost = cfg.seam_step_cost * self.cell  # per cell of sideways step
        segment = np.array([[0, solved - 1, -1, -1]])  # one, free at both ends
        self._solver = BandPath(solved, self.width, segment, cfg)
        self._speed = max(cfg.video_seam_speed_px, self.cell)  # px a frame: at least one cell, or it could not glide
        self._glide_width = min(self.width, 2 * int(np.ceil(self._speed / self.cell)) + 1)
        self._glide_solver = BandPath(solved, self._glide_width, segment, cfg)
        device, cells = cfg.device, (solved, self.width)
        self._lines_wp = wp.array(self._lines, dtype=int, device=device)
        self._x0_wp = wp.zeros(solved, dtype=int, device=device)  # the band's first cells, per reset
        self._diff = wp.zeros(cells, dtype=float, device=device)  # this frame's difference and sum
        self._total = wp.zeros(cells, dtype=float, device=device)
        self._last_diff = wp.zeros(cells, dtype=float, device=device)  # the last frame's difference
        self._delta = wp.zeros(cells, dtype=float, device=device)  # how much it changed since
        self._learn = 1.0 / max(1.0, fps * cfg.video_seam_background_s)  # the background's update per frame
        self._background = wp.zeros(cells, dtype=float, device=device)  # source-plus-target luma of the background
        self._spread = wp.zeros(cells, dtype=float, device=device)  # its mean absolute deviation
        self._off = wp.zeros(cells, dtype=wp.uint8, device=device)  # 1: off the background this frame
        self._moving = wp.zeros(cells, dtype=wp.uint8, device=device)  # 1: something in front (a static rig's)
        self._home_term = wp.zeros(cells, dtype=float, device=device)  # the cost of leaving home, per reset
        self._last_wp = wp.zeros(solved, dtype=int, device=device)  # the last frame's seam, per solved line
        self._still_wp = wp.zeros(solved, dtype=wp.uint8, device=device)
        self._change = wp.zeros(cells, dtype=float, device=device)  # a cell's cost without the seam's terms
        self._free_cost = wp.zeros(cells, dtype=float, device=device)  # ... with them: the free path's
        self._glide_first = wp.zeros(solved, dtype=int, device=device)  # the glide's first cells
        self._glide_cost = wp.zeros((solved, self._glide_width), dtype=float, device=device)  # ... its cost
        self._line_min = wp.zeros(solved, dtype=float, device=device)  # each line's cheapest cell
        self._path_wp = wp.zeros(solved, dtype=int, device=device)  # this frame's seam, for the strip's mean
        self._strip_mean = wp.zeros(solved, dtype=float, device=device)  # the seam blend's difference by the seam
        self._strip_count = wp.zeros(solved, dtype=int, device=device)
        self._modelled = False  # whether the background model holds this estimate's band
        self._shown: np.ndarray | None = None  # (K,) the solved lines' seam the last frame was composited with
        self._has_last = False  # whether ``_last_diff`` holds the last frame's difference on this band
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
        runtime.upload(self._x0_wp, self._x0)
        self._cells = self._x0[:, None] + self.cell * np.arange(self.width, dtype=np.int32)[None, :]
        runtime.upload(self._home_term, self.cfg.video_seam_home_cost
                       * np.abs(self._cells - self.home[self._lines, None]))
        self._has_last = False  # the band's cells moved: the last difference no longer lines up
        self._modelled = False
        self._path = self._on_grid(self.home[self._lines] if self._path is None else self._path)

    def _on_grid(self, path: np.ndarray) -> np.ndarray:
        """(K,) int32 the band cells' positions nearest to ``path`` (K,) px on the solved lines."""
        nearest = self._x0 + self.cell * np.rint((np.asarray(path, np.float64) - self._x0) / self.cell)
        return np.clip(nearest, self._x0, self._cells[:, -1]).astype(np.int32)

    def _solve_band(self, solver: BandPath, cost: wp.array, x0: np.ndarray) -> np.ndarray:
        """(K,) int32 positions (px) of the cheapest path through ``cost`` (K, cells; a Warp array) whose cells start
        at ``x0`` (K,) px on the grid of cells."""
        first = x0 // self.cell
        return (solver.solve(cost, first, self._max_step, self._step_cost) * self.cell).astype(np.int32)

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
        return np.interp(self._every_line, self._lines, self._still.astype(np.float64)) == 1.0

    def _per_line(self, path: np.ndarray) -> np.ndarray:
        return np.rint(np.interp(self._every_line, self._lines, path)).astype(np.int32)

    def next(self, luma: Compositor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seam of the frame loaded in ``luma`` and its seam blend's offsets (``band_offsets``):
        (positions (L,) int32, offsets off the source (L, 1), onto the target (L, 1) float32)."""
        self._diff, self._last_diff = self._last_diff, self._diff  # this frame's fills the older
        luma.band_difference(self._lines_wp, self._x0_wp, self.width, self.cell, self._last_diff, self._diff,
                             self._total, self._delta)
        self._still = self.still_lines()
        self._has_last = True
        last = self._path if self._shown is None else self._shown
        if not self._still.all():  # else nothing changed on any line: the seam and the background model stay
            moving = self.foreground(self._diff, self._total) if self.jumps else None
            self._path = self._solve(moving, last)
        self._shown = self._path.copy()
        runtime.upload(self._path_wp, self._path)
        runtime.launch_rows(strip_mean_kernel, len(self._lines), 1, [
            self._diff, self._x0_wp, self.cell, self._path_wp, self.cfg.seam_blend_strip_px // self.cell,
            self._strip_mean, self._strip_count], self.cfg.device, runtime.BAND_THREADS)
        offsets_src, offsets_tgt = band_offsets(self._strip_mean.numpy(), self._strip_count.numpy(), self._lines,
                                                self.step, self.cfg)
        return self.positions, offsets_src, offsets_tgt

    def _solve(self, moving: np.ndarray | None, last: np.ndarray) -> np.ndarray:
        """The solved lines' new path (module docstring); ``moving``: the cells in front of the
        background (``foreground``), None on a moving rig.

        The glide moves at most ``video_seam_speed_px`` (or one cell) per solved line from ``last`` (K,)
        and not at all on still lines: it is solved on the few cells it may take, from ``first``."""
        cfg = self.cfg
        first = np.clip((last - self._x0) // self.cell - self._glide_width // 2, 0, self.width - self._glide_width)
        runtime.upload(self._last_wp, last)
        runtime.upload(self._still_wp, self._still)
        runtime.upload(self._glide_first, first)
        runtime.launch_rows(band_cost_kernel, len(self._lines), 1, [
            self._diff, self._moving, self._home_term, self._x0_wp, self.cell, self._last_wp, self._still_wp,
            self._glide_first, float(self._speed), float(cfg.video_seam_noise), float(cfg.video_seam_motion_cost),
            float(cfg.video_seam_blocked_cost), float(cfg.video_seam_stay_cost),
            float(cfg.video_seam_blocked_cost * 10),  # a blocked cell; still lines keep their seam
            self._change, self._free_cost, self._glide_cost, self._line_min], cfg.device, runtime.BAND_THREADS)
        change = self._change.numpy()
        glide = self._solve_band(self._glide_solver, self._glide_cost, self._x0 + self.cell * first)
        def along(path: np.ndarray) -> float:
            return float(change[self._solved, (path - self._x0) // self.cell].sum())

        limit = len(self._lines)
        path = glide
        jump = cfg.video_seam_jump_cost * limit
        # Something in front of the background, and a path cheaper than the glide's by a jump may exist
        # (no path costs less than each line's cheapest cell): it may jump round it.
        if moving is not None and moving.any() and along(glide) - float(self._line_min.numpy().sum()) > jump:
            free = self._solve_band(self._solver, self._free_cost, self._x0)
            path = free if along(glide) - along(free) > jump else glide
        if along(self._path) - along(path) > cfg.video_seam_margin * limit:
            return path.astype(np.int32)
        return self._path

    def foreground(self, diff: wp.array, total: wp.array) -> np.ndarray:
        """(K, width) uint8 over the solved lines' band (its difference ``diff`` and source-plus-target
        ``total``, Warp arrays as ``band_difference`` fills them), 1 on cells off the background model
        (module docstring), grown by ``video_seam_still_box_px``; none on the first frame of an estimate.
        Updates the model."""
        if diff.shape != self._background.shape or total.shape != self._background.shape:
            raise ValueError(f"band of {diff.shape} / {total.shape} cells for a model of {self._background.shape}")
        noise = np.float32(2.0 * self.cfg.video_seam_noise)
        if not self._modelled:
            wp.copy(self._background, total)
            self._spread.fill_(float(noise / SPREAD_FACTOR))
            self._modelled = True
        fit = (slice(None, None, FIT_STRIDE),) * 2
        gain, offset = whole_band_fit(self._background.numpy()[fit], total.numpy()[fit],
                                      diff.numpy()[fit] < 0.5 * NOT_BOTH, float(noise))
        runtime.launch_row_loops(background_kernel, len(self._lines), self.width, [
            diff, total, float(np.float32(gain - 1.0)), float(np.float32(offset)), float(noise), SPREAD_FACTOR,
            float(np.float32(self._learn)), self._background, self._spread, self._off], self.cfg.device,
            runtime.BAND_THREADS)
        box, kernel = self._object_box
        solid = (cv2.blur(self._off.numpy(), (box, box)) > 0).view(np.uint8)
        moving = cv2.dilate(solid, kernel)
        runtime.upload(self._moving, moving)
        return moving

    def still_lines(self) -> np.ndarray:
        """(K,) bool: solved lines where nothing changed since the last frame (module docstring), from the
        band's difference loaded by ``band_difference``; none without a last frame."""
        if not self._has_last:
            return np.zeros(len(self._lines), bool)
        box = max(1, self.cfg.video_seam_still_box_px)
        moved = (cv2.blur(self._delta.numpy(), (box, box)) > self.cfg.video_seam_noise).any(axis=1)
        return ~lines_near(moved, int(np.ceil(self.width * self.cell / self.step)))


def whole_band_fit(background: np.ndarray, total: np.ndarray, both: np.ndarray, noise: float) -> tuple[float, float]:
    """(gain, offset): how ``total`` changed from ``background`` over the whole band (a camera's exposure
    step, a flickering light): their least-squares fit on the cells in ``both`` (the caller takes every
    :data:`FIT_STRIDE`-th line and cell), fitted again without the cells more than ``noise`` (and twice
    the median residual) off the first fit (an object in front). ``(gain - 1) x background + offset``
    is the change they explain."""
    x = background[both].astype(np.float64)
    y = total[both].astype(np.float64)
    gain, offset = _gain_offset(x, y)
    residual = np.abs(y - gain * x - offset)
    kept = residual <= max(noise, 2.0 * float(np.median(residual))) if residual.size else residual > 0
    return _gain_offset(x[kept], y[kept])


def _gain_offset(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least squares y = gain x + offset; gain 1 where x does not vary, (1, 0) without points."""
    if x.size == 0:
        return 1.0, 0.0
    x_mean, y_mean = x.sum() / x.size, y.sum() / y.size
    dx = x - x_mean
    x_var = float(dx @ dx) / x.size
    if x.size < 2 or x_var <= 1e-6:
        return 1.0, float(y_mean - x_mean)
    gain = float(dx @ (y - y_mean)) / x.size / x_var
    return gain, float(y_mean - gain * x_mean)


def lines_near(flags: np.ndarray, reach: int) -> np.ndarray:
    """(L,) bool: the lines within ``reach`` lines of a flagged one (``flags`` (L,) bool)."""
    count = np.concatenate([[0], np.cumsum(flags, dtype=np.int64)])
    lines = np.arange(len(flags))
    return count[np.minimum(lines + reach + 1, len(flags))] > count[np.maximum(lines - reach, 0)]


def band_offsets(strip_mean: np.ndarray, strip_count: np.ndarray, lines: np.ndarray, step: int,
                 cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """The seam blend's low-frequency offsets of one frame (``partition.seam_offsets`` on the band): per
    solved line (seam line ``lines`` (K,), ascending, the last line last, every ``step``-th), half the
    mean difference next to the seam (``strip_mean`` (K,) over ``strip_count`` (K,) cells within
    ``seam_blend_strip_px`` of it: ``strip_mean_kernel``), averaged over ``seam_blend_rows`` lines, off
    the source and onto the target, interpolated to every line: ((L, 1), (L, 1)) float32."""
    solved = running_mean(strip_mean[:, None], strip_count > 0, max(1, round(cfg.seam_blend_rows / step)))[:, 0]
    delta = np.interp(np.arange(int(lines[-1]) + 1), lines, solved).astype(np.float32)[:, None]
    return -0.5 * delta, 0.5 * delta
