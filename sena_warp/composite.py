"""Apply the canvas maps and the seam to a frame pair: the per-frame path of images and videos.

Three values and one step. A :class:`CompositePlan` is one map set made ready, once, for inputs of one
(source, target) shape on the Warp device: the fixed-point plan of ``kernels/composite.py`` (what
depends on the maps alone), the static seam, the border blend, the fill and the highlight knee; it
never changes (:func:`with_runs` gives the same plan with each row's runs, found once it has served a
frame). A :class:`FrameState` is what a frame sets: the seam (re-optimised in its band for a video),
each side's gains and the seam blend's low-frequency offsets. :func:`composite` launches the step on
the device buffers of one frame (:class:`FrameArrays`): on the CPU the target's gain table, each
row's runs for the frame's seam and the row-run frame kernel; on CUDA the per-pixel frame kernel (the
same planes). :func:`composite_image` does all of it for one image pair.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
import warp as wp

from sena_warp.config import Config
from sena_warp.kernels import runtime, transfer
from sena_warp.kernels.composite import (COMPOSITE_FRAME_KERNELS, COMPOSITE_PIXEL_KERNELS, MAX_CHANNELS, BandCells,
                                        BandWords, Border, Gains, Layout, Plan, Planes, RowRuns, SeamState,
                                        band_difference_kernel, band_words_kernel, composite_plan_kernel, frame_runs_kernel,
                                        gain_table_kernel, row_runs_kernel, seam_weights_kernel,
                                        Window, window_plan_kernel)
from sena_warp.warp_map import as_channels

GAIN_ONE = 1 << 12  # kernel gains in 1/4096
LEVEL = 1 << 20  # kernel biases and offsets in 1/2**20 grey levels
RUN_MARGIN_PX = 1.0  # runs keep this much further from the seam's reach than its offsets: float32 rounding
IDENTITY = (np.ones(MAX_CHANNELS), np.zeros(MAX_CHANNELS))


@dataclass(frozen=True)
class SeamLayout:
    """Where the seam runs on the canvas and how wide its parts are (canvas pixels, input frame).

    ``positions`` (L,) float32: the seam's position per line; a line is a canvas row when
    ``lines_are_rows`` (the seam's x per row; the source is left of it), else a canvas column (the
    seam's y per column; the source is above it). ``band_px``: half-width of the band in which the
    frame's seam may move (both sides are kept there); ``transition_px`` and ``smooth_sigma_px``: the
    mix across the seam (``kernels/seam.py``'s ``source_alpha``); ``lf_px``: half-width over which the
    low-frequency offsets fade to 0.
    """

    positions: np.ndarray
    lines_are_rows: bool
    band_px: float
    transition_px: float
    smooth_sigma_px: float
    lf_px: float

    def kernel(self) -> Layout:
        """The layout as the kernels take it."""
        layout = Layout()
        layout.lines_are_rows = int(self.lines_are_rows)
        layout.band_px = float(self.band_px)
        layout.transition_px = float(self.transition_px)
        layout.smooth_sigma_px = float(self.smooth_sigma_px)
        layout.lf_px = float(self.lf_px)
        return layout

    def reach_px(self) -> float:
        """How far from the static seam the frame's seam may go: the band less half the transition."""
        return max(self.band_px - 0.5 * self.transition_px, 0.0)


def lf_weights(distance: np.ndarray, lf_px: float) -> np.ndarray:
    """How much of a low-frequency offset a pixel at ``distance`` from its seam or border gets: the
    frame kernel's ``lf_weight`` on the host (1 there, linearly 0 at ``lf_px`` > 0)."""
    return np.maximum(0.0, 1.0 - np.abs(distance) / lf_px)


def fixed_point(values: np.ndarray) -> np.ndarray:
    """Grey levels (any shape) as the kernels' int32 in 1/2**20 grey levels, flat."""
    return np.rint(np.ascontiguousarray(values, np.float64).ravel() * LEVEL).astype(np.int32)


@dataclass(frozen=True)
class BorderBlend:
    """The border blend's low-frequency offsets of each side along the target's two borders (grey
    levels at the border, or relative changes of the gain for a frame with ``relative_offsets``, fading
    like the seam's over ``lf_px``): border k lies at line coordinate
    ``lines[k]``; ``src``, ``tgt`` (2, P, C) float32, P positions along it (canvas columns when lines
    are rows, else rows)."""

    lines: tuple[float, float]
    src: np.ndarray
    tgt: np.ndarray


@dataclass(frozen=True)
class FrameState:
    """What one frame sets: ``seam`` (L,) float32 its seam per line as composited (kept within the band
    around the static seam, :func:`clipped_seam`); ``gains`` (gain_src, bias_src, gain_tgt, bias_tgt),
    each (C,) grey levels; ``offsets`` (src, tgt), each (L, C) grey levels, the seam blend's offsets
    per line, or None (none: a chroma pass). ``relative_offsets``: the seam's and the border blend's
    offsets are relative changes of each side's gain (0.05: 5 % brighter there, a smooth gain that
    changes no colour or contrast), not grey levels added."""

    seam: np.ndarray
    gains: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    offsets: tuple[np.ndarray, np.ndarray] | None = None
    relative_offsets: bool = False


def clipped_seam(positions: np.ndarray, layout: SeamLayout) -> np.ndarray:
    """(L,) float32: a frame's seam ``positions`` kept within the band around the static seam
    (``layout.reach_px()`` either side): where the plan keeps both views."""
    static, reach = layout.positions, layout.reach_px()
    return np.clip(positions, static - reach, static + reach).astype(np.float32)


def kernel_gains(gains: Sequence, channels: int, tone: wp.vec3i, table: wp.array, relative: bool = False) -> Gains:
    """(gain_src, bias_src, gain_tgt, bias_tgt) grey levels of ``channels`` channels as the kernels take
    them (fixed point), with the highlight knee ``tone`` and the target's gain ``table`` to fill;
    ``relative``: the offsets change the gains relatively (:class:`FrameState`'s ``relative_offsets``)."""
    def vec(values, default, unit):
        v = np.array(default, np.float64)
        v[:channels] = values
        return wp.vec4i(*np.rint(v * unit).astype(int).tolist())

    fixed = Gains()
    gain_src, bias_src, gain_tgt, bias_tgt = gains
    fixed.gain_src = vec(gain_src, IDENTITY[0], GAIN_ONE)
    fixed.bias_src = vec(bias_src, IDENTITY[1], LEVEL)
    fixed.gain_tgt = vec(gain_tgt, IDENTITY[0], GAIN_ONE)
    fixed.bias_tgt = vec(bias_tgt, IDENTITY[1], LEVEL)
    fixed.tone = tone
    fixed.relative = int(relative)
    fixed.table = table
    return fixed


def applied_gains(fixed: Gains, channels: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The gains a frame is composited with, back in grey levels: each (channels,) float64."""
    units = (GAIN_ONE, LEVEL, GAIN_ONE, LEVEL)
    values = (fixed.gain_src, fixed.bias_src, fixed.gain_tgt, fixed.bias_tgt)
    return tuple(np.array(list(v)[:channels], np.float64) / unit for v, unit in zip(values, units))


@dataclass(frozen=True)
class CompositePlan:
    """One map set on the Warp device for inputs of (H, W, C) ``shapes`` (source, target): made by
    :func:`composite_plan`, never changed.

    ``words`` / ``words_tgt`` (Hc * Wc,) int64 the plan (``kernels/composite.py``); ``coverage`` (Hc, Wc)
    uint8 255 where a side is sampled; ``seam`` the static seam (``layout.positions``) on the device;
    ``border`` the border blend as the kernels take it (``border_source``: its host values, or None);
    ``fill`` the value per channel where no side is sampled; ``tone`` the highlight knee in kernel units
    (``knee``: (knee, white) grey levels, or None; its third: 1 where it follows each colour pixel's
    largest channel, ``Config.gain_knee_peak``); ``reach_px`` how far from a frame's seam its offsets
    change a pixel (with the float32 margin); ``runs`` each row's runs (``RowRuns``, found by
    :func:`with_runs`) or None.
    """

    canvas_shape: tuple[int, int]
    shapes: tuple[tuple[int, int, int], tuple[int, int, int]]
    layout: SeamLayout
    device: str
    words: wp.array
    words_tgt: wp.array
    coverage: wp.array
    seam: wp.array
    border: Border
    border_source: BorderBlend | None
    fill: tuple[int, ...]
    knee: tuple[float, float] | None
    tone: wp.vec3i
    reach_px: float
    runs: wp.array | None = None

    @property
    def channels(self) -> int:
        return self.shapes[0][2]

    @property
    def lines(self) -> int:
        return len(self.layout.positions)

    @property
    def knee_peak(self) -> bool:
        """Whether near white a pixel's channels share its largest one's knee (``tone``'s third)."""
        return bool(self.tone[2])


def _border_on_device(border: BorderBlend | None, positions: int, channels: int, device: str) -> Border:
    """The border blend as the kernels take it (off, with empty offsets, for None)."""
    kernel = Border()
    if border is None:
        none = wp.zeros(1, dtype=int, device=device)
        kernel.on, kernel.lines, kernel.second, kernel.src, kernel.tgt = 0, wp.vec2(0.0, 0.0), 0, none, none
        return kernel
    if border.src.shape != (2, positions, channels) or border.tgt.shape != border.src.shape:
        raise ValueError(f"border offsets need shape (2, {positions}, {channels}), got {border.src.shape} "
                         f"and {border.tgt.shape}")
    kernel.on, kernel.lines, kernel.second = 1, wp.vec2(*border.lines), positions * channels
    kernel.src, kernel.tgt = (transfer.to_device(fixed_point(v), int, device, "plan") for v in (border.src, border.tgt))
    return kernel


def composite_plan(map_src_canvas: np.ndarray, map_tgt_canvas: np.ndarray, layout: SeamLayout,
                   shapes: tuple[tuple[int, ...], tuple[int, ...]], cfg: Config, *, border: BorderBlend | None = None,
                   fill: Sequence[int] | None = None, white: float | None = 255.0, offsets: bool = True,
                   reuse: CompositePlan | None = None) -> CompositePlan:
    """The plan of one map set for inputs of ``shapes`` ((H, W, C) of the source, of the target).

    ``map_src_canvas``, ``map_tgt_canvas``: (Hc, Wc, 2) float32 (x, y) sample positions in the source /
    target (input frame), NaN where nothing may be sampled; ``layout``: the seam; ``border``: the
    border blend or None; ``fill``: the C values where no side is sampled (default 0); ``white``: the
    images' white level, where the gains' highlight knee runs to (None: no knee, for planes without
    one such as chroma); ``offsets``: whether frames carry seam offsets (the runs keep clear of their
    reach). On ``cfg.device`` (resolved), the maps uploaded (used in place on the CPU when read-only:
    nothing may change them). ``reuse``: a plan whose border blend (the same values) is kept on the
    device instead of uploaded again.
    """
    canvas_shape = tuple(np.asarray(map_src_canvas).shape[:2])
    if map_tgt_canvas.shape[:2] != canvas_shape:
        raise ValueError("map_src_canvas and map_tgt_canvas must share one (Hc, Wc)")
    maps = [transfer.for_reading(map_src_canvas, wp.vec2, cfg.device, "plan"),
            transfer.for_reading(map_tgt_canvas, wp.vec2, cfg.device, "plan")]
    return _planned(composite_plan_kernel, maps, canvas_shape, layout, shapes, cfg, border, fill, white, offsets, reuse)


def window_plan(map_src_canvas: np.ndarray, corner: np.ndarray, origin_tgt: np.ndarray, shape: tuple[int, int],
                layout: SeamLayout, shapes: tuple[tuple[int, ...], tuple[int, ...]], cfg: Config, *,
                border: BorderBlend | None = None, fill: Sequence[int] | None = None, white: float | None = 255.0,
                offsets: bool = True, into: CompositePlan | None = None) -> CompositePlan:
    """:func:`composite_plan` of an output window of (H, W) ``shape`` on a canvas whose source map is
    ``map_src_canvas``: window pixel (x, y) shows canvas (x, y) + ``corner`` (x, y, sub-pixel), sampling
    the source where the canvas map does there (bilinearly, NaN where a counted tap is NaN or off the
    canvas) and the target at (x, y) - ``origin_tgt``; ``layout`` and ``border`` are the window's. The
    plan of the window's own maps (``video.maps.windowed_plane_maps``) without making them: one kernel.
    ``into``: a plan of the same grid that no frame composites any more (the window's of the last frame),
    whose device buffers this one fills instead of new ones (a new window every frame: no fresh memory)."""
    corner = np.asarray(corner, np.float64)
    whole = np.floor(corner)
    window = Window()
    window.whole = wp.vec2i(*(int(v) for v in whole))
    window.frac = wp.vec2(*(float(v) for v in corner - whole))
    window.origin_tgt = wp.vec2(*(float(v) for v in origin_tgt))
    inputs = [transfer.for_reading(map_src_canvas, wp.vec2, cfg.device, "plan"), window]
    return _planned(window_plan_kernel, inputs, tuple(int(v) for v in shape), layout, shapes, cfg, border, fill, white,
                    offsets, None, into)


def _planned(kernel, maps: list, canvas_shape: tuple[int, int], layout: SeamLayout,
             shapes: tuple[tuple[int, ...], tuple[int, ...]], cfg: Config, border: BorderBlend | None,
             fill: Sequence[int] | None, white: float | None, offsets: bool, reuse: CompositePlan | None,
             into: CompositePlan | None = None) -> CompositePlan:
    """The plan of a (Hc, Wc) ``canvas_shape`` made by ``kernel`` (``composite_plan_kernel`` or
    ``window_plan_kernel``, whose inputs before the seam are ``maps``), in the buffers of ``into`` where
    it has the same grid on the same device; the rest as :func:`composite_plan`."""
    lines = canvas_shape[0] if layout.lines_are_rows else canvas_shape[1]
    if layout.positions.shape != (lines,):
        raise ValueError(f"the seam needs one position per line ({lines}), got {layout.positions.shape}")
    shape_src, shape_tgt = (tuple(int(v) for v in shape) for shape in shapes)
    if shape_src[2] != shape_tgt[2]:
        raise ValueError(f"source has {shape_src[2]} channels, target {shape_tgt[2]}")
    channels = shape_src[2]
    if channels > MAX_CHANNELS:
        raise ValueError(f"images have {channels} channels; at most {MAX_CHANNELS} are supported")
    values = [int(v) for v in fill] if fill is not None else [0] * channels
    if len(values) != channels:
        raise ValueError(f"fill has {len(values)} values for {channels} channels")
    device = cfg.device
    pixels = canvas_shape[0] * canvas_shape[1]
    if into is not None and into.canvas_shape == canvas_shape and into.device == device:
        words, words_tgt, coverage = into.words, into.words_tgt, into.coverage
    else:
        words = wp.empty(pixels, dtype=wp.int64, device=device)
        words_tgt = wp.empty(pixels, dtype=wp.int64, device=device)  # read for band pixels only
        coverage = wp.empty(canvas_shape, dtype=wp.uint8, device=device)
    seam = transfer.to_device(np.ascontiguousarray(layout.positions, np.float32), float, device, "plan")
    inputs = [*maps, seam, layout.kernel(), wp.vec3i(*shape_src), wp.vec3i(*shape_tgt), words, words_tgt, coverage]
    runtime.launch_row_loops(kernel, *canvas_shape, inputs, device, cfg.cpu_threads)
    positions = canvas_shape[1] if layout.lines_are_rows else canvas_shape[0]
    if reuse is not None and reuse.border_source is border and reuse.device == device:
        kernel_border = reuse.border
    else:
        kernel_border = _border_on_device(border, positions, channels, device)
    knee = None if white is None else (float(white) * cfg.gain_knee_ratio, float(white))
    knee_level, white_level = knee or (0.0, 0.0)
    knee_peak = cfg.gain_knee_peak and channels >= 3  # a colour pixel's channels; a plane (a video's Y) is its own
    reach = (max(layout.lf_px, 0.0) if offsets else 0.0) + RUN_MARGIN_PX
    return CompositePlan(canvas_shape, (shape_src, shape_tgt), layout, device, words, words_tgt, coverage, seam,
                         kernel_border, border, tuple(values), knee,
                         wp.vec3i(int(round(knee_level * LEVEL)), int(round(white_level * LEVEL)), int(knee_peak)),
                         reach)


def with_runs(plan: CompositePlan, cfg: Config) -> CompositePlan:
    """``plan`` with each canvas row's longest runs of one side alone that no offset reaches
    (``row_runs_kernel``): the CPU frame kernel copies the target's through its gain table and samples the
    source's with its gains alone.

    Where the lines are rows, the plan's runs ignore the seam and each frame's are cut around its seam
    (:func:`frame_runs`). Else they keep clear of wherever the frame's seam may be, and serve every
    frame as they are: it stays within ``layout.reach_px()`` of the static seam (:func:`clipped_seam`),
    its offsets reach ``plan.reach_px`` beyond that.

    A video looks for a plan's runs once the plan has served a frame: a plan made anew every frame (maps
    being blended in, a moving rig's steady window) would cost more to scan than its runs save (a window's
    target, shifted by a fraction of a pixel, has no copy runs; sampled, they saved 0.4 ms of a house frame
    against 2 ms to find them)."""
    layout = plan.layout
    clear_px = 0.0 if layout.lines_are_rows else layout.reach_px() + plan.reach_px
    runs = wp.empty(plan.canvas_shape[0], dtype=RowRuns, device=plan.device)
    inputs = [plan.canvas_shape[1], plan.words, plan.seam, layout.kernel(), clear_px, plan.border, plan.channels,
              runs]
    runtime.launch_rows(row_runs_kernel, plan.canvas_shape[0], 1, inputs, plan.device, cfg.cpu_threads)
    return replace(plan, runs=runs)


@dataclass(frozen=True)
class FrameArrays:
    """The device arrays one frame of a plan's shapes is composited in: the pair (``planes``: flat
    source and target and their steps), ``out`` (Hc * Wc * C,) uint8, and scratch filled per frame: the
    target's gain ``table`` (C * 256,) uint8 and each row's ``runs`` for the frame's seam. ``no_runs``:
    every row's runs empty (a plan without runs yet)."""

    planes: Planes
    out: wp.array
    table: wp.array
    runs: wp.array
    no_runs: wp.array

    @staticmethod
    def on(src: wp.array, tgt: wp.array, out: wp.array, plan: CompositePlan) -> "FrameArrays":
        """Frame arrays over flat device arrays ``src``, ``tgt`` (the plan's input shapes) and ``out``."""
        shape_src, shape_tgt = plan.shapes
        channels = plan.channels
        planes = Planes()
        planes.src, planes.tgt = src, tgt
        planes.steps = wp.vec4i(
            channels * min(1, shape_src[1] - 1), channels * shape_src[1] * min(1, shape_src[0] - 1),
            channels * min(1, shape_tgt[1] - 1), channels * shape_tgt[1] * min(1, shape_tgt[0] - 1),
        )
        rows = plan.canvas_shape[0]
        return FrameArrays(planes, out, wp.empty(channels * 256, dtype=wp.uint8, device=plan.device),
                           wp.empty(rows, dtype=RowRuns, device=plan.device),
                           wp.zeros(rows, dtype=RowRuns, device=plan.device))


def frame_runs(plan: CompositePlan, seam: wp.array, scratch: wp.array, none: wp.array) -> wp.array:
    """Each canvas row's runs for a frame whose seam is ``seam`` (device array): the plan's runs cut
    ``plan.reach_px`` from it where the lines are rows (``frame_runs_kernel``, into ``scratch``), else the
    plan's as they are; ``none`` (every row's runs empty) for a plan without runs."""
    if plan.runs is None:
        return none
    if not plan.layout.lines_are_rows:
        return plan.runs
    inputs = [plan.runs, seam, plan.reach_px, scratch]
    runtime.launch_rows(frame_runs_kernel, plan.canvas_shape[0], 1, inputs, plan.device, runtime.BAND_THREADS)
    return scratch


def kernel_plan(plan: CompositePlan, runs: wp.array) -> Plan:
    """The plan as the frame kernels take it, with this frame's ``runs``."""
    kernel = Plan()
    kernel.words, kernel.words_tgt, kernel.runs = plan.words, plan.words_tgt, runs
    kernel.size = wp.vec2i(plan.canvas_shape[1], plan.canvas_shape[0])
    kernel.fill = wp.vec4i(*plan.fill, *[0] * (MAX_CHANNELS - plan.channels))
    return kernel


def composite(frame: FrameArrays, plan: CompositePlan, seam: SeamState, gains: Gains, cfg: Config,
              per_pixel: bool | None = None) -> None:
    """The compositing step: the pair loaded in ``frame`` composited by ``plan`` with the frame's ``seam``
    (its positions and offsets on the device) and ``gains`` (:func:`kernel_gains` with ``frame.table``)
    into ``frame.out``, queued on the device (a download waits for it). ``per_pixel`` None: on the CPU
    the row-run kernel (one thread per row, the target's gain table filled first for its copy runs), on
    CUDA the per-pixel kernel; True or False forces one (they give the same planes)."""
    channels = plan.channels
    layout = plan.layout.kernel()
    if per_pixel if per_pixel is not None else plan.device != "cpu":
        inputs = [frame.planes, kernel_plan(plan, frame.no_runs), seam, layout, plan.border, gains, frame.out]
        runtime.launch_rows(COMPOSITE_PIXEL_KERNELS[channels], *plan.canvas_shape, inputs, plan.device,
                            cfg.cpu_threads)
        return
    wp.launch(gain_table_kernel, dim=channels * 256, inputs=[gains.gain_tgt, gains.bias_tgt, gains.tone, frame.table],
              device=plan.device, stream=transfer.stream(plan.device))
    runs = frame_runs(plan, seam.seam, frame.runs, frame.no_runs)
    inputs = [frame.planes, kernel_plan(plan, runs), seam, layout, plan.border, gains, frame.out]
    runtime.launch_row_loops(COMPOSITE_FRAME_KERNELS[channels], *plan.canvas_shape, inputs, plan.device,
                             cfg.cpu_threads)


def band_words(frame: FrameArrays, plan: CompositePlan, band: BandCells, reach: int, out: BandWords) -> None:
    """The plan's words on the band's cells (``band``) and ``reach`` cells further each side into ``out``
    (its ``first`` (K,) and ``words`` (K, width) on the plan's device, each line's width band cells plus
    2 x ``reach``): (source's, target's) where the plan holds both taps, (0, 0) elsewhere
    (``band_words_kernel``); ``frame``: the plan's frame arrays."""
    inputs = [kernel_plan(plan, frame.no_runs), plan.layout.kernel(), band, reach, out]
    runtime.launch_row_loops(band_words_kernel, band.lines.shape[0], out.words.shape[1], inputs, plan.device,
                             runtime.BAND_THREADS)


def band_difference(frame: FrameArrays, plan: CompositePlan, words: BandWords, band: BandCells, gains: Gains,
                    width: int, out: tuple[wp.array, wp.array, wp.array]) -> None:
    """Channel 0 of the pair loaded in ``frame``, source minus target and source plus target with their
    gains (grey levels), on the band's cells (``band``: K lines of ``width`` cells, their words of
    ``plan`` in ``words``, :func:`band_words` on cells reaching as far): into ``out`` = (diff, total,
    delta), each (K, width) float on the plan's device; ``NOT_BOTH`` and 0 where a cell does not hold
    both views; delta = |diff - the value diff held| (the last frame's), 0 where either lacks a view
    (``band_difference_kernel``)."""
    inputs = [frame.planes, words, band, gains, *out]
    runtime.launch_row_loops(band_difference_kernel, band.lines.shape[0], width, inputs, plan.device,
                             runtime.BAND_THREADS)


def seam_state(state: FrameState, plan: CompositePlan) -> SeamState:
    """The frame's seam and offsets on the plan's device (two uploads, one with its offsets): for an
    image; a video moves every pass's in one block."""
    kernel = SeamState()
    kernel.seam = transfer.to_device(state.seam.astype(np.float32), float, plan.device, "seam")
    offsets = state.offsets if state.offsets is not None else (np.zeros((plan.lines, plan.channels)),) * 2
    values = np.stack([fixed_point(v) for v in offsets])
    both = transfer.to_device(values, int, plan.device, "seam")
    kernel.lf_src, kernel.lf_tgt = both[0], both[1]
    return kernel


def composite_image(img_src: np.ndarray, img_tgt: np.ndarray, plan: CompositePlan, state: FrameState,
                    cfg: Config, per_pixel: bool | None = None) -> np.ndarray:
    """The panorama of one pair of uint8 images (H, W, C) or planes (H, W) of the plan's shapes: a new
    (Hc, Wc, C) uint8 array, or (Hc, Wc) for planes (``per_pixel`` as :func:`composite`'s)."""
    src3, tgt3 = as_channels(img_src), as_channels(img_tgt)
    if (src3.shape, tgt3.shape) != plan.shapes:
        raise ValueError(f"images of shapes {src3.shape} and {tgt3.shape} for a plan of {plan.shapes}")
    out = wp.empty(plan.canvas_shape[0] * plan.canvas_shape[1] * plan.channels, dtype=wp.uint8, device=plan.device)
    frame = FrameArrays.on(transfer.to_device(src3.ravel(), wp.uint8, plan.device, "planes"),
                           transfer.to_device(tgt3.ravel(), wp.uint8, plan.device, "planes"), out, plan)
    gains = kernel_gains(state.gains, plan.channels, plan.tone, frame.table, state.relative_offsets)
    composite(frame, plan, seam_state(state, plan), gains, cfg, per_pixel)
    image = transfer.download(out, "output").reshape(*plan.canvas_shape, plan.channels).copy()
    return image[:, :, 0] if np.ndim(img_src) == 2 else image


def coverage(plan: CompositePlan) -> np.ndarray:
    """(Hc, Wc) uint8 255 where at least one side of the plan's inputs is sampled, else 0."""
    return transfer.download(plan.coverage, "coverage").copy()


def seam_weights(seam: np.ndarray, layout: SeamLayout, canvas_shape: tuple[int, int], cfg: Config
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(alpha, lf) (Hc, Wc) float32 for a frame's ``seam`` (L,): the source weight where both views are
    valid and the weight of the low-frequency offsets (the frame kernel's rule)."""
    alpha = wp.empty(canvas_shape, dtype=float, device=cfg.device)
    lf = wp.empty(canvas_shape, dtype=float, device=cfg.device)
    positions = transfer.to_device(np.ascontiguousarray(seam, np.float32), float, cfg.device, "figures")
    runtime.launch_rows(seam_weights_kernel, *canvas_shape, [positions, layout.kernel(), alpha, lf], cfg.device,
                        cfg.cpu_threads)
    return transfer.download(alpha, "figures").copy(), transfer.download(lf, "figures").copy()


def border_offsets(plan: CompositePlan) -> tuple[np.ndarray, np.ndarray]:
    """The border blend's offsets per canvas pixel (Hc, Wc, C) float32 of each side, as the frame
    kernel adds them (zeros without a border blend), for figures and reference implementations."""
    channels = plan.channels
    height, width = plan.canvas_shape
    border = plan.border_source
    if border is None:
        zeros = np.zeros((height, width, channels), np.float32)
        return zeros, zeros.copy()
    rows = plan.layout.lines_are_rows
    line = np.arange(height if rows else width, dtype=np.float32)
    lf_px = max(plan.layout.lf_px, 1e-6)
    weights = [lf_weights(line - np.float32(border.lines[k]), lf_px) for k in range(2)]

    def spread(values: np.ndarray) -> np.ndarray:
        along = fixed_point(values).reshape(2, -1, channels) / LEVEL
        if rows:
            total = sum(weights[k][:, None, None] * along[k][None, :, :] for k in range(2))
        else:
            total = sum(weights[k][None, :, None] * along[k][:, None, :] for k in range(2))
        return total.astype(np.float32)

    return spread(border.src), spread(border.tgt)


def row_runs(plan: CompositePlan, seam: np.ndarray, cfg: Config) -> np.ndarray:
    """(Hc, 5) int32 per canvas row: the runs the frame kernel takes for a frame whose seam is ``seam``
    (L,) with ``plan``'s runs (:func:`with_runs`): columns [a, b) it copies from the target through the
    gains alone, the copy's target element at column 0, and columns [a, b) it samples from the source
    with its gains alone (a = b where a row has none)."""
    rows = plan.canvas_shape[0]
    scratch, none = (wp.zeros(rows, dtype=RowRuns, device=plan.device) for _ in range(2))
    positions = transfer.to_device(np.ascontiguousarray(seam, np.float32), float, plan.device, "figures")
    return transfer.download(frame_runs(plan, positions, scratch, none), "figures").copy()
