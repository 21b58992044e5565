"""The seam of every video frame: "cached warps, per-frame seam slicing".

The estimate fixes the maps and a seam; each frame the seam is re-optimised inside a band around it
(``band`` cells each side, ``video_seam_band_ratio`` x the canvas diagonal: room to go round an
object and its second copy) on that frame's luma difference (``composite.band_difference`` on the
frame's device, source minus target, gains applied, downloaded as one small :class:`BandFrame`), by
the dynamic programming of ``seam_path`` with a temporal term:
a cell costs its difference beyond the noise floor, plus ``video_seam_stay_cost`` per pixel away from
the last frame's seam and ``video_seam_home_cost`` per pixel away from the estimate's.

*Glide and jump.* The seam glides: it moves at most ``video_seam_speed_px`` per line from the last
frame's (one cell where cells are wider). While the rig's plan is static and something is in front
of the background (below), a second path, free in the band, is taken instead when the gliding one
would cost ``video_seam_jump_cost`` per line more: something moved across the seam and the seam steps
round it at once. (While the plan is a moving rig's, everything shifts a little every frame; there
the seam only glides, and keeps the two copies of what the frame's warp left apart on one side,
:func:`separation_band_cost`.) A new path replaces the last one only when it is cheaper by
``video_seam_margin`` per line: while nothing moves the costs only carry noise.

*Still lines.* A line is still when no box of ``video_seam_still_box_px`` cells of the band's
difference changed by more than ``video_seam_noise`` since the last frame on it or within a band's
width of lines (room for the path to leave and come back); there every cell but the last frame's
seam is blocked, and a frame whose lines are all still solves nothing.

*In front of the background* (a static plan, ``frame_objects.ObjectBand``). Over the whole overlap, on
cells four times as wide, each view keeps a background model; what is off it in either view (an object,
both its copies) costs ``video_seam_motion_cost`` more, so the seam goes round a moving object whole,
not only round where the views differ: inside a smooth object its two copies differ little, and a
seam through it would lose a strip of it. Each object's two copies (paired across the views) and the
strip between them cost ``video_seam_object_cost``: the seam keeps off them and shows the object once
and whole from one view. Where an object stands on the band's home, the next frame's band moves
to where the object band's route passes it, on the side it passed before (a jump when the route
switches sides, round the object); where the band left the seam last shown behind, the seam goes with
it, freely in the band, that frame. The object band and the seam's band come down in one block, so
the band is placed a frame after the objects that place it (the strips the seam keeps off are
this frame's). (The plan keeps both views wherever the
band may go: about the estimate's seam and, where the rig may be static, over the overlap.) When the
plan turns moving the object band is dropped; when it turns static a new one learns.

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
from sena_warp.kernels.frame_objects import CellGrid, coarse_masks_kernel
from sena_warp.kernels.frame_seam import (DEVICE, CellCosts, LastSeam, SeamCosts, band_cost_kernel, gentle_kernel,
                                          strip_mean_kernel)
from sena_warp.kernels.transfer import host_array
from .frame_objects import ObjectBand, ObjectGrid


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
    a frame, on ``glide_width`` cells."""

    count: int
    lines: np.ndarray
    cell: int
    width: int
    step: int
    max_step: int
    step_cost: float
    speed: float
    glide_width: int

    @staticmethod
    def of(count: int, band: int, cell: int, cfg: Config) -> "BandGrid":
        """The grid of ``count`` seam lines whose band reaches ``band`` px each side, cells ``cell`` px."""
        width = 2 * int(np.ceil(band / cell)) + 1
        step = line_step(cell, cfg)
        lines = np.unique(np.append(np.arange(0, count, step), count - 1)).astype(np.int32)
        speed = max(cfg.video_seam_speed_px, cell)  # px a frame: at least one cell, or it could not glide
        return BandGrid(count, lines, cell, width, step, int(np.ceil(cfg.seam_max_step_px * step / cell)),
                        cfg.seam_step_cost * cell, speed, min(width, 2 * int(np.ceil(speed / cell)) + 1))

    @property
    def shape(self) -> tuple[int, int]:
        """(solved lines, cells): the shape of the band's per-cell arrays."""
        return len(self.lines), self.width


@dataclass(frozen=True)
class BandPlace:
    """Where the band lies for one estimate's seam ``home`` (L,) float32 (centred on it, or where a static
    rig's objects move it): each solved line's first cell
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
    def of(home: np.ndarray, grid: BandGrid, cfg: Config, centre: np.ndarray | None = None) -> "BandPlace":
        """The band about ``centre`` (K,) px on the solved lines, or about ``home`` without one."""
        x0 = BandPlace.first_cells(home[grid.lines] if centre is None else centre, grid)
        cells = x0[:, None] + grid.cell * np.arange(grid.width, dtype=np.int32)[None, :]
        away = np.subtract(cells, home[grid.lines, None], dtype=np.float64)  # in place: a frame's band moves often
        np.abs(away, out=away)
        home_term = np.empty(grid.shape, np.float32)
        np.multiply(away, cfg.video_seam_home_cost, out=home_term, casting="unsafe")
        return BandPlace(home, x0, cells, home_term, host_array(x0, int), host_array(home_term, float))

    @staticmethod
    def first_cells(centre: np.ndarray, grid: BandGrid) -> np.ndarray:
        """(K,) int32 each solved line's first cell (px) of a band about ``centre`` (K,) px."""
        half = grid.width // 2
        return ((np.floor_divide(np.rint(centre).astype(np.int32), grid.cell) - half) * grid.cell).astype(np.int32)


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


class BandCosts:
    """The host arrays ``band_cost_kernel`` and ``strip_mean_kernel`` fill for the band's paths, and
    what they cost (``SeamCosts`` of ``cfg``): a path's cells from the last seam (``last``, ``still``,
    ``glide_first``), each cell's costs (``change``, ``free``, ``glide``, ``line_min``), the frame's
    ``path`` and the difference next to it (``strip_mean``, ``strip_count``); what is in front
    (``moving``) and the strips kept off (``kept_off``) on a static plan, the last frame's difference
    (``last_diff``, for lines where the band moved), and a frame's cost of leaving home with its
    separation cost added (``home_frame``, :meth:`FrameSeam.next`'s ``copies``)."""

    def __init__(self, grid: BandGrid, cfg: Config):
        solved, width = grid.shape
        self.host = {"last": np.zeros(solved, np.int32), "still": np.zeros(solved, np.uint8),
                     "glide_first": np.zeros(solved, np.int32), "change": np.zeros(grid.shape, np.float32),
                     "free": np.zeros(grid.shape, np.float32),
                     "glide": np.zeros((solved, grid.glide_width), np.float32),
                     "line_min": np.zeros(solved, np.float32), "path": np.zeros(solved, np.int32),
                     "strip_mean": np.zeros(solved, np.float32), "strip_count": np.zeros(solved, np.int32),
                     "moving": np.zeros(grid.shape, np.uint8), "kept_off": np.zeros(grid.shape, np.uint8),
                     "lines": grid.lines.astype(np.int32), "last_diff": np.zeros(grid.shape, np.float32),
                     "home_frame": np.zeros(grid.shape, np.float32)}
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
        self.costs.object_cost = float(cfg.video_seam_object_cost)
        self.costs.blocked_cost = float(cfg.video_seam_blocked_cost)
        self.costs.stay_cost = float(cfg.video_seam_stay_cost)
        self.costs.block_cost = float(cfg.video_seam_blocked_cost * 10)  # a blocked cell; still lines keep their seam


class FrameSeam:
    """The per-frame seam of a luma plane whose plan keeps both views within ``band`` px of the
    estimate's seam ``home`` (L,) float32 (positions per line) and, where the rig may be static, over
    the whole overlap, on cells ``cell`` px wide (:func:`cell_px`); ``overlap`` (L, 2) int: per line the
    first and the last position holding both views (None: the plan keeps only the band); ``jumps``:
    whether the rig's plan is static, so that the seam may jump and goes round what is in front of
    the background (``frame_objects.ObjectBand``, kept where there is an overlap), not on a moving rig
    (whose seam only glides; :meth:`set_jumps` when the plan changes); ``fps``: the video's frame rate.

    The seam is solved on the grid's lines (:class:`BandGrid`) and interpolated between them;
    ``positions``, ``shown`` and ``still`` are per line. :meth:`reset` follows a new estimate's seam; per
    frame :meth:`next` takes the frame's band (:class:`BandFrame`, at ``place``) and, with an object
    band, the object band's (on ``objects.grid``), both from one download: the objects are found, the
    seam is solved, and the band is placed for the next frame where the objects' route passes."""

    def __init__(self, home: np.ndarray, band: int, cell: int, overlap: np.ndarray | None, jumps: bool, fps: float,
                 cfg: Config):
        self.cfg = cfg
        self.fps = fps
        self._jumps = jumps
        self._overlap: np.ndarray | None = None
        self.band = band
        self.grid = BandGrid.of(len(home), band, cell, cfg)
        self.work = BandCosts(self.grid, cfg)
        segment = np.array([[0, len(self.grid.lines) - 1, -1, -1]])  # one, free at both ends
        self._solvers = (BandPath(len(self.grid.lines), self.grid.width, segment, cfg.cpu_threads),  # free
                         BandPath(len(self.grid.lines), self.grid.glide_width, segment, cfg.cpu_threads))  # glide
        self.objects: ObjectBand | None = None  # a static plan's (``reset``, ``set_jumps``)
        self.place: BandPlace | None = None  # where the band lies (``reset``, ``_follow``)
        self._moved = False  # whether ``_follow`` moved the band off the seam last shown since the last solve
        self._path: np.ndarray | None = None  # (K,) the solved lines' seam (px, on the grid of cells)
        self._shown: np.ndarray | None = None  # (K,) the solved lines' seam the last frame was composited with
        self._still = np.zeros(len(self.grid.lines), bool)  # the solved lines the last frame found still
        # Per solved line, how many cells the band moved since the last frame (``_follow``): 0 where the
        # band's ``delta`` compares with the last frame, a band's width or more where nothing does.
        self._shift = np.full(len(self.grid.lines), self.grid.width, np.int32)
        self.reset(home, overlap)

    @property
    def cell(self) -> int:
        return self.grid.cell

    @property
    def step(self) -> int:
        return self.grid.step

    @property
    def home(self) -> np.ndarray:
        """(L,) float32 the estimate's seam, the band's centre where nothing is in the way."""
        return self.place.home

    @property
    def jumps(self) -> bool:
        """Whether the seam may jump round what is in front (a static plan): the object band is kept."""
        return self._jumps

    def set_jumps(self, jumps: bool) -> None:
        """Whether the seam may jump and keeps the object band from now on (a rig that stopped or started
        moving): a new object band's models learn from the next frame; without one the band goes back
        to the estimate's seam."""
        if jumps != self._jumps:
            self._jumps = jumps
            self._place_home(self.place.home)

    def reset(self, home: np.ndarray, overlap: np.ndarray | None) -> None:
        """A new estimate's seam and overlap (as the constructor's): the band follows it; the last path
        is kept where it still fits. The glide still starts from the seam last shown (``shown``), so a
        band that moves with a blend does not add its own step to the seam's. A seam that did not move
        (a static rig's maps moved with a camera's drift) keeps its band, its last difference and its
        background models: the band's content moved by a pixel or two, which the models' own learning
        follows."""
        home = np.asarray(home, np.float32)
        if self.place is not None and np.array_equal(home, self.place.home):
            return
        self._overlap = overlap
        self._place_home(home)

    def _place_home(self, home: np.ndarray) -> None:
        """The band about ``home``, and a new object band over the overlap where the seam may jump."""
        keeps = self._jumps and self._overlap is not None
        self.objects = ObjectBand(ObjectGrid.of(home, self._overlap, self.grid.cell), self.fps, self.cfg) \
            if keeps else None
        self.place = BandPlace.of(home, self.grid, self.cfg)
        for name in ("moving", "kept_off"):  # filled again each frame while there is an object band
            self.work.host[name].fill(0)
        self._shift[:] = self.grid.width  # the band's cells moved: the last difference no longer lines up
        self._moved = False
        self._path = self._on_grid(home[self.grid.lines] if self._path is None else self._path)

    def _follow(self) -> None:
        """After a frame whose objects changed their route: the band of the next frame centred where the
        route passes (``ObjectBand.centre``), moved as gently as a path can follow. On lines whose cells
        moved, the last frame's difference moves with the cells it was taken on (``still_lines``); where
        the band left the seam last shown behind, the next solve is free in the band."""
        grid, place = self.grid, self.place
        centre = gentle(self.objects.centre(grid.lines), max(grid.max_step - 1, 1) * grid.cell)
        if np.array_equal(BandPlace.first_cells(centre, grid), place.x0):
            return
        moved = BandPlace.of(place.home, grid, self.cfg, centre)
        self._shift = np.where(np.abs(self._shift) >= grid.width, self._shift,
                               (moved.x0 - place.x0) // grid.cell).astype(np.int32)
        self._moved = bool(np.any((self._shown < moved.x0) | (self._shown > moved.cells[:, -1])))
        self.place = moved
        self._path = self._on_grid(self._path)

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

    def next(self, band: BandFrame, objects: BandFrame | None = None,
             copies: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seam of the frame whose band is ``band`` and its seam blend's offsets (``band_offsets``):
        (positions (L,) int32, offsets off the source (L, 1), onto the target (L, 1) float32).
        ``objects``: the frame's object band (on ``objects.grid``; None without an object band): what is
        in front, kept off, and where the next frame's band lies. ``copies``: (target's, source's) (M, 2)
        (line, position) of points the warp leaves apart this frame: the seam keeps each pair on one
        side (:func:`separation_band_cost`)."""
        route_changed = self.objects is not None and objects is not None and self.objects.update(objects)
        self._still = self.still_lines(band)
        if self._moved:  # the band left the seam shown last behind: no line keeps it, the seam follows the band
            self._still[:] = False
        self._shift[:] = 0
        np.copyto(self.work.host["last_diff"], band.diff)
        last = self._path if self._shown is None else self._shown
        if not self._still.all():  # else nothing changed on any line: the seam stays
            moving = self.foreground() if self.objects is not None else None
            home_term = self.place.home_term_wp
            if copies is not None and len(copies[0]):  # this frame's home term carries the separation's cost
                separation = separation_band_cost(self.grid.lines, self.place.x0, self.grid.cell, self.grid.width,
                                                  *copies, self.cfg)
                np.add(self.place.home_term, separation, out=self.work.host["home_frame"])
                home_term = self.work.views["home_frame"]
            self._path = self._solve(band, moving, last, home_term)
        self._shown = self._path.copy()
        work, grid = self.work, self.grid
        np.copyto(work.host["path"], self._path, casting="unsafe")
        runtime.launch_rows(strip_mean_kernel, len(grid.lines), 1, [
            band.diff_wp, self.place.x0_wp, grid.cell, work.views["path"], self.cfg.seam_blend_strip_px // grid.cell,
            work.views["strip_mean"], work.views["strip_count"]], DEVICE, runtime.BAND_THREADS)
        offsets_src, offsets_tgt = band_offsets(work.host["strip_mean"], work.host["strip_count"], grid.lines,
                                                grid.step, self.cfg)
        positions = self.positions
        if route_changed:
            self._follow()
        return positions, offsets_src, offsets_tgt

    def _solve(self, band: BandFrame, moving: np.ndarray | None, last: np.ndarray, home_term: wp.array
               ) -> np.ndarray:
        """The solved lines' new path (module docstring); ``moving``: the cells in front of the
        background (:meth:`foreground`, which also filled the strips kept off), None without an object
        band; ``home_term``: each cell's cost of leaving home (with the frame's separation cost, if any).

        The glide moves at most ``video_seam_speed_px`` (or one cell) per solved line from ``last`` (K,)
        and not at all on still lines: it is solved on the few cells it may take, from ``first``."""
        cfg, grid, place, work = self.cfg, self.grid, self.place, self.work
        first = np.clip((last - place.x0) // grid.cell - grid.glide_width // 2, 0, grid.width - grid.glide_width)
        for name, values in (("last", last), ("still", self._still), ("glide_first", first)):
            np.copyto(work.host[name], values, casting="unsafe")
        runtime.launch_rows(band_cost_kernel, len(grid.lines), 1, [
            band.diff_wp, work.views["moving"], work.views["kept_off"], home_term, place.x0_wp, grid.cell, work.last,
            work.costs, work.out], DEVICE, runtime.BAND_THREADS)
        change = work.host["change"]
        free_solver, glide_solver = self._solvers
        if self._moved:  # the band left the seam behind (round an object): the seam follows, anywhere in the band
            self._moved = False
            return self._solve_band(free_solver, work.views["free"], place.x0)
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

    def foreground(self) -> np.ndarray:
        """(K, width) uint8 over the solved lines' band: 1 on cells in front of either view's background
        (the object band's, grown by an object's box), with the strips the seam keeps off
        (``work.host["kept_off"]``) filled from it too (``frame_objects``)."""
        objects, work, grid = self.objects, self.work, self.grid
        fine = CellGrid()
        fine.x0, fine.cell, fine.step = self.place.x0_wp, grid.cell, grid.step
        runtime.launch_row_loops(coarse_masks_kernel, len(grid.lines), grid.width, [
            work.views["lines"], fine, objects.grid.kernel, objects.views["moving"], objects.views["kept_off"],
            work.views["moving"], work.views["kept_off"]], DEVICE, runtime.BAND_THREADS)
        return work.host["moving"]

    def still_lines(self, band: BandFrame) -> np.ndarray:
        """(K,) bool: solved lines where nothing changed since the last frame (module docstring), from the
        band's ``delta`` (on lines where the band moved, from the last frame's difference moved with its
        cells); none on a line without the last frame's difference."""
        width = self.grid.width
        missing = np.abs(self._shift) >= width
        if missing.all():
            return np.zeros(len(self.grid.lines), bool)
        delta = band.delta
        shifted = np.flatnonzero((self._shift != 0) & ~missing)
        if shifted.size:
            delta = delta.copy()
            taken = np.arange(width)[None, :] + self._shift[shifted, None]
            inside = (taken >= 0) & (taken < width)
            at = np.clip(taken, 0, width - 1) + (shifted * width)[:, None]  # in the flat last difference
            last = np.take(self.work.host["last_diff"], at)
            now = band.diff[shifted]
            both = inside & (now < 0.5 * NOT_BOTH) & (last < 0.5 * NOT_BOTH)
            delta[shifted] = np.where(both, np.abs(now - last), 0.0)
        box = max(1, self.cfg.video_seam_still_box_px)
        moved = (cv2.blur(delta, (box, box)) > self.cfg.video_seam_noise).any(axis=1) | missing
        return ~lines_near(moved, int(np.ceil(self.grid.width * self.grid.cell / self.grid.step)))


def gentle(positions: np.ndarray, most: float) -> np.ndarray:
    """(K,) float64 ``positions`` (K,) moved as little as it takes to change by at most ``most`` from
    one line to the next (clamped forwards, then backwards)."""
    out = np.asarray(positions, np.float64)
    if np.all(np.abs(np.diff(out)) <= most):  # gentle already (the route's own steps are): nothing moves
        return out.copy()
    out = out.copy()
    runtime.launch_rows(gentle_kernel, 1, 1, [host_array(out, wp.float64), float(most)], DEVICE, runtime.BAND_THREADS)
    return out


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
    rows = cfg.seam_separation_rows
    line = (np.rint(mid).astype(np.int64)[None, :] + np.arange(-rows, rows + 1)[:, None]).ravel()  # every pair's lines
    lo, hi = np.tile(lo, 2 * rows + 1), np.tile(hi, 2 * rows + 1)
    k = np.where((line >= 0) & (line < len(solved)), solved[np.clip(line, 0, len(solved) - 1)], -1)
    ok = k >= 0
    k, lo, hi = k[ok], lo[ok], hi[ok]
    first = np.clip(np.floor((lo - x0[k]) / cell), 0, width).astype(np.int64)
    last = np.clip(np.ceil((hi - x0[k]) / cell), 0, width).astype(np.int64)
    wide = last > first
    edges = np.zeros((len(lines), width + 1), np.float32)
    np.add.at(edges, (k[wide], first[wide]), cfg.seam_separation_weight)
    np.add.at(edges, (k[wide], last[wide]), -cfg.seam_separation_weight)
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
