"""Apply the canvas maps and the seam to a frame pair: the per-frame path of images and videos.

``Compositor`` uploads the maps to the Warp device once and turns them, once per input shape, into a
fixed-point plan (see ``kernels/composite.py``). Per frame it takes the two images and, when they
change, the seam positions (video: the seam re-optimised in its band), the per-side gains and the
seam blend's low-frequency offsets (per seam line, and per position along the target's two borders
beyond the seam's ends); one integer-plan kernel launch composites the frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
import warp as wp

from sena_warp.config import Config
from sena_warp.kernels import runtime
from sena_warp.kernels.composite import (COMPOSITE_FRAME_KERNELS, MAX_CHANNELS, RowRuns, band_difference_kernel,
                                        composite_plan_kernel, frame_runs_kernel, gain_table_kernel,
                                        row_runs_kernel, seam_weights_kernel)
from sena_warp.warp_map import as_channels


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


IDENTITY = (np.ones(MAX_CHANNELS), np.zeros(MAX_CHANNELS))


def lf_weights(distance: np.ndarray, lf_px: float) -> np.ndarray:
    """How much of a low-frequency offset a pixel at ``distance`` from its seam or border gets: the
    frame kernel's ``lf_weight`` on the host (1 there, linearly 0 at ``lf_px`` > 0)."""
    return np.maximum(0.0, 1.0 - np.abs(distance) / lf_px)
GAIN_ONE = 1 << 12  # kernel gains in 1/4096
RUN_MARGIN_PX = 1.0  # runs keep this much further from the seam's reach than its offsets: float32 rounding
LEVEL = 1 << 20  # kernel biases and offsets in 1/2**20 grey levels


class _Buffers:
    """Warp arrays for one (src shape, tgt shape) pair: inputs, host staging, plan, outputs."""

    def __init__(self, shape_src: tuple, shape_tgt: tuple, canvas_shape: tuple[int, int], device: str):
        channels = shape_src[2]
        pixels = canvas_shape[0] * canvas_shape[1]
        self.src = wp.empty(shape_src, dtype=wp.uint8, device=device)
        self.tgt = wp.empty(shape_tgt, dtype=wp.uint8, device=device)
        self.out = wp.empty((*canvas_shape, channels), dtype=wp.uint8, device=device)
        self.coverage = wp.empty(canvas_shape, dtype=wp.uint8, device=device)
        self.plan = wp.empty(pixels, dtype=wp.int64, device=device)
        self.plan_tgt = wp.empty(pixels, dtype=wp.int64, device=device)  # read for band pixels only
        self.plan_ready = False
        self.runs = wp.empty(canvas_shape[0], dtype=RowRuns, device=device)  # each row's runs
        self.runs_ready = False  # made anew with the plan and with the border blend
        self.plan_served = False  # whether a frame has been composited with the plan since it was made
        self.runs_clear_px = 0.0  # how far from the static seam the runs were made to keep
        self.frame_runs = wp.empty(canvas_shape[0], dtype=RowRuns, device=device)  # this frame's
        self.table = wp.empty(channels * 256, dtype=wp.uint8, device=device)  # the target's gains, per frame
        steps = wp.vec4i(
            channels * min(1, shape_src[1] - 1), channels * shape_src[1] * min(1, shape_src[0] - 1),
            channels * min(1, shape_tgt[1] - 1), channels * shape_tgt[1] * min(1, shape_tgt[0] - 1),
        )
        self.frame_inputs = [self.src.flatten(), self.tgt.flatten(), steps, self.plan, self.plan_tgt]
        self.out_flat = self.out.flatten()
        on_cpu = device == "cpu"
        self.src_host = self.src if on_cpu else wp.empty(shape_src, dtype=wp.uint8, device="cpu", pinned=True)
        self.tgt_host = self.tgt if on_cpu else wp.empty(shape_tgt, dtype=wp.uint8, device="cpu", pinned=True)


class Compositor:
    """The panorama of a frame pair from the source / target maps and the seam, on the Warp device.

    ``map_src_canvas``, ``map_tgt_canvas``: (Hc, Wc, 2) float32 (x, y) sample positions in the source
    / target (input frame); ``seam``: its layout. Runs on ``cfg.device`` (resolved,
    ``runtime.resolve_config``) with ``cfg.cpu_threads``. Gains default to the identity and offsets to
    zero until set; ``white``: the images' white level, where the gains' highlight knee runs to (None:
    no knee, for planes without one such as chroma). ``relative_offsets``: the seam's and the borders'
    low-frequency offsets are relative changes of each side's gain (0.05: 5 % brighter there), not
    grey levels added.
    """

    def __init__(self, map_src_canvas: np.ndarray, map_tgt_canvas: np.ndarray, seam: SeamLayout, cfg: Config,
                 white: float | None = 255.0, relative_offsets: bool = False):
        self.relative_offsets = bool(relative_offsets)
        device, threads = cfg.device, cfg.cpu_threads
        # The gains' highlight knee (``gains.tone_curve``): at gain_knee_ratio x the white level of the
        # images composited (None: no knee, e.g. chroma planes).
        self._knee = None if white is None else (float(white) * cfg.gain_knee_ratio, float(white))
        knee, white_level = self._knee or (0.0, 0.0)
        self.tone = wp.vec2i(int(round(knee * LEVEL)), int(round(white_level * LEVEL)))
        self.canvas_shape = tuple(np.asarray(map_src_canvas).shape[:2])
        if map_tgt_canvas.shape[:2] != self.canvas_shape:
            raise ValueError("map_src_canvas and map_tgt_canvas must share one (Hc, Wc)")
        lines = self.canvas_shape[0] if seam.lines_are_rows else self.canvas_shape[1]
        if seam.positions.shape != (lines,):
            raise ValueError(f"the seam needs one position per line ({lines}), got {seam.positions.shape}")
        self.device, self.threads, self.layout = device, threads, seam
        self.lines = lines
        self.map_src = self._take(None, map_src_canvas, wp.vec2)
        self.map_tgt = self._take(None, map_tgt_canvas, wp.vec2)
        self.seam_static = wp.array(np.ascontiguousarray(seam.positions, np.float32), dtype=float, device=device)
        self.seam = wp.clone(self.seam_static)
        self._lf = {}
        self._lf_reaches: set[int] = set()  # channel counts whose seam offsets have been nonzero
        self._border = {}
        self._gains = {}
        self._buffers: dict[tuple, _Buffers] = {}
        self._loaded: tuple[_Buffers, int, bool] | None = None

    @property
    def planned_shapes(self) -> tuple[tuple[tuple, tuple], ...]:
        """(source shape, target shape) of every input pair a plan and its buffers were made for, in
        order: a video's frames, all of one shape, reuse a single one."""
        return tuple(self._buffers)

    def set_maps(self, map_src_canvas: np.ndarray, positions: np.ndarray) -> None:
        """A new source map (same shape) and static seam; the plans are rebuilt on the next ``apply``.

        On the CPU the maps are used where they are, not copied (a canvas map is 8 bytes a pixel): do
        not change them afterwards, hand over new arrays instead, as the video path does. On CUDA
        they are uploaded into the arrays allocated the first time.
        """
        self.map_src = self._take(self.map_src, map_src_canvas, wp.vec2)
        self.layout = replace(self.layout, positions=np.asarray(positions, np.float32))
        self.seam_static.assign(self.layout.positions)
        self.seam.assign(self.layout.positions)
        for buf in self._buffers.values():
            buf.plan_ready = False

    def _take(self, current: wp.array | None, values: np.ndarray, dtype) -> wp.array:
        if current is None or self.device == "cpu":
            return runtime.readonly_array(values, dtype, self.device)
        current.assign(np.ascontiguousarray(values, dtype=np.float32))
        return current

    def set_seam(self, positions: np.ndarray) -> None:
        """This frame's seam (L,) float32, kept within the band around the static seam."""
        static = self.layout.positions
        reach = max(self.layout.band_px - 0.5 * self.layout.transition_px, 0.0)
        self.seam.assign(np.clip(positions, static - reach, static + reach).astype(np.float32))

    def set_gains(self, channels: int, gain_src, bias_src, gain_tgt, bias_tgt) -> None:
        """Per-channel affine gains of each side for images of ``channels`` channels."""
        def vec(values, default, unit):
            v = np.array(default, np.float64)
            v[:channels] = values
            return wp.vec4i(*np.rint(v * unit).astype(int).tolist())
        self._gains[channels] = (vec(gain_src, IDENTITY[0], GAIN_ONE), vec(bias_src, IDENTITY[1], LEVEL),
                                 vec(gain_tgt, IDENTITY[0], GAIN_ONE), vec(bias_tgt, IDENTITY[1], LEVEL))

    def set_offsets(self, lf_src: np.ndarray, lf_tgt: np.ndarray) -> None:
        """Low-frequency offsets (L, C) float32 of each side at the seam (grey levels, or relative changes
        of the gain with ``relative_offsets``)."""
        channels = lf_src.shape[1]
        arrays = self._lf.get(channels)
        if arrays is None:
            arrays = self._lf[channels] = (wp.zeros(self.lines * channels, dtype=int, device=self.device),
                                           wp.zeros(self.lines * channels, dtype=int, device=self.device))
        values = [np.rint(np.ascontiguousarray(v, np.float64).ravel() * LEVEL).astype(np.int32) for v in (lf_src, lf_tgt)]
        arrays[0].assign(values[0])
        arrays[1].assign(values[1])
        if values[0].any() or values[1].any():
            self._lf_reaches.add(channels)

    def set_border_offsets(self, border_lines: tuple[float, float], border_src: np.ndarray,
                           border_tgt: np.ndarray) -> None:
        """Low-frequency offsets (2, P, C) float32 of each side along the target's two borders (grey levels at
        the border, or relative changes of the gain with ``relative_offsets``, fading like the seam's over
        ``lf_px``): border k lies at line coordinate
        ``border_lines[k]``, P positions along it (canvas columns when lines are rows, else rows)."""
        positions = self.canvas_shape[1] if self.layout.lines_are_rows else self.canvas_shape[0]
        channels = border_src.shape[2]
        if border_src.shape != (2, positions, channels) or border_tgt.shape != border_src.shape:
            raise ValueError(f"border offsets need shape (2, {positions}, C), got {border_src.shape} "
                             f"and {border_tgt.shape}")
        src, tgt = (wp.array(np.rint(np.ascontiguousarray(v, np.float64).ravel() * LEVEL).astype(np.int32), dtype=int,
                             device=self.device) for v in (border_src, border_tgt))
        self._border[channels] = (1, wp.vec2(*border_lines), positions * channels, src, tgt)
        for buf in self._buffers.values():
            buf.runs_ready = False

    def _buffers_for(self, shape_src: tuple, shape_tgt: tuple) -> _Buffers:
        key = (shape_src, shape_tgt)
        if key not in self._buffers:
            self._buffers[key] = _Buffers(shape_src, shape_tgt, self.canvas_shape, self.device)
        buf = self._buffers[key]
        if not buf.plan_ready:
            inputs = [self.map_src, self.map_tgt, self.seam_static, int(self.layout.lines_are_rows),
                      float(self.layout.band_px), wp.vec3i(*shape_src), wp.vec3i(*shape_tgt),
                      buf.plan, buf.plan_tgt, buf.coverage]
            runtime.launch_row_loops(composite_plan_kernel, *self.canvas_shape, inputs, self.device, self.threads)
            buf.plan_ready = True
            buf.runs_ready = False
            buf.plan_served = False
        return buf

    def _offsets_reach_px(self, channels: int) -> float:
        """How far from the frame's seam its offsets may change a pixel: ``lf_px`` once they have ever been
        nonzero (kept after, so that the runs are not scanned anew each time they flip), nothing until then
        (a chroma pass); plus a pixel for float32 rounding."""
        return (max(self.layout.lf_px, 0.0) if channels in self._lf_reaches else 0.0) + RUN_MARGIN_PX

    def _frame_runs(self, buf: _Buffers, channels: int, at_once: bool = False) -> wp.array:
        """``buf``'s runs per canvas row for the current seam (``frame_runs_kernel``) from the plan's
        (``row_runs_kernel``), which are made anew after the plan or the border blend changed.

        Where the lines are rows, the plan's runs ignore the seam and each frame's are cut around its
        seam. Else the plan's runs keep clear of wherever the frame's seam may be, and serve every frame
        as they are: it stays within ``band_px - transition_px / 2`` of the static seam
        (:meth:`set_seam`), its offsets reach :meth:`_offsets_reach_px` beyond that.

        A plan's runs are looked for once it has served a frame (or ``at_once``), none before: a plan
        made anew every frame (maps being blended in) would cost more to scan than its runs save."""
        layout = self.layout
        reach_px = self._offsets_reach_px(channels)
        clear_px = 0.0 if layout.lines_are_rows else max(layout.band_px - 0.5 * layout.transition_px, 0.0) + reach_px
        if not buf.runs_ready and not buf.plan_served and not at_once:
            buf.frame_runs.zero_()
            return buf.frame_runs
        if not buf.runs_ready or buf.runs_clear_px != clear_px:
            border_on, border_lines, second, border_src, border_tgt = self._border[channels]
            inputs = [self.canvas_shape[1], buf.plan, self.seam_static, int(layout.lines_are_rows), clear_px,
                      float(layout.lf_px), border_on, border_lines, second, border_src, border_tgt, channels, buf.runs]
            runtime.launch_rows(row_runs_kernel, self.canvas_shape[0], 1, inputs, self.device, self.threads)
            buf.runs_ready, buf.runs_clear_px = True, clear_px
        if not layout.lines_are_rows:
            return buf.runs
        inputs = [buf.runs, self.seam, reach_px, buf.frame_runs]
        runtime.launch_rows(frame_runs_kernel, self.canvas_shape[0], 1, inputs, self.device, runtime.BAND_THREADS)
        return buf.frame_runs

    def coverage(self, shape_src: tuple, shape_tgt: tuple) -> np.ndarray:
        """(Hc, Wc) uint8 255 where at least one side of images of these shapes is sampled, else 0."""
        return self._buffers_for(tuple(shape_src), tuple(shape_tgt)).coverage.numpy()

    def row_runs(self, shape_src: tuple, shape_tgt: tuple) -> np.ndarray:
        """(Hc, 5) int32 per canvas row for images of these shapes, as :meth:`composite` takes them for
        the current seam once the plan has served a frame (``frame_runs_kernel``): columns [a, b) it
        copies from the target through the gains alone, the copy's target element at column 0, and
        columns [a, b) it samples from the source with its gains alone (a = b where a row has none)."""
        channels = shape_src[2]
        self._ensure_defaults(channels)
        buf = self._buffers_for(tuple(shape_src), tuple(shape_tgt))
        return self._frame_runs(buf, channels, at_once=True).numpy().copy()

    def seam_positions(self) -> np.ndarray:
        """(L,) float32: the seam per line as the next :meth:`composite` uses it (after ``set_seam``'s clip)."""
        return self.seam.numpy().copy()

    def seam_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """(alpha, lf) (Hc, Wc) float32 for the current seam: the source weight where both views are
        valid and the weight of the low-frequency offsets (the frame kernel's rule)."""
        alpha = wp.empty(self.canvas_shape, dtype=float, device=self.device)
        lf = wp.empty(self.canvas_shape, dtype=float, device=self.device)
        layout = self.layout
        inputs = [self.seam, int(layout.lines_are_rows), float(layout.transition_px), float(layout.smooth_sigma_px),
                  float(layout.lf_px), alpha, lf]
        runtime.launch_rows(seam_weights_kernel, *self.canvas_shape, inputs, self.device, self.threads)
        return alpha.numpy(), lf.numpy()

    def border_offsets(self, channels: int) -> tuple[np.ndarray, np.ndarray]:
        """The border blend's offsets per canvas pixel (Hc, Wc, channels) float32 of each side, as the
        frame kernel adds them (zeros without a border blend), for figures and reference implementations."""
        self._ensure_defaults(channels)
        on, lines, _, src, tgt = self._border[channels]
        height, width = self.canvas_shape
        if not on:
            zeros = np.zeros((height, width, channels), np.float32)
            return zeros, zeros.copy()
        rows = self.layout.lines_are_rows
        line = np.arange(height if rows else width, dtype=np.float32)
        lf_px = max(self.layout.lf_px, 1e-6)
        weights = [lf_weights(line - lines[k], lf_px) for k in range(2)]

        def spread(values: wp.array) -> np.ndarray:
            along = values.numpy().reshape(2, -1, channels) / LEVEL
            if rows:
                total = sum(weights[k][:, None, None] * along[k][None, :, :] for k in range(2))
            else:
                total = sum(weights[k][None, :, None] * along[k][:, None, :] for k in range(2))
            return total.astype(np.float32)

        return spread(src), spread(tgt)

    def knee(self) -> tuple[float, float] | None:
        """(knee, white) grey levels of the gains' highlight knee (``gains.tone_curve``), or None."""
        return self._knee

    def gains(self, channels: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(gain_src, bias_src, gain_tgt, bias_tgt), each (channels,) float64 grey levels, as applied."""
        self._ensure_defaults(channels)
        units = (GAIN_ONE, LEVEL, GAIN_ONE, LEVEL)
        return tuple(np.array(list(v)[:channels], np.float64) / unit for v, unit in zip(self._gains[channels], units))

    def offsets(self, channels: int) -> tuple[np.ndarray, np.ndarray]:
        """The low-frequency offsets (L, channels) float64 of each side, as applied (grey levels, or relative
        changes of the gain with ``relative_offsets``)."""
        self._ensure_defaults(channels)
        return tuple(a.numpy().reshape(self.lines, channels) / LEVEL for a in self._lf[channels])

    def load(self, img_src: np.ndarray, img_tgt: np.ndarray) -> None:
        """Upload one pair of uint8 images (H, W, C) or planes (H, W), same C on both sides, for
        :meth:`band_difference` and :meth:`composite`."""
        src3, tgt3 = as_channels(img_src), as_channels(img_tgt)
        self._upload(src3.shape, tgt3.shape, (src3,), (tgt3,), np.ndim(img_src) == 2)

    def load_planes(self, planes_src: Sequence[np.ndarray], planes_tgt: Sequence[np.ndarray]) -> None:
        """As :meth:`load` for images given as C uint8 planes (H, W) per side (e.g. a frame's U and V),
        each copied straight into its channel: no interleaved (H, W, C) copy is made first."""
        def shape(planes: Sequence[np.ndarray]) -> tuple[int, int, int]:
            if any(p.dtype != np.uint8 or p.shape != planes[0].shape for p in planes):
                raise ValueError("expected uint8 planes of one (H, W) per side")
            return (*planes[0].shape, len(planes))
        self._upload(shape(planes_src), shape(planes_tgt), planes_src, planes_tgt, False)

    def _upload(self, shape_src: tuple, shape_tgt: tuple, parts_src: Sequence[np.ndarray],
                parts_tgt: Sequence[np.ndarray], planes: bool) -> None:
        """Copy a pair into the host buffers for its (H, W, C) shapes: ``parts_*`` one (H, W, C) image
        or C (H, W) planes per side; ``planes``: :meth:`composite` gives (Hc, Wc), not (Hc, Wc, 1)."""
        if shape_src[2] != shape_tgt[2]:
            raise ValueError(f"source has {shape_src[2]} channels, target {shape_tgt[2]}")
        if shape_src[2] > MAX_CHANNELS:
            raise ValueError(f"images have {shape_src[2]} channels; at most {MAX_CHANNELS} are supported")
        buf = self._buffers_for(tuple(shape_src), tuple(shape_tgt))
        for host, parts in ((buf.src_host.numpy(), parts_src), (buf.tgt_host.numpy(), parts_tgt)):
            if len(parts) == 1 and np.ndim(parts[0]) == 3:
                np.copyto(host, parts[0])
            else:
                for channel, plane in enumerate(parts):
                    host[:, :, channel] = plane
        if buf.src_host is not buf.src:
            wp.copy(buf.src, buf.src_host)
            wp.copy(buf.tgt, buf.tgt_host)
        self._loaded = (buf, shape_src[2], planes)
        self._ensure_defaults(shape_src[2])

    def _ensure_defaults(self, channels: int) -> None:
        if channels not in self._gains:
            self.set_gains(channels, *(v[:channels] for v in IDENTITY * 2))
        if channels not in self._lf:
            zeros = np.zeros((self.lines, channels), np.float32)
            self.set_offsets(zeros, zeros)
        if channels not in self._border:
            none = wp.zeros(1, dtype=int, device=self.device)
            self._border[channels] = (0, wp.vec2(0.0, 0.0), 0, none, none)

    def band_difference(self, lines: wp.array, band_x0: wp.array, width: int, cell: int, last: wp.array,
                        out: wp.array, out_total: wp.array, out_delta: wp.array) -> None:
        """Fill ``out`` and ``out_total`` ((K, width) float Warp arrays on this device) with source minus
        target and source plus target (channel 0, with gains; grey levels) of the loaded pair on seam
        lines ``lines`` (K,) int, ``width`` cells each from ``band_x0`` (K,) int, one every ``cell``
        positions (Warp arrays, uploaded once by the caller): ``NOT_BOTH`` and 0 where a cell does not
        hold both views; ``out_delta`` with |difference - ``last``| (the last frame's difference), 0
        where either lacks a view."""
        buf, channels, _ = self._loaded
        gains = self._gains[channels]
        inputs = [buf.src.flatten(), buf.tgt.flatten(), buf.frame_inputs[2], buf.plan, buf.plan_tgt,
                  self.canvas_shape[1], self.canvas_shape[0], int(self.layout.lines_are_rows), lines, band_x0,
                  int(cell), *gains, self.tone, last, out, out_total, out_delta]
        runtime.launch_row_loops(band_difference_kernel, lines.shape[0], width, inputs, self.device,
                                 runtime.BAND_THREADS)

    def composite(self, fill: Sequence[int] | None = None) -> np.ndarray:
        """The panorama of the loaded pair: (Hc, Wc, C) uint8, or (Hc, Wc) for planes; ``fill``: the C
        values of pixels no side covers (default 0). The array is reused by the next call."""
        buf, channels, planes = self._loaded
        values = [int(v) for v in fill] if fill is not None else [0] * channels
        if len(values) != channels:
            raise ValueError(f"fill has {len(values)} values for {channels} channels")
        lf_src, lf_tgt = self._lf[channels]
        _, _, gain_tgt, bias_tgt = self._gains[channels]
        wp.launch(gain_table_kernel, dim=channels * 256, inputs=[gain_tgt, bias_tgt, self.tone, buf.table],
                  device=self.device)
        inputs = [*buf.frame_inputs, self._frame_runs(buf, channels), buf.table, self.seam,
                  int(self.layout.lines_are_rows), float(self.layout.transition_px),
                  float(self.layout.smooth_sigma_px), float(self.layout.lf_px), lf_src, lf_tgt, *self._border[channels],
                  *self._gains[channels], self.tone, int(self.relative_offsets),
                  wp.vec4i(*values, *[0] * (MAX_CHANNELS - channels)), buf.out_flat]
        runtime.launch_row_loops(COMPOSITE_FRAME_KERNELS[channels], *self.canvas_shape, inputs, self.device,
                                 self.threads)
        buf.plan_served = True
        out = buf.out.numpy()
        return out[:, :, 0] if planes else out

    def apply(self, img_src: np.ndarray, img_tgt: np.ndarray, fill: Sequence[int] | None = None) -> np.ndarray:
        """:meth:`load` then :meth:`composite`: a fresh (Hc, Wc[, C]) uint8 array."""
        self.load(img_src, img_tgt)
        return self.composite(fill).copy()
