"""Apply the three canvas maps to a frame pair: the per-frame path of images and videos.

``Compositor`` uploads the maps to the Warp device once and turns them, once per input shape, into a
fixed-point plan (per pixel: which side is shown, its tap offset and sub-pixel fractions; alpha
where the two blend, see ``kernels/composite.py``), so a video's per-frame cost is two uploads, one integer kernel launch and
one download (SENA.md "Maps, not images": cached warps, per-frame compositing).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import warp as wp

from sena_warp.config import Config
from sena_warp.kernels import runtime
from sena_warp.kernels.composite import COMPOSITE_FIXED_KERNELS, MAX_CHANNELS, composite_plan_kernel
from sena_warp.warp_map import as_channels


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
        self.plan_tgt = wp.empty(pixels, dtype=wp.int64, device=device)  # read for blend pixels only
        self.alpha = wp.empty(pixels, dtype=wp.uint16, device=device)  # likewise
        self.plan_ready = False
        # Neighbour taps in flat elements: C along x, W*C along y (0 on an axis of length 1).
        steps = wp.vec4i(
            channels * min(1, shape_src[1] - 1), channels * shape_src[1] * min(1, shape_src[0] - 1),
            channels * min(1, shape_tgt[1] - 1), channels * shape_tgt[1] * min(1, shape_tgt[0] - 1),
        )
        # The frame kernel's inputs before (channels, fill, out); flat views of the (H, W, C) arrays.
        self.frame_inputs = [self.src.flatten(), self.tgt.flatten(), steps, self.plan, self.plan_tgt, self.alpha]
        self.out_flat = self.out.flatten()
        # On CPU the device arrays are host memory already; on CUDA copies go through pinned memory.
        on_cpu = device == "cpu"
        self.src_host = self.src if on_cpu else wp.empty(shape_src, dtype=wp.uint8, device="cpu", pinned=True)
        self.tgt_host = self.tgt if on_cpu else wp.empty(shape_tgt, dtype=wp.uint8, device="cpu", pinned=True)


class Compositor:
    """out = alpha * src(map_src) + (1 - alpha) * tgt(map_tgt), bilinear, on the Warp device.

    ``map_src_canvas``, ``map_tgt_canvas``: (Hc, Wc, 2) float32 (x, y) sample positions in the
    source / target; ``alpha_canvas``: (Hc, Wc) float32 weight of the source. Runs on ``cfg.device``
    (resolved, ``runtime.resolve_config``) with ``cfg.cpu_threads`` row-band threads. Results match
    the float rule of ``kernels.composite.composite_kernel`` within 1 grey level (positions in
    1/1024 px, alpha in 1/16384).
    """

    def __init__(self, map_src_canvas: np.ndarray, map_tgt_canvas: np.ndarray, alpha_canvas: np.ndarray, cfg: Config):
        self.canvas_shape = tuple(np.asarray(alpha_canvas).shape[:2])
        if map_src_canvas.shape[:2] != self.canvas_shape or map_tgt_canvas.shape[:2] != self.canvas_shape:
            raise ValueError("map_src_canvas, map_tgt_canvas and alpha_canvas must share one (Hc, Wc)")
        self.device = cfg.device
        self.threads = cfg.cpu_threads
        self.map_src = self.map_tgt = self.alpha = None
        self._buffers: dict[tuple, _Buffers] = {}
        self.set_maps(map_src_canvas, map_tgt_canvas, alpha_canvas)

    @property
    def planned_shapes(self) -> tuple[tuple[tuple, tuple], ...]:
        """(source shape, target shape) of every input pair a plan and its buffers were made for, in
        order: a video's frames, all of one shape, reuse a single one."""
        return tuple(self._buffers)

    def set_maps(self, map_src_canvas: np.ndarray | None = None, map_tgt_canvas: np.ndarray | None = None,
                 alpha_canvas: np.ndarray | None = None) -> None:
        """Take new maps (same shapes); the plans are rebuilt on the next ``apply``.

        On the CPU the maps are used where they are, not copied (a canvas map is 8 bytes a pixel): do
        not change them afterwards, hand over new arrays instead, as the video path does. On CUDA
        they are uploaded into the arrays allocated the first time.
        """
        if map_src_canvas is not None:
            self.map_src = self._take(self.map_src, map_src_canvas, wp.vec2)
        if map_tgt_canvas is not None:
            self.map_tgt = self._take(self.map_tgt, map_tgt_canvas, wp.vec2)
        if alpha_canvas is not None:
            self.alpha = self._take(self.alpha, alpha_canvas, float)
        for buf in self._buffers.values():
            buf.plan_ready = False

    def _take(self, current: wp.array | None, values: np.ndarray, dtype) -> wp.array:
        if current is None or self.device == "cpu":
            return runtime.readonly_array(values, dtype, self.device)
        current.assign(np.ascontiguousarray(values, dtype=np.float32))
        return current

    def _buffers_for(self, shape_src: tuple, shape_tgt: tuple) -> _Buffers:
        key = (shape_src, shape_tgt)
        if key not in self._buffers:
            self._buffers[key] = _Buffers(shape_src, shape_tgt, self.canvas_shape, self.device)
        buf = self._buffers[key]
        if not buf.plan_ready:
            inputs = [self.map_src, self.map_tgt, self.alpha, wp.vec3i(*shape_src), wp.vec3i(*shape_tgt),
                      buf.plan, buf.plan_tgt, buf.alpha, buf.coverage]
            runtime.launch_rows(composite_plan_kernel, *self.canvas_shape, inputs, self.device, self.threads)
            buf.plan_ready = True
        return buf

    def apply(self, img_src: np.ndarray, img_tgt: np.ndarray,
              fill: Sequence[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Composite one pair of uint8 images (H, W, C) or planes (H, W), same C on both sides.

        ``fill``: the C values of pixels no side covers (default 0). Returns (out uint8 (Hc, Wc, C),
        or (Hc, Wc) for planes; coverage uint8 (Hc, Wc), 255 where at least one side was sampled,
        else 0). Both are fresh arrays the caller may keep.
        """
        src3, tgt3 = as_channels(img_src), as_channels(img_tgt)
        if src3.shape[2] != tgt3.shape[2]:
            raise ValueError(f"source has {src3.shape[2]} channels, target {tgt3.shape[2]}")
        channels = src3.shape[2]
        if channels > MAX_CHANNELS:
            raise ValueError(f"images have {channels} channels; at most {MAX_CHANNELS} are supported")
        buf = self._buffers_for(src3.shape, tgt3.shape)
        values = [int(v) for v in fill] if fill is not None else [0] * channels
        if len(values) != channels:
            raise ValueError(f"fill has {len(values)} values for {channels} channels")
        fill_vec = wp.vec4i(*values, *[0] * (MAX_CHANNELS - channels))
        np.copyto(buf.src_host.numpy(), src3)
        np.copyto(buf.tgt_host.numpy(), tgt3)
        if buf.src_host is not buf.src:
            wp.copy(buf.src, buf.src_host)
            wp.copy(buf.tgt, buf.tgt_host)
        inputs = [*buf.frame_inputs, fill_vec, buf.out_flat]
        runtime.launch_row_loops(COMPOSITE_FIXED_KERNELS[channels], *self.canvas_shape, inputs, self.device,
                                 self.threads)
        out = buf.out.numpy()
        return (out[:, :, 0] if np.ndim(img_src) == 2 else out).copy(), buf.coverage.numpy().copy()
