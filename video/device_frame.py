"""A video frame on the Warp device: the plans of a map set, the frame's buffers, and the one step.

A :class:`FramePlan` is one map set made ready for the video's planes: the Y pass's plan and the U/V
pass's (U and V composited as two channels at half resolution), made once per map set
(:class:`Plans`; each row's runs are found once the plan has served a frame).

:class:`DeviceFrame` holds the frame's device memory, allocated once, and moves it as few times as a
frame allows (``kernels/transfer.py``): the decoded planes go up in one block (:meth:`DeviceFrame.load`);
the seam band's difference and, on a static plan, the object band's (the whole overlap on coarse
cells) come down together in one small block (:meth:`DeviceFrame.band`); the frame's seam and
seam-blend offsets go up in one small block, with where the next frame's seam band lies, and both
passes are composited, then the output planes come down in one block for the encoder
(:meth:`DeviceFrame.composite`). A moving rig's output is a window on the canvas (``steady.py``),
composited by the plan of the window's own maps, made in one kernel without them (``frame_plan`` with an
:class:`OutputWindow`, ``composite.window_plan``: each output pixel samples the inputs once, and a new window
every frame costs one pass over it); the seam's band is read on that plan at the canvas's cells, to the nearest pixel.
Nothing in a frame waits for the device but those two downloads. An observer may ask for the canvas
itself too (:meth:`DeviceFrame.canvas`: the pair composited again by the canvas's plan).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import warp as wp

from ..composite import (CompositePlan, FrameArrays, FrameState, band_difference, band_words, composite,
                         composite_plan, fixed_point, kernel_gains, window_plan, with_runs)
from ..config import Config
from sena_warp.kernels import transfer
from sena_warp.kernels.composite import BandCells, BandWord, BandWords, Gains, SeamState
from .frame_objects import ObjectGrid
from .frame_seam import BandFrame, BandGrid, BandPlace
from .maps import BLACK_UV, BLACK_Y, WHITE_Y, PlaneMaps, windowed_layouts, windowed_plane_maps

LUMA_FILL = (BLACK_Y,)  # output Y where no input is sampled
CHROMA_FILL = (BLACK_UV, BLACK_UV)  # output U, V likewise


def chroma_shape(shape_y: tuple[int, ...]) -> tuple[int, int]:
    """(rows, cols) of a 4:2:0 chroma plane for a Y plane of ``shape_y``."""
    return (shape_y[0] + 1) // 2, (shape_y[1] + 1) // 2


@dataclass(frozen=True)
class OutputWindow:
    """An output of (H, W) ``shape`` (even) whose pixel (x, y) shows the canvas at (x, y) + ``corner`` (x, y, sub-pixel),
    on a canvas whose target offset is ``offset_tgt`` (x, y): a moving rig's steady window (``steady.py``)."""

    corner: np.ndarray
    shape: tuple[int, int]
    offset_tgt: np.ndarray


@dataclass(frozen=True)
class FramePlan:
    """One map set made ready for planes of Y shapes ``shapes`` ((rows, cols) of the source, of the
    target): ``luma`` the Y pass's plan, ``chroma`` the U/V pass's, both of ``maps``, or with ``window``
    of that window on them (:meth:`shown_maps`)."""

    maps: PlaneMaps
    shapes: tuple[tuple[int, int], tuple[int, int]]
    luma: CompositePlan
    chroma: CompositePlan
    window: OutputWindow | None = None

    def shown_maps(self) -> PlaneMaps:
        """The maps the plans composite: ``maps``, or the window's own (``maps.windowed_plane_maps``)."""
        if self.window is None:
            return self.maps
        return windowed_plane_maps(self.maps, self.window.corner, self.window.shape, self.window.offset_tgt)


def frame_plan(maps: PlaneMaps, shapes: tuple[tuple[int, int], tuple[int, int]], cfg: Config,
               previous: FramePlan | None = None, window: OutputWindow | None = None) -> FramePlan:
    """The plans of ``maps`` for planes of Y shapes ``shapes``, or of the output ``window`` on them (each
    output pixel samples the inputs once, where the canvas position it shows does: ``composite.window_plan``,
    no map of the window made); the border blend on the device is kept from ``previous`` while it is the
    same (a blend's steps share their goal's), and a window's plan is made in the buffers of ``previous``
    where that was a window's too (the plan it replaces: no frame composites it any more)."""
    shape_src, shape_tgt = (tuple(shape[:2]) for shape in shapes)
    luma_shapes = ((*shape_src, 1), (*shape_tgt, 1))
    chroma_shapes = ((*chroma_shape(shape_src), 2), (*chroma_shape(shape_tgt), 2))
    if window is not None:
        seam_luma, seam_chroma, border = windowed_layouts(maps, window.corner, window.shape)
        corner = np.asarray(window.corner, np.float64)
        origin = np.asarray(window.offset_tgt, np.float64) - corner  # where target pixel (0, 0) sits on the window
        rows, cols = window.shape
        # The last window's plan serves no later frame: this one fills its buffers.
        last = previous if previous is not None and previous.window is not None else None
        luma = window_plan(maps.map_src_luma, corner, origin, (rows, cols), seam_luma, luma_shapes, cfg, border=border,
                           fill=LUMA_FILL, white=WHITE_Y, into=last.luma if last is not None else None)
        chroma = window_plan(maps.map_src_chroma, 0.5 * corner, 0.5 * origin, (rows // 2, cols // 2), seam_chroma,
                             chroma_shapes, cfg, fill=CHROMA_FILL, white=None, offsets=False,
                             into=last.chroma if last is not None else None)
        return FramePlan(maps, (shape_src, shape_tgt), luma, chroma, window)
    luma = composite_plan(maps.map_src_luma, maps.map_tgt_luma, maps.seam_luma, luma_shapes, cfg,
                          border=maps.border_luma, fill=LUMA_FILL, white=WHITE_Y,
                          reuse=previous.luma if previous is not None else None)
    chroma = composite_plan(maps.map_src_chroma, maps.map_tgt_chroma, maps.seam_chroma, chroma_shapes, cfg,
                            fill=CHROMA_FILL, white=None, offsets=False)
    return FramePlan(maps, (shape_src, shape_tgt), luma, chroma)


class Plans:
    """The plan of each frame's maps, or of the window on them that the frame shows (:class:`OutputWindow`
    for an output of (H, W) ``output_shape`` on a canvas whose target offset is ``offset_tgt``), made when
    the maps or the window change (a new :class:`PlaneMaps` object, another window) and, on the CPU, given
    its runs once it has served a frame (``composite.with_runs``; CUDA's per-pixel kernel takes none)."""

    def __init__(self, output_shape: tuple[int, int], offset_tgt: np.ndarray, cfg: Config):
        self._cfg = cfg
        self._output_shape = tuple(output_shape)
        self._offset_tgt = np.asarray(offset_tgt, np.float64)
        self._plan: FramePlan | None = None
        self._made_of: tuple[PlaneMaps, tuple[float, float] | None] | None = None  # the maps and window of ``_plan``
        self._served = False  # whether ``_plan`` has served a frame since it was made

    def plan(self, maps: PlaneMaps, shapes: tuple[tuple[int, int], tuple[int, int]],
             window: np.ndarray | None = None) -> FramePlan:
        """The plan of a frame composited with ``maps`` on planes of Y ``shapes``, or of the output window
        at ``window`` (x, y) on their canvas (call once per frame)."""
        plan = self._plan
        corner = None if window is None else tuple(float(v) for v in window)
        made = self._made_of
        if plan is None or made[0] is not maps or made[1] != corner or plan.shapes != shapes:
            shown = None if corner is None else OutputWindow(np.asarray(corner), self._output_shape, self._offset_tgt)
            self._plan = frame_plan(maps, shapes, self._cfg, plan, shown)
            self._made_of, self._served = (maps, corner), False
        elif not self._served:
            if self._cfg.device == "cpu":
                self._plan = replace(plan, luma=with_runs(plan.luma, self._cfg), chroma=with_runs(plan.chroma, self._cfg))
            self._served = True
        return self._plan


BAND_FIELDS = ("diff", "total", "delta")  # what ``composite.band_difference`` fills on a band's cells


class BandWordsCopy:
    """A band's plan words (``composite.band_words``) on its cells and further each side of them, made
    again only when the plan or its origin changes or the band's cells leave them: on a static plan
    once in a while, so that each frame's difference reads a small array (``band_difference_kernel``).
    ``cells``: the band's cells as the kernel takes them (their first cells on the device, as the band's
    difference reads them), ``width`` of them a line."""

    def __init__(self, cells: BandCells, width: int, device: str):
        self._cells = cells
        self._width = width
        self._device = device
        self._kernel = BandWords()
        self._kernel.first = wp.empty(cells.lines.shape[0], dtype=int, device=device)
        self._made: tuple[CompositePlan, tuple[int, int], np.ndarray] | None = None  # plan, origin, first cells
        self._held: np.ndarray | None = None  # the last band's first cells found within the copy

    def words(self, frame: FrameArrays, plan: CompositePlan, origin: tuple[int, int], x0: np.ndarray,
              reach: int) -> BandWords:
        """The copy for the band whose first cells are ``x0`` (K,) px (the host's copy of the cells'), on
        ``plan`` read at ``origin`` (``BandCells.origin``), made again (then ``reach`` cells further each
        side) where it does not hold them."""
        made = self._made
        if made is None or made[0] is not plan or made[1] != origin or not self._holds(x0):
            count = self._width + 2 * reach
            if made is None or self._kernel.words.shape[1] != count:
                self._kernel.words = wp.empty((len(x0), count), dtype=BandWord, device=self._device)
            self._cells.origin = wp.vec2i(*origin)
            band_words(frame, plan, self._cells, reach, self._kernel)
            self._made = plan, origin, np.asarray(x0, np.int64) - reach * self._cells.cell
            self._held = x0
        return self._kernel

    def _holds(self, x0: np.ndarray) -> bool:
        """Whether every line's cells from ``x0`` (K,) px lie on the copy's."""
        if x0 is self._held:
            return True
        cell = self._cells.cell
        offset = np.asarray(x0, np.int64) - self._made[2]
        held = bool(np.all((offset >= 0) & (offset % cell == 0)
                           & (offset <= cell * (self._kernel.words.shape[1] - self._width))))
        self._held = x0 if held else None
        return held


@dataclass(frozen=True)
class BandCellsOn:
    """One band of a :class:`BandBlock`: its (K, width) ``shape``, its cells as the kernel takes them
    (``cells``), its plan words (``copy``), its difference, sum and change on the device as the kernel
    fills them (``out``) and on the host (``frame``)."""

    shape: tuple[int, int]
    cells: BandCells
    copy: BandWordsCopy
    out: tuple[wp.array, wp.array, wp.array]
    frame: BandFrame


class BandBlock:
    """Bands of cells on the device, each by name in ``bands``: (``lines`` (K,) the seam lines, cells
    ``cell`` px, ``shape`` (K, width), ``x0`` the device array of each line's first cell (px)), and
    their differences, sums and changes on the host, all moved in one block counted as ``"band"``."""

    def __init__(self, bands: dict[str, tuple[np.ndarray, int, tuple[int, int], wp.array]], device: str):
        self._block = transfer.Staged({f"{name}_{field}": (shape, np.float32) for name, (_, _, shape, _) in
                                       bands.items() for field in BAND_FIELDS}, device, "band")
        self._block.zero()  # the first frame's "last difference"
        self._bands = {}
        for name, (lines, cell, shape, x0) in bands.items():
            cells = BandCells()
            cells.lines, cells.cell, cells.x0 = transfer.to_device(lines, int, device, "plan"), cell, x0
            cells.origin = wp.vec2i(0, 0)
            out = tuple(self._block.device[f"{name}_{field}"].reshape(shape) for field in BAND_FIELDS)
            frame = BandFrame.of(*(self._block.host[f"{name}_{field}"] for field in BAND_FIELDS))
            self._bands[name] = BandCellsOn(shape, cells, BandWordsCopy(cells, shape[1], device), out, frame)

    def difference(self, frame: FrameArrays, plan: CompositePlan, gains_luma: Gains, origin: tuple[int, int],
                   places: dict[str, tuple[np.ndarray, int]]) -> dict[str, BandFrame]:
        """``composite.band_difference`` of the pair loaded in ``frame`` on each band's cells, read on a
        ``plan`` whose pixel (0, 0) shows canvas pixel ``origin`` (x, y), on the host (one small download);
        ``places``: per band the host's copy of its first cells (K,) px and how many cells each side further
        its plan words are copied (:class:`BandWordsCopy`)."""
        for name, band in self._bands.items():
            words = band.copy.words(frame, plan, origin, *places[name])
            band_difference(frame, plan, words, band.cells, gains_luma, band.shape[1], band.out)
        self._block.download()
        return {name: band.frame for name, band in self._bands.items()}


class DeviceFrame:
    """The device buffers of frames whose Y planes have (rows, cols) ``shapes`` (source, target),
    composited by plans of (H, W) ``output_shape`` (even) with the per-frame seam's band ``grid`` (its
    cells on the fixed canvas of ``canvas_shape`` (H, W)); on ``cfg.device``.

    Per frame: :meth:`load`, :meth:`band`, :meth:`composite` (:meth:`set_seams`, :meth:`composite_pass` for
    each pass, the download), in that order; :meth:`canvas` after them, where the canvas is wanted too."""

    def __init__(self, shapes: tuple[tuple[int, int], tuple[int, int]], canvas_shape: tuple[int, int],
                 output_shape: tuple[int, int], grid: BandGrid, cfg: Config):
        self._cfg = cfg
        self.shapes = tuple(tuple(shape[:2]) for shape in shapes)
        self.canvas_shape, self.output_shape = tuple(canvas_shape), tuple(output_shape)
        device = cfg.device
        (rows_s, cols_s), (rows_t, cols_t) = self.shapes
        (crows_s, ccols_s), (crows_t, ccols_t) = (chroma_shape(shape) for shape in self.shapes)
        self._planes = transfer.Staged({
            "y_src": ((rows_s, cols_s), np.uint8), "y_tgt": ((rows_t, cols_t), np.uint8),
            "uv_src": ((crows_s, ccols_s, 2), np.uint8), "uv_tgt": ((crows_t, ccols_t, 2), np.uint8)}, device, "planes")
        self._out: dict[tuple[int, int], transfer.Staged] = {}  # the composited planes' block of each (H, W)
        self._grid = grid
        self._bands: tuple[ObjectGrid | None, BandBlock] | None = None  # made with the object grid it holds
        self._seams: dict[tuple[int, int], transfer.Staged] = {}  # the seams' block of each plan's (luma, chroma) lines
        self._band_x0: np.ndarray | None = None  # the seam band's cells (``BandPlace.x0``) on the device
        self._seams_set: transfer.Staged | None = None  # the block the last seams went up in
        self._arrays: dict[tuple[str, tuple[int, int]], FrameArrays] = {}

    def load(self, planes_src: tuple[np.ndarray, ...], planes_tgt: tuple[np.ndarray, ...]) -> None:
        """One frame pair's (y, u, v) planes of the source and of the target onto the device (one copy);
        U and V are interleaved as the U/V pass's two channels on the way."""
        host = self._planes.host
        for (y, u, v), side in ((planes_src, "src"), (planes_tgt, "tgt")):
            np.copyto(host[f"y_{side}"], y)
            uv = host[f"uv_{side}"]
            uv[:, :, 0] = u
            uv[:, :, 1] = v
        self._planes.upload()

    def _out_block(self, shape: tuple[int, int]) -> transfer.Staged:
        """The block the planes composited on an (H, W) ``shape`` come down in (made once per shape)."""
        if shape not in self._out:
            self._out[shape] = transfer.Staged({"y": (shape, np.uint8), "uv": ((shape[0] // 2, shape[1] // 2, 2), np.uint8)},
                                               self._cfg.device, "output")
        return self._out[shape]

    def frame_arrays(self, name: str, plan: CompositePlan) -> FrameArrays:
        """The pass's frame arrays on the plan's grid (made once a grid: the pair and output in this
        frame's blocks)."""
        key = (name, tuple(plan.canvas_shape))
        if key not in self._arrays:
            rows, cols = key[1]
            side = "y" if name == "luma" else "uv"
            planes, out = self._planes.device, self._out_block((rows, cols) if side == "y" else (2 * rows, 2 * cols)).device
            self._arrays[key] = FrameArrays.on(planes[f"{side}_src"], planes[f"{side}_tgt"], out[side], plan)
        return self._arrays[key]

    def gains(self, plan: FramePlan, luma: tuple, chroma: tuple) -> tuple[Gains, Gains]:
        """The frame's gains of each pass ((gain_src, bias_src, gain_tgt, bias_tgt) grey levels) as the
        kernels take them, with the passes' gain tables."""
        return (kernel_gains(luma, 1, plan.luma.tone, self.frame_arrays("luma", plan.luma).table),
                kernel_gains(chroma, 2, plan.chroma.tone, self.frame_arrays("chroma", plan.chroma).table))

    def band(self, plan: FramePlan, place: BandPlace, objects: ObjectGrid | None, gains_luma: Gains,
             origin: tuple[int, int] = (0, 0)) -> tuple[BandFrame, BandFrame | None]:
        """The seam band's difference, sum and change of the loaded pair on the band's cells at ``place``
        (``composite.band_difference`` with the Y pass's gains) and, on a static plan, the object band's
        on ``objects`` (``frame_objects.ObjectGrid``, the whole overlap on coarse cells), on the host in
        one small download; read on ``plan``, whose pixel (0, 0) shows canvas pixel ``origin`` (x, y).
        The seam band's cells went up with the last frame's seam (:meth:`composite`), or go up now where
        the band moved otherwise (a new map set's). The arrays are this frame's: the next call
        overwrites them."""
        block = self._seam_block(plan)
        if place.x0 is not self._band_x0:
            np.copyto(block.host["band_x0"], place.x0)
            transfer.upload(block.device["band_x0"], place.x0, "plan")
            self._band_x0 = place.x0
        if self._bands is None or self._bands[0] is not objects:
            grid = self._grid
            bands = {"seam": (grid.lines, grid.cell, grid.shape, block.device["band_x0"])}
            if objects is not None:
                bands["objects"] = (objects.lines, objects.cell, objects.shape,
                                    transfer.to_device(objects.x0, int, self._cfg.device, "plan"))
            self._bands = objects, BandBlock(bands, self._cfg.device)
        # The seam band's words reach a band's width further each side on a plan that holds (the band
        # moves round objects), none on a window's, made again every frame.
        reach = self._grid.width if plan.window is None else 0
        places = {"seam": (place.x0, reach)}
        if objects is not None:
            places["objects"] = (objects.x0, 0)
        frames = self._bands[1].difference(self.frame_arrays("luma", plan.luma), plan.luma, gains_luma, origin, places)
        return frames["seam"], frames.get("objects")

    def _seam_block(self, plan: FramePlan) -> transfer.Staged:
        """The block the frame's seam and offsets, and the next frame's seam band's cells, go up in (made
        once per plan grid's lines; the band's cells are the first block's)."""
        key = (plan.luma.lines, plan.chroma.lines)
        if key not in self._seams:
            luma, chroma = key
            block = transfer.Staged({
                "seam_luma": ((luma,), np.float32), "offsets_luma": ((2, luma), np.int32),
                "seam_chroma": ((chroma,), np.float32), "offsets_chroma": ((2, chroma * 2), np.int32),
                "band_x0": ((len(self._grid.lines),), np.int32)}, self._cfg.device, "seam")
            block.host["offsets_chroma"].fill(0)  # the U/V pass has no seam offsets
            self._seams[key] = block
        return self._seams[key]

    def composite(self, plan: FramePlan, luma: FrameState, chroma: FrameState, gains: tuple[Gains, Gains],
                  next_band: BandPlace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The loaded pair composited by ``plan`` with each pass's state (``luma`` with the seam blend's
        offsets, ``chroma`` without) and ``gains`` (:meth:`gains`): the output (y, u, v) planes, new
        arrays (one upload of the seams, with the cells of the next frame's seam band at ``next_band``; one
        download of the planes)."""
        self.set_seams(plan, luma, chroma, next_band.x0)
        self.composite_pass("luma", plan.luma, gains[0])
        self.composite_pass("chroma", plan.chroma, gains[1])
        return self._planes_of(self._out_block(tuple(plan.luma.canvas_shape)))

    def canvas(self, plan: FramePlan, luma: FrameState, chroma: FrameState, gains: tuple[Gains, Gains]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """After :meth:`composite`: the loaded pair composited again by ``plan`` (the canvas's, where the
        output is a window on it) with its states and the frame's ``gains`` (:meth:`gains`: the same
        values whichever plan's tables hold them), its (y, u, v) planes, new arrays (for an observer)."""
        self.set_seams(plan, luma, chroma, self._band_x0)
        self.composite_pass("luma", plan.luma, gains[0])
        self.composite_pass("chroma", plan.chroma, gains[1])
        return self._planes_of(self._out_block(tuple(plan.luma.canvas_shape)))

    @staticmethod
    def _planes_of(block: transfer.Staged) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``block``'s (y, u, v) planes, downloaded (one copy) into new host arrays."""
        block.download()
        uv = block.host["uv"]
        return block.host["y"].copy(), uv[:, :, 0].copy(), uv[:, :, 1].copy()

    def set_seams(self, plan: FramePlan, luma: FrameState, chroma: FrameState, band_x0: np.ndarray) -> None:
        """Both passes' seams and the Y pass's seam-blend offsets onto the device, with the seam band's
        cells ``band_x0`` (``BandPlace.x0``) for the next :meth:`band`, in one copy."""
        block = self._seam_block(plan)
        host = block.host
        np.copyto(host["seam_luma"], luma.seam)
        host["offsets_luma"][:] = np.stack([fixed_point(v) for v in luma.offsets])
        np.copyto(host["seam_chroma"], chroma.seam)
        np.copyto(host["band_x0"], band_x0)
        self._band_x0 = band_x0
        block.upload()
        self._seams_set = block

    def composite_pass(self, name: str, plan: CompositePlan, gains: Gains, per_pixel: bool | None = None) -> None:
        """One pass ("luma" or "chroma") of the loaded pair by its ``plan`` with the seams set last
        (:meth:`set_seams`; ``composite.composite``, queued on the device)."""
        block = self._seams_set
        seam = SeamState()
        seam.seam = block.device[f"seam_{name}"]
        offsets = block.device[f"offsets_{name}"]
        half = offsets.shape[0] // 2
        seam.lf_src, seam.lf_tgt = offsets[:half], offsets[half:]
        composite(self.frame_arrays(name, plan), plan, seam, gains, self._cfg, per_pixel)
