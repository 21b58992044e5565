"""A video frame on the Warp device: the plans of a map set, the frame's buffers, and the one step.

A :class:`FramePlan` is one map set made ready for the video's planes: the Y pass's plan and the U/V
pass's (U and V composited as two channels at half resolution), made once per map set
(:class:`Plans`; each row's runs are found once the plan has served a frame).

:class:`DeviceFrame` holds the frame's device memory, allocated once, and moves it as few times as a
frame allows (``kernels/transfer.py``): the decoded planes go up in one block (:meth:`DeviceFrame.load`);
the seam band's difference comes down in one small block (:meth:`DeviceFrame.band`); the frame's seam
and seam-blend offsets go up in one small block and both passes are composited, then the output
planes come down in one block for the encoder (:meth:`DeviceFrame.composite`). Nothing in a frame
waits for the device but those two downloads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..composite import (CompositePlan, FrameArrays, FrameState, band_difference, composite, composite_plan,
                         fixed_point, kernel_gains, with_runs)
from ..config import Config
from sena_warp.kernels import transfer
from sena_warp.kernels.composite import BandCells, Gains, SeamState
from .frame_seam import BandFrame, BandGrid, BandPlace
from .maps import BLACK_UV, BLACK_Y, WHITE_Y, PlaneMaps

LUMA_FILL = (BLACK_Y,)  # output Y where no input is sampled
CHROMA_FILL = (BLACK_UV, BLACK_UV)  # output U, V likewise


def chroma_shape(shape_y: tuple[int, ...]) -> tuple[int, int]:
    """(rows, cols) of a 4:2:0 chroma plane for a Y plane of ``shape_y``."""
    return (shape_y[0] + 1) // 2, (shape_y[1] + 1) // 2


@dataclass(frozen=True)
class FramePlan:
    """One map set made ready for planes of Y shapes ``shapes`` ((rows, cols) of the source, of the
    target): ``luma`` the Y pass's plan, ``chroma`` the U/V pass's, both of ``maps``."""

    maps: PlaneMaps
    shapes: tuple[tuple[int, int], tuple[int, int]]
    luma: CompositePlan
    chroma: CompositePlan


def frame_plan(maps: PlaneMaps, shapes: tuple[tuple[int, int], tuple[int, int]], cfg: Config,
               previous: FramePlan | None = None) -> FramePlan:
    """The plans of ``maps`` for planes of Y shapes ``shapes``; the border blend on the device is kept
    from ``previous`` while it is the same (a blend's steps share their goal's)."""
    shape_src, shape_tgt = (tuple(shape[:2]) for shape in shapes)
    luma = composite_plan(maps.map_src_luma, maps.map_tgt_luma, maps.seam_luma, ((*shape_src, 1), (*shape_tgt, 1)),
                          cfg, border=maps.border_luma, fill=LUMA_FILL, white=WHITE_Y,
                          reuse=previous.luma if previous is not None else None)
    chroma = composite_plan(maps.map_src_chroma, maps.map_tgt_chroma, maps.seam_chroma,
                            ((*chroma_shape(shape_src), 2), (*chroma_shape(shape_tgt), 2)), cfg, fill=CHROMA_FILL,
                            white=None, offsets=False)
    return FramePlan(maps, (shape_src, shape_tgt), luma, chroma)


class Plans:
    """The plan of each frame's maps, made when the maps change (a new :class:`PlaneMaps` object) and,
    on the CPU, given its runs once it has served a frame (``composite.with_runs``; CUDA's per-pixel
    kernel takes none)."""

    def __init__(self, cfg: Config):
        self._cfg = cfg
        self._plan: FramePlan | None = None
        self._served = False  # whether ``_plan`` has served a frame since it was made

    def plan(self, maps: PlaneMaps, shapes: tuple[tuple[int, int], tuple[int, int]]) -> FramePlan:
        """The plan of a frame composited with ``maps`` on planes of Y ``shapes`` (call once per frame)."""
        plan = self._plan
        if plan is None or plan.maps is not maps or plan.shapes != shapes:
            self._plan, self._served = frame_plan(maps, shapes, self._cfg, plan), False
        elif not self._served:
            if self._cfg.device == "cpu":
                self._plan = FramePlan(maps, shapes, with_runs(plan.luma, self._cfg), with_runs(plan.chroma, self._cfg))
            self._served = True
        return self._plan


class DeviceFrame:
    """The device buffers of frames whose Y planes have (rows, cols) ``shapes`` (source, target),
    composited by plans of the fixed canvas (``canvas_shape`` (H, W), even) with the per-frame seam's
    band ``grid``; on ``cfg.device``.

    Per frame: :meth:`load`, :meth:`band`, :meth:`composite` (:meth:`set_seams`, :meth:`composite_pass` for
    each pass, the download), in that order."""

    def __init__(self, shapes: tuple[tuple[int, int], tuple[int, int]], canvas_shape: tuple[int, int],
                 grid: BandGrid, cfg: Config):
        self._cfg = cfg
        self.shapes = tuple(tuple(shape[:2]) for shape in shapes)
        device = cfg.device
        (rows_s, cols_s), (rows_t, cols_t) = self.shapes
        (crows_s, ccols_s), (crows_t, ccols_t) = (chroma_shape(shape) for shape in self.shapes)
        height, width = canvas_shape
        self._planes = transfer.Staged({
            "y_src": ((rows_s, cols_s), np.uint8), "y_tgt": ((rows_t, cols_t), np.uint8),
            "uv_src": ((crows_s, ccols_s, 2), np.uint8), "uv_tgt": ((crows_t, ccols_t, 2), np.uint8)}, device, "planes")
        self._out = transfer.Staged({"y": ((height, width), np.uint8),
                                     "uv": ((height // 2, width // 2, 2), np.uint8)}, device, "output")
        self._grid = grid
        self._band = transfer.Staged({name: (grid.shape, np.float32) for name in ("diff", "total", "delta")}, device,
                                     "band")
        self._band.zero()  # the first frame's "last difference"
        self._band_frame = BandFrame.of(*(self._band.host[name] for name in ("diff", "total", "delta")))
        self._seam: transfer.Staged | None = None  # made with the first plan: its lines
        self._cells = BandCells()
        self._cells.lines = transfer.to_device(grid.lines, int, device, "plan")
        self._cells.cell = grid.cell
        self._place: BandPlace | None = None
        planes, out = self._planes.device, self._out.device
        self._passes = {"luma": (planes["y_src"], planes["y_tgt"], out["y"]),
                        "chroma": (planes["uv_src"], planes["uv_tgt"], out["uv"])}
        self._arrays: dict[str, FrameArrays] = {}

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

    def frame_arrays(self, name: str, plan: CompositePlan) -> FrameArrays:
        """The pass's frame arrays (made once: the pair and output in this frame's blocks)."""
        if name not in self._arrays:
            self._arrays[name] = FrameArrays.on(*self._passes[name], plan)
        return self._arrays[name]

    def gains(self, plan: FramePlan, luma: tuple, chroma: tuple) -> tuple[Gains, Gains]:
        """The frame's gains of each pass ((gain_src, bias_src, gain_tgt, bias_tgt) grey levels) as the
        kernels take them, with the passes' gain tables."""
        return (kernel_gains(luma, 1, plan.luma.tone, self.frame_arrays("luma", plan.luma).table),
                kernel_gains(chroma, 2, plan.chroma.tone, self.frame_arrays("chroma", plan.chroma).table))

    def band(self, plan: FramePlan, place: BandPlace, gains_luma: Gains) -> BandFrame:
        """The seam band's difference, sum and change of the loaded pair on the band's cells at ``place``
        (``composite.band_difference`` with the Y pass's gains), on the host (one small download; its
        cells go up when the band moves). The arrays are this frame's: the next call overwrites them."""
        if place is not self._place:
            self._cells.x0 = transfer.to_device(place.x0, int, plan.luma.device, "plan")
            self._place = place
        device = self._band.device
        band_difference(self.frame_arrays("luma", plan.luma), plan.luma, self._cells, gains_luma, self._grid.width,
                        (device["diff"].reshape(self._grid.shape), device["total"].reshape(self._grid.shape),
                         device["delta"].reshape(self._grid.shape)))
        self._band.download()
        return self._band_frame

    def _seam_block(self, plan: FramePlan) -> transfer.Staged:
        """The block the frame's seam and offsets go up in (made once: the canvas's lines are fixed)."""
        if self._seam is None:
            luma, chroma = plan.luma.lines, plan.chroma.lines
            self._seam = transfer.Staged({
                "seam_luma": ((luma,), np.float32), "offsets_luma": ((2, luma), np.int32),
                "seam_chroma": ((chroma,), np.float32), "offsets_chroma": ((2, chroma * 2), np.int32)},
                self._cfg.device, "seam")
            self._seam.host["offsets_chroma"].fill(0)  # the U/V pass has no seam offsets
        return self._seam

    def composite(self, plan: FramePlan, luma: FrameState, chroma: FrameState, gains: tuple[Gains, Gains]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The loaded pair composited by ``plan`` with each pass's state (``luma`` with the seam blend's
        offsets, ``chroma`` without) and ``gains`` (:meth:`gains`): the output's (y, u, v) planes, new
        arrays (one upload of the seams, one download of the planes)."""
        self.set_seams(plan, luma, chroma)
        self.composite_pass("luma", plan.luma, gains[0])
        self.composite_pass("chroma", plan.chroma, gains[1])
        self._out.download()
        uv = self._out.host["uv"]
        return self._out.host["y"].copy(), uv[:, :, 0].copy(), uv[:, :, 1].copy()

    def set_seams(self, plan: FramePlan, luma: FrameState, chroma: FrameState) -> None:
        """Both passes' seams and the Y pass's seam-blend offsets onto the device, in one copy."""
        block = self._seam_block(plan)
        host = block.host
        np.copyto(host["seam_luma"], luma.seam)
        host["offsets_luma"][:] = np.stack([fixed_point(v) for v in luma.offsets])
        np.copyto(host["seam_chroma"], chroma.seam)
        block.upload()

    def composite_pass(self, name: str, plan: CompositePlan, gains: Gains, per_pixel: bool | None = None) -> None:
        """One pass ("luma" or "chroma") of the loaded pair by its ``plan`` with the seams set last
        (``composite.composite``, queued on the device)."""
        block = self._seam
        seam = SeamState()
        seam.seam = block.device[f"seam_{name}"]
        offsets = block.device[f"offsets_{name}"]
        half = offsets.shape[0] // 2
        seam.lf_src, seam.lf_tgt = offsets[:half], offsets[half:]
        composite(self.frame_arrays(name, plan), plan, seam, gains, self._cfg, per_pixel)
