"""The seam of every video frame (issue 14): "cached warps, per-frame seam slicing".

The estimate fixes the maps and a seam; each frame the seam is re-optimised inside a band around it
(``band`` px each side, ``video_seam_band_ratio`` x the canvas diagonal) on that frame's luma
difference (the compositor's ``band_difference``: source minus target, gains applied), by the
dynamic programming of ``seam_path`` with a temporal term:
a cell costs its difference beyond the noise floor, plus ``video_seam_stay_cost`` per pixel away from
the last frame's seam and ``video_seam_home_cost`` per pixel away from the estimate's. (The plan keeps
both views wherever the band may go: about the estimate's seam, and on a static rig over the overlap.)

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

*In front of the background* (static rigs, ``frame_objects.ObjectBand``). Over the whole overlap, on
cells four times as wide, each view keeps a background model; what is off it in either view (an object,
both its copies) costs ``video_seam_motion_cost`` more, so the seam goes round a moving object whole,
not only round where the views differ: inside a smooth object its two copies differ little, and a
seam through it would lose a strip of it. Each object's two copies (paired across the views) and the
strip between them cost ``video_seam_object_cost``: the seam keeps off them and shows the object once
and whole from one view. Where an object stands on the band's home, the band moves (``_place``) to
where the object band's route passes it, on the side it passed before (a jump when the route switches
sides, round the object); the seam goes with it, freely in the band, that frame.

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
from sena_warp.kernels.frame_objects import CellGrid, coarse_masks_kernel
from sena_warp.kernels.frame_seam import band_cost_kernel, strip_mean_kernel
from .frame_objects import ObjectBand, whole_band_fit



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
    estimate's seam ``home`` (L,) float32 (positions per line) and, on a static rig, over the whole
    overlap, on cells ``cell`` px wide (:func:`cell_px`); ``overlap`` (L, 2) int: per line the first
    and the last position holding both views, for a static rig (whose seam may jump and goes round
    what is in front of the background, ``frame_objects.ObjectBand``), None for a moving rig (whose
    seam only glides); ``fps``: the video's frame rate.

    The seam is solved on every ``step``-th line (:func:`line_step`, and the last) and interpolated
    between them; ``positions``, ``shown`` and ``still`` are per line. The band's cells live in Warp
    arrays (K solved lines, ``width`` cells) that the kernels of ``kernels/frame_seam.py`` fill (on
    ``runtime.BAND_THREADS`` CPU threads)."""

    def __init__(self, home: np.ndarray, band: int, cell: int, overlap: np.ndarray | None, fps: float, cfg: Config):
        self.cfg = cfg
        self.fps = fps
        self.band = band
        self.cell = cell
        self.width = 2 * int(np.ceil(band / self.cell)) + 1  # cells
        count = len(home)
        self._every_line = np.arange(count)
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
        self._moving = wp.zeros(cells, dtype=wp.uint8, device=device)  # 1: something in front (a static rig's)
        self._kept_off = wp.zeros(cells, dtype=wp.uint8, device=device)  # 1: on an object's copies or between them
        self._grid = CellGrid()  # the band's cells, for the object band's masks
        self._grid.x0, self._grid.cell, self._grid.step = self._x0_wp, self.cell, step
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
        self._objects: ObjectBand | None = None  # a static rig's (``reset``)
        self._shown: np.ndarray | None = None  # (K,) the solved lines' seam the last frame was composited with
        self._has_last = np.zeros(solved, bool)  # the lines where ``_last_diff`` holds the last frame's difference
        self._still = np.zeros(solved, bool)  # the solved lines the last frame found still (``still_lines``)
        self.home: np.ndarray | None = None  # (L,) the estimate's seam (``reset``)
        self._centre: np.ndarray | None = None  # (K,) where the band is centred on the solved lines (``_place``)
        self._moved = False  # whether ``_place`` moved the band off the seam last shown since the last solve
        self._path: np.ndarray | None = None  # (K,) the solved lines' seam (px, on the grid of cells)
        self.reset(home, overlap)

    @property
    def jumps(self) -> bool:
        """Whether the seam may leave its gliding path: a static rig's, which watches what moves."""
        return self._objects is not None

    def reset(self, home: np.ndarray, overlap: np.ndarray | None) -> None:
        """A new estimate's seam and, for a static rig, overlap (as the constructor's): the band follows
        it; the last path is kept where it still fits. The glide still starts from the seam last shown
        (``shown``), so a band that moves with a blend does not add its own step to the seam's. A seam
        that did not move (a static rig's maps moved with a camera's drift) keeps its band, its last
        difference and its background models: the band's content moved by a pixel or two, which the
        models' own learning follows."""
        home = np.asarray(home, np.float32)
        if self.home is not None and np.array_equal(home, self.home):
            return
        self.home = home
        self._objects = None if overlap is None else ObjectBand(home, overlap, self.cell, self.fps, self.cfg)
        self._centre = None
        self._place(self.home[self._lines].astype(np.float64))

    def _place(self, centre: np.ndarray) -> None:
        """The band centred on ``centre`` (K,) px on the solved lines (the estimate's seam, or where a
        static rig's objects move it): its cells, their cost of leaving home; the last path is kept where
        it still fits."""
        half = self.width // 2
        centre = gentle(centre, max(self._max_step - 1, 1) * self.cell)  # a path can follow it, rounding and all
        x0 = ((np.floor_divide(np.rint(centre).astype(np.int32), self.cell) - half)
              * self.cell).astype(np.int32)  # on the grid of cells, so cells line up from line to line
        if self._centre is not None and np.array_equal(x0, self._x0):
            return
        if self._centre is None:
            kept = np.zeros(len(x0), bool)
        else:  # the last frame's difference moves with the cells it was taken on (none where new)
            shift = (x0 - self._x0) // self.cell
            kept = np.abs(shift) < self.width
            taken = np.arange(self.width)[None, :] + shift[:, None]
            inside = (taken >= 0) & (taken < self.width)
            last = np.take_along_axis(self._diff.numpy(), np.clip(taken, 0, self.width - 1), axis=1)
            runtime.upload(self._diff, np.where(inside, last, np.float32(NOT_BOTH)).astype(np.float32))
        last = self._path if self._shown is None else self._shown
        # Moved away from the seam last shown (round an object): it has to follow, anywhere in the band.
        self._moved = self._centre is not None and bool(np.any((last < x0) | (last > x0 + self.cell * (self.width - 1))))
        self._centre, self._x0 = centre, x0
        runtime.upload(self._x0_wp, self._x0)
        self._cells = self._x0[:, None] + self.cell * np.arange(self.width, dtype=np.int32)[None, :]
        runtime.upload(self._home_term, self.cfg.video_seam_home_cost
                       * np.abs(self._cells - self.home[self._lines, None]))
        self._has_last &= kept
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
        if self._objects is not None:  # a static rig: what is in front, and where the band must lie to go round it
            self._objects.update(luma)
            self._place(self._objects.centre(self._lines))
        self._diff, self._last_diff = self._last_diff, self._diff  # this frame's fills the older
        luma.band_difference(self._lines_wp, self._x0_wp, self.width, self.cell, self._last_diff, self._diff,
                             self._total, self._delta)
        self._still = self.still_lines()
        self._has_last[:] = True
        last = self._path if self._shown is None else self._shown
        if not self._still.all():  # else nothing changed on any line: the seam stays
            moving = self.foreground() if self.jumps else None
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
            self._diff, self._moving, self._kept_off, float(cfg.video_seam_object_cost), self._home_term,
            self._x0_wp, self.cell, self._last_wp, self._still_wp,
            self._glide_first, float(self._speed), float(cfg.video_seam_noise), float(cfg.video_seam_motion_cost),
            float(cfg.video_seam_blocked_cost), float(cfg.video_seam_stay_cost),
            float(cfg.video_seam_blocked_cost * 10),  # a blocked cell; still lines keep their seam
            self._change, self._free_cost, self._glide_cost, self._line_min], cfg.device, runtime.BAND_THREADS)
        if self._moved:  # the band left the seam behind (round an object): the seam follows, anywhere in the band
            self._moved = False
            return self._solve_band(self._solver, self._free_cost, self._x0)
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

    def foreground(self) -> np.ndarray:
        """(K, width) uint8 over the solved lines' band: 1 on cells in front of either view's background
        (the object band's, grown by an object's box), with the strips the seam keeps off (``_kept_off``)
        from it too (``frame_objects``)."""
        objects = self._objects
        runtime.launch_row_loops(coarse_masks_kernel, len(self._lines), self.width, [
            self._lines_wp, self._grid, objects.grid, objects.moving_wp, objects.kept_off_wp, self._moving,
            self._kept_off], self.cfg.device, runtime.BAND_THREADS)
        return self._moving.numpy()

    def still_lines(self) -> np.ndarray:
        """(K,) bool: solved lines where nothing changed since the last frame (module docstring), from the
        band's difference loaded by ``band_difference``; none on a line without the last frame's (the band
        moved there)."""
        if not self._has_last.any():
            return np.zeros(len(self._lines), bool)
        box = max(1, self.cfg.video_seam_still_box_px)
        moved = (cv2.blur(self._delta.numpy(), (box, box)) > self.cfg.video_seam_noise).any(axis=1) | ~self._has_last
        return ~lines_near(moved, int(np.ceil(self.width * self.cell / self.step)))


def gentle(positions: np.ndarray, most: float) -> np.ndarray:
    """(K,) float64 ``positions`` (K,) moved as little as it takes to change by at most ``most`` from
    one line to the next (clamped forwards, then backwards)."""
    out = np.asarray(positions, np.float64).copy()
    for k in range(1, len(out)):
        out[k] = min(max(out[k], out[k - 1] - most), out[k - 1] + most)
    for k in range(len(out) - 2, -1, -1):
        out[k] = min(max(out[k], out[k + 1] - most), out[k + 1] + most)
    return out


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
