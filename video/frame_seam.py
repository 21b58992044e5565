"""The seam of every video frame: "cached warps, per-frame seam slicing".

The estimate fixes the maps and a seam; each frame the seam is re-optimised inside a band around it
(``band`` cells each side, ``video_seam_band_ratio`` x the canvas diagonal: room to go round an
object and its second copy) on that frame's luma difference (``composite.band_difference`` on the
frame's device, source minus target, gains applied, downloaded as one small :class:`BandFrame`), by
the dynamic programming of ``seam_path`` with a temporal term:
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

All of it runs on the host, on the band's few thousand cells (``kernels/frame_seam.py`` on Warp's
CPU device, numpy, OpenCV); the frame's seam and the seam blend's offsets go back to the device in
one small block, the plan stays. Positions are per seam line of the luma plane (canvas rows, or
columns for a vertical rig). The seam is
solved on a grid of square cells: along a line every ``cell`` px (:func:`cell_px`: 1 px for inputs
up to 640x480, 2 px for 720p, 3 px for 1080p), on every ``video_seam_line_step``-th line or, where
cells are wider, every cell-th (:func:`line_step`), and interpolated between the solved lines (the
seam blend's transition is wider than the interpolation's rounding). The work per frame so grows
little with the size; the boxes above are counted in cells and solved lines.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import warp as wp

from ..config import Config
from ..partition import running_mean
from ..seam_path import BandPath, separation_spans
from sena_warp.kernels import runtime
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.kernels.frame_seam import (DEVICE, BackgroundModel, CellCosts, LastSeam, SeamCosts, background_kernel,
                                          band_cost_kernel, strip_mean_kernel)
from sena_warp.kernels.transfer import host_array

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


@dataclass(frozen=True)
class BandGrid:
    """The band's cells, fixed for a video: ``lines`` (K,) int32 the solved seam lines (every ``step``-th
    of the ``count`` lines, and the last), ``width`` cells of ``cell`` px each; a path moves at most
    ``max_step`` cells between solved lines, at ``step_cost`` per cell; it glides at most ``speed`` px
    a frame, on ``glide_width`` cells; ``box``: an object's box (``FrameSeam.foreground``), in cells."""

    count: int
    lines: np.ndarray
    cell: int
    width: int
    step: int
    max_step: int
    step_cost: float
    speed: float
    glide_width: int
    box: int

    @staticmethod
    def of(count: int, band: int, cell: int, cfg: Config) -> "BandGrid":
        """The grid of ``count`` seam lines whose band reaches ``band`` px each side, cells ``cell`` px."""
        width = 2 * int(np.ceil(band / cell)) + 1
        step = line_step(cell, cfg)
        lines = np.unique(np.append(np.arange(0, count, step), count - 1)).astype(np.int32)
        speed = max(cfg.video_seam_speed_px, cell)  # px a frame: at least one cell, or it could not glide
        return BandGrid(count, lines, cell, width, step, int(np.ceil(cfg.seam_max_step_px * step / cell)),
                        cfg.seam_step_cost * cell, speed, min(width, 2 * int(np.ceil(speed / cell)) + 1),
                        2 * max(1, cfg.video_seam_still_box_px) + 1)

    @property
    def shape(self) -> tuple[int, int]:
        """(solved lines, cells): the shape of the band's per-cell arrays."""
        return len(self.lines), self.width


@dataclass(frozen=True)
class BandPlace:
    """Where the band lies for one estimate's seam ``home`` (L,) float32: each solved line's first cell
    ``x0`` (K,) int32 px, on the grid of cells so that cells line up from line to line, every cell's
    position ``cells`` (K, width), and the cost of leaving home per cell ``home_term`` (K, width)
    float32 (with its Warp view on the host, as the kernels take it)."""

    home: np.ndarray
    x0: np.ndarray
    cells: np.ndarray
    home_term: np.ndarray
    x0_wp: wp.array
    home_term_wp: wp.array

    @staticmethod
    def of(home: np.ndarray, grid: BandGrid, cfg: Config) -> "BandPlace":
        half = grid.width // 2
        x0 = ((np.floor_divide(np.rint(home[grid.lines]).astype(np.int32), grid.cell) - half) * grid.cell
              ).astype(np.int32)
        cells = x0[:, None] + grid.cell * np.arange(grid.width, dtype=np.int32)[None, :]
        home_term = np.empty(grid.shape, np.float32)
        np.copyto(home_term, cfg.video_seam_home_cost * np.abs(cells - home[grid.lines, None]), casting="unsafe")
        return BandPlace(home, x0, cells, home_term, host_array(x0, int), host_array(home_term, float))


@dataclass(frozen=True)
class BandFrame:
    """One frame's band, as ``composite.band_difference`` gives it: per solved line and cell, the source
    minus the target (``diff``, ``NOT_BOTH`` where a cell lacks a view), their sum (``total``) and how
    much ``diff`` changed since the last frame (``delta``), each (K, width) float32 on the host, with
    Warp views of the first two for the host kernels."""

    diff: np.ndarray
    total: np.ndarray
    delta: np.ndarray
    diff_wp: wp.array
    total_wp: wp.array

    @staticmethod
    def of(diff: np.ndarray, total: np.ndarray, delta: np.ndarray) -> "BandFrame":
        """The band over host arrays (float32, C-ordered), used in place."""
        return BandFrame(diff, total, delta, host_array(diff, float), host_array(total, float))


class BandModel:
    """The band's background model (module docstring), for static rigs: per cell the source-plus-target
    luma of the background and its mean absolute deviation (``kernels/frame_seam.py``'s
    ``BackgroundModel``), learnt at the rate of ``video_seam_background_s`` at ``fps``."""

    def __init__(self, grid: BandGrid, fps: float, cfg: Config):
        self.noise = np.float32(2.0 * cfg.video_seam_noise)
        self.modelled = False  # whether the model holds the band's current place
        self._arrays = [np.zeros(grid.shape, np.float32), np.zeros(grid.shape, np.float32),
                        np.zeros(grid.shape, np.uint8)]  # background, spread, off
        model = BackgroundModel()
        model.background, model.spread = (host_array(a, float) for a in self._arrays[:2])
        model.off = host_array(self._arrays[2], wp.uint8)
        model.noise, model.spread_factor = float(self.noise), SPREAD_FACTOR
        model.learn = float(np.float32(1.0 / max(1.0, fps * cfg.video_seam_background_s)))
        self.kernel = model
        self._box = (grid.box, np.ones((grid.box, grid.box), np.uint8))

    def foreground(self, band: BandFrame) -> np.ndarray:
        """(K, width) uint8 1 on cells off the model in ``band`` (module docstring), grown by
        ``video_seam_still_box_px``; none on the first frame of a place. Updates the model."""
        background, spread, off = self._arrays
        if band.diff.shape != background.shape or band.total.shape != background.shape:
            raise ValueError(f"band of {band.diff.shape} / {band.total.shape} cells for a model of {background.shape}")
        if not self.modelled:
            np.copyto(background, band.total)
            spread.fill(float(self.noise / SPREAD_FACTOR))
            self.modelled = True
        fit = (slice(None, None, FIT_STRIDE),) * 2
        gain, offset = whole_band_fit(background[fit], band.total[fit], band.diff[fit] < 0.5 * NOT_BOTH,
                                      float(self.noise))
        runtime.launch_row_loops(background_kernel, background.shape[0], background.shape[1], [
            band.diff_wp, band.total_wp, float(np.float32(gain - 1.0)), float(np.float32(offset)), self.kernel],
            DEVICE, runtime.BAND_THREADS)
        box, kernel = self._box
        solid = (cv2.blur(off, (box, box)) > 0).view(np.uint8)
        return cv2.dilate(solid, kernel)


class BandCosts:
    """The host arrays ``band_cost_kernel`` and ``strip_mean_kernel`` fill for the band's paths, and
    what they cost (``SeamCosts`` of ``cfg``): a path's cells from the last seam (``last``, ``still``,
    ``glide_first``), each cell's costs (``change``, ``free``, ``glide``, ``line_min``), the frame's
    ``path`` and the difference next to it (``strip_mean``, ``strip_count``)."""

    def __init__(self, grid: BandGrid, cfg: Config):
        solved, width = grid.shape
        self.host = {"last": np.zeros(solved, np.int32), "still": np.zeros(solved, np.uint8),
                     "glide_first": np.zeros(solved, np.int32), "change": np.zeros(grid.shape, np.float32),
                     "free": np.zeros(grid.shape, np.float32),
                     "glide": np.zeros((solved, grid.glide_width), np.float32),
                     "line_min": np.zeros(solved, np.float32), "path": np.zeros(solved, np.int32),
                     "strip_mean": np.zeros(solved, np.float32), "strip_count": np.zeros(solved, np.int32),
                     "moving": np.zeros(grid.shape, np.uint8)}
        dtypes = {np.dtype(np.int32): int, np.dtype(np.float32): float, np.dtype(np.uint8): wp.uint8}
        self.views = {name: host_array(a, dtypes[a.dtype]) for name, a in self.host.items()}
        self.last = LastSeam()
        self.last.last, self.last.still, self.last.glide_first = (
            self.views[k] for k in ("last", "still", "glide_first"))
        self.out = CellCosts()
        self.out.change, self.out.free, self.out.glide, self.out.line_min = (
            self.views[k] for k in ("change", "free", "glide", "line_min"))
        self.costs = SeamCosts()
        self.costs.speed, self.costs.noise = float(grid.speed), float(cfg.video_seam_noise)
        self.costs.motion_cost = float(cfg.video_seam_motion_cost)
        self.costs.blocked_cost = float(cfg.video_seam_blocked_cost)
        self.costs.stay_cost = float(cfg.video_seam_stay_cost)
        self.costs.block_cost = float(cfg.video_seam_blocked_cost * 10)  # a blocked cell; still lines keep their seam


class FrameSeam:
    """The per-frame seam of a luma plane whose plan keeps both views within ``band`` px of the
    estimate's seam ``home`` (L,) float32 (positions per line), on cells ``cell`` px wide
    (:func:`cell_px`); ``jumps``: whether it may leave its gliding path and keeps a background model (a
    static rig); ``fps``: the video's frame rate.

    The seam is solved on the grid's lines (:class:`BandGrid`) and interpolated between them;
    ``positions``, ``shown`` and ``still`` are per line. :meth:`reset` follows a new estimate's seam,
    :meth:`next` takes a frame's band (:class:`BandFrame`)."""

    def __init__(self, home: np.ndarray, band: int, cell: int, jumps: bool, fps: float, cfg: Config):
        self.cfg = cfg
        self.band = band
        self.grid = BandGrid.of(len(home), band, cell, cfg)
        self._fps = fps
        self.model = BandModel(self.grid, fps, cfg) if jumps else None
        self.work = BandCosts(self.grid, cfg)
        # A frame's cost of leaving home with its separation cost added (``next``'s ``copies``).
        self._home_frame = np.zeros(self.grid.shape, np.float32)
        self._home_frame_wp = host_array(self._home_frame, float)
        segment = np.array([[0, len(self.grid.lines) - 1, -1, -1]])  # one, free at both ends
        self._solvers = (BandPath(len(self.grid.lines), self.grid.width, segment, cfg.cpu_threads),  # free
                         BandPath(len(self.grid.lines), self.grid.glide_width, segment, cfg.cpu_threads))  # glide
        self.place: BandPlace | None = None  # where the band lies (``reset``)
        self._path: np.ndarray | None = None  # (K,) the solved lines' seam (px, on the grid of cells)
        self._shown: np.ndarray | None = None  # (K,) the solved lines' seam the last frame was composited with
        self._still = np.zeros(len(self.grid.lines), bool)  # the solved lines the last frame found still
        self._has_last = False  # whether the band's ``delta`` compares with the last frame on this place
        self.reset(home)

    @property
    def cell(self) -> int:
        return self.grid.cell

    @property
    def step(self) -> int:
        return self.grid.step

    @property
    def home(self) -> np.ndarray:
        """(L,) float32 the estimate's seam, the band's centre."""
        return self.place.home

    @property
    def jumps(self) -> bool:
        return self.model is not None

    def set_jumps(self, jumps: bool) -> None:
        """Whether it may jump and keeps a background model from now on (a rig that stopped or started
        moving); a new model learns the band from the next frame."""
        if jumps != self.jumps:
            self.model = BandModel(self.grid, self._fps, self.cfg) if jumps else None

    def reset(self, home: np.ndarray) -> None:
        """A new estimate's seam: the band follows it; the last path is kept where it still fits. The
        glide still starts from the seam last shown (``shown``), so a band that moves with a blend does
        not add its own step to the seam's. A seam that did not move (a static rig's maps moved with a
        camera's drift) keeps its band, its last difference and its background model: the band's
        content moved by a pixel or two, which the model's own learning follows."""
        home = np.asarray(home, np.float32)
        if self.place is not None and np.array_equal(home, self.place.home):
            return
        self.place = BandPlace.of(home, self.grid, self.cfg)
        self._has_last = False  # the band's cells moved: the last difference no longer lines up
        if self.model is not None:
            self.model.modelled = False
        self._path = self._on_grid(home[self.grid.lines] if self._path is None else self._path)

    def _on_grid(self, path: np.ndarray) -> np.ndarray:
        """(K,) int32 the band cells' positions nearest to ``path`` (K,) px on the solved lines."""
        x0, cell = self.place.x0, self.grid.cell
        nearest = x0 + cell * np.rint((np.asarray(path, np.float64) - x0) / cell)
        return np.clip(nearest, x0, self.place.cells[:, -1]).astype(np.int32)

    def _solve_band(self, solver: BandPath, cost: wp.array, x0: np.ndarray) -> np.ndarray:
        """(K,) int32 positions (px) of the cheapest path through ``cost`` (K, cells; a host Warp array)
        whose cells start at ``x0`` (K,) px on the grid of cells."""
        grid = self.grid
        return (solver.solve(cost, x0 // grid.cell, grid.max_step, grid.step_cost) * grid.cell).astype(np.int32)

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
        return np.interp(np.arange(self.grid.count), self.grid.lines, self._still.astype(np.float64)) == 1.0

    def _per_line(self, path: np.ndarray) -> np.ndarray:
        return np.rint(np.interp(np.arange(self.grid.count), self.grid.lines, path)).astype(np.int32)

    def next(self, band: BandFrame, copies: tuple[np.ndarray, np.ndarray] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seam of the frame whose band is ``band`` and its seam blend's offsets (``band_offsets``):
        (positions (L,) int32, offsets off the source (L, 1), onto the target (L, 1) float32).
        ``copies``: (target's, source's) (M, 2) (line, position) of points the warp leaves apart this
        frame: the seam keeps each pair on one side (:func:`separation_band_cost`)."""
        self._still = self.still_lines(band)
        self._has_last = True
        last = self._path if self._shown is None else self._shown
        if not self._still.all():  # else nothing changed on any line: the seam and the background model stay
            moving = self.model.foreground(band) if self.model is not None else None
            home_term = self.place.home_term_wp
            if copies is not None and len(copies[0]):  # this frame's home term carries the separation's cost
                separation = separation_band_cost(self.grid.lines, self.place.x0, self.grid.cell, self.grid.width,
                                                  *copies, self.cfg)
                np.add(self.place.home_term, separation, out=self._home_frame)
                home_term = self._home_frame_wp
            self._path = self._solve(band, moving, last, home_term)
        self._shown = self._path.copy()
        work, grid = self.work, self.grid
        np.copyto(work.host["path"], self._path, casting="unsafe")
        runtime.launch_rows(strip_mean_kernel, len(grid.lines), 1, [
            band.diff_wp, self.place.x0_wp, grid.cell, work.views["path"], self.cfg.seam_blend_strip_px // grid.cell,
            work.views["strip_mean"], work.views["strip_count"]], DEVICE, runtime.BAND_THREADS)
        offsets_src, offsets_tgt = band_offsets(work.host["strip_mean"], work.host["strip_count"], grid.lines,
                                                grid.step, self.cfg)
        return self.positions, offsets_src, offsets_tgt

    def _solve(self, band: BandFrame, moving: np.ndarray | None, last: np.ndarray, home_term: wp.array
               ) -> np.ndarray:
        """The solved lines' new path (module docstring); ``moving``: the cells in front of the
        background (``BandModel.foreground``), None on a moving rig; ``home_term``: each cell's cost of
        leaving home (with the frame's separation cost, if any).

        The glide moves at most ``video_seam_speed_px`` (or one cell) per solved line from ``last`` (K,)
        and not at all on still lines: it is solved on the few cells it may take, from ``first``."""
        cfg, grid, place, work = self.cfg, self.grid, self.place, self.work
        first = np.clip((last - place.x0) // grid.cell - grid.glide_width // 2, 0, grid.width - grid.glide_width)
        for name, values in (("last", last), ("still", self._still), ("glide_first", first)):
            np.copyto(work.host[name], values, casting="unsafe")
        if moving is not None:
            np.copyto(work.host["moving"], moving)
        runtime.launch_rows(band_cost_kernel, len(grid.lines), 1, [
            band.diff_wp, work.views["moving"], home_term, place.x0_wp, grid.cell, work.last, work.costs,
            work.out], DEVICE, runtime.BAND_THREADS)
        change = work.host["change"]
        free_solver, glide_solver = self._solvers
        glide = self._solve_band(glide_solver, work.views["glide"], place.x0 + grid.cell * first)
        solved = np.arange(len(grid.lines))

        def along(path: np.ndarray) -> float:
            return float(change[solved, (path - place.x0) // grid.cell].sum())

        limit = len(grid.lines)
        path = glide
        jump = cfg.video_seam_jump_cost * limit
        # Something in front of the background, and a path cheaper than the glide's by a jump may exist
        # (no path costs less than each line's cheapest cell): it may jump round it.
        if moving is not None and moving.any() and along(glide) - float(work.host["line_min"].sum()) > jump:
            free = self._solve_band(free_solver, work.views["free"], place.x0)
            path = free if along(glide) - along(free) > jump else glide
        if along(self._path) - along(path) > cfg.video_seam_margin * limit:
            return path.astype(np.int32)
        return self._path

    def still_lines(self, band: BandFrame) -> np.ndarray:
        """(K,) bool: solved lines where nothing changed since the last frame (module docstring), from the
        band's ``delta``; none without a last frame on this place."""
        if not self._has_last:
            return np.zeros(len(self.grid.lines), bool)
        box = max(1, self.cfg.video_seam_still_box_px)
        moved = (cv2.blur(band.delta, (box, box)) > self.cfg.video_seam_noise).any(axis=1)
        return ~lines_near(moved, int(np.ceil(self.grid.width * self.grid.cell / self.grid.step)))


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


def separation_band_cost(lines: np.ndarray, x0: np.ndarray, cell: int, width: int, copies_tgt: np.ndarray,
                         copies_src: np.ndarray, cfg: Config) -> np.ndarray:
    """(K, width) float32 over a band's cells (solved lines ``lines`` (K,), their first cells at ``x0`` (K,)
    px, cells ``cell`` px wide): ``seam_path.separation_cost`` for points whose two copies are
    ``copies_tgt`` / ``copies_src`` (M, 2) (line, position): every cell between a pair's copies, and
    within the transition's reach of them, costs ``seam_separation_weight`` on the solved lines within
    ``seam_separation_rows`` of the pair's."""
    solved = np.full(int(lines[-1]) + 1, -1, np.int64)
    solved[lines] = np.arange(len(lines))
    mid, lo, hi = separation_spans(np.asarray(copies_src, np.float64)[:, ::-1],
                                   np.asarray(copies_tgt, np.float64)[:, ::-1], cfg)
    row = np.rint(mid).astype(np.int64)
    edges = np.zeros((len(lines), width + 1), np.float32)
    for dy in range(-cfg.seam_separation_rows, cfg.seam_separation_rows + 1):
        line = row + dy
        k = np.where((line >= 0) & (line < len(solved)), solved[np.clip(line, 0, len(solved) - 1)], -1)
        ok = k >= 0
        first = np.clip(np.floor((lo[ok] - x0[k[ok]]) / cell), 0, width).astype(np.int64)
        last = np.clip(np.ceil((hi[ok] - x0[k[ok]]) / cell), 0, width).astype(np.int64)
        wide = last > first
        np.add.at(edges, (k[ok][wide], first[wide]), cfg.seam_separation_weight)
        np.add.at(edges, (k[ok][wide], last[wide]), -cfg.seam_separation_weight)
    return np.cumsum(edges, axis=1)[:, :width]


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
