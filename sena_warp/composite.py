"""Apply the three canvas maps to a frame pair: the per-frame path of images and videos.

``Compositor`` uploads the maps to the Warp device once and keeps input and output buffers per
input shape, so a video's per-frame cost is two uploads, one kernel launch and one download
(SENA.md "Maps, not images": cached warps, per-frame compositing).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from sena_warp.kernels import runtime
from sena_warp.kernels.composite import composite_kernel
from sena_warp.warp_map import as_channels


class _Buffers:
    """Warp arrays for one (src shape, tgt shape) pair: device inputs, host staging, outputs."""

    def __init__(self, shape_src: tuple, shape_tgt: tuple, canvas_shape: tuple[int, int], device: str):
        self.src = wp.empty(shape_src, dtype=wp.uint8, device=device)
        self.tgt = wp.empty(shape_tgt, dtype=wp.uint8, device=device)
        self.out = wp.empty((*canvas_shape, shape_src[2]), dtype=wp.uint8, device=device)
        self.coverage = wp.empty(canvas_shape, dtype=wp.uint8, device=device)
        # On CPU the device arrays are host memory already; on CUDA copies go through pinned memory.
        on_cpu = device == "cpu"
        self.src_host = self.src if on_cpu else wp.empty(shape_src, dtype=wp.uint8, device="cpu", pinned=True)
        self.tgt_host = self.tgt if on_cpu else wp.empty(shape_tgt, dtype=wp.uint8, device="cpu", pinned=True)


class Compositor:
    """out = alpha * src(map_src) + (1 - alpha) * tgt(map_tgt), bilinear, on the Warp device.

    ``map_src_canvas``, ``map_tgt_canvas``: (Hc, Wc, 2) float32 (x, y) sample positions in the
    source / target; ``alpha_canvas``: (Hc, Wc) float32 weight of the source. ``device`` is a
    resolved Warp device ("cpu" or "cuda", see ``runtime.resolve_device``); ``threads`` the CPU
    row-band launch threads (0 = one per core).
    """

    def __init__(
        self,
        map_src_canvas: np.ndarray,
        map_tgt_canvas: np.ndarray,
        alpha_canvas: np.ndarray,
        device: str,
        threads: int = 0,
    ):
        self.canvas_shape = tuple(np.asarray(alpha_canvas).shape[:2])
        if map_src_canvas.shape[:2] != self.canvas_shape or map_tgt_canvas.shape[:2] != self.canvas_shape:
            raise ValueError("map_src_canvas, map_tgt_canvas and alpha_canvas must share one (Hc, Wc)")
        self.device = device
        self.threads = threads
        self.map_src = wp.array(np.ascontiguousarray(map_src_canvas, dtype=np.float32), dtype=wp.vec2, device=device)
        self.map_tgt = wp.array(np.ascontiguousarray(map_tgt_canvas, dtype=np.float32), dtype=wp.vec2, device=device)
        self.alpha = wp.array(np.ascontiguousarray(alpha_canvas, dtype=np.float32), dtype=float, device=device)
        self._buffers: dict[tuple, _Buffers] = {}

    def _buffers_for(self, shape_src: tuple, shape_tgt: tuple) -> _Buffers:
        key = (shape_src, shape_tgt)
        if key not in self._buffers:
            self._buffers[key] = _Buffers(shape_src, shape_tgt, self.canvas_shape, self.device)
        return self._buffers[key]

    def apply(self, img_src: np.ndarray, img_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Composite one pair of uint8 images (H, W, C) or planes (H, W), same C on both sides.

        Returns (out uint8 (Hc, Wc, C), or (Hc, Wc) for planes; coverage uint8 (Hc, Wc), 255 where
        at least one side was sampled, else 0). Both are fresh arrays the caller may keep.
        """
        src3, tgt3 = as_channels(img_src), as_channels(img_tgt)
        if src3.shape[2] != tgt3.shape[2]:
            raise ValueError(f"source has {src3.shape[2]} channels, target {tgt3.shape[2]}")
        buf = self._buffers_for(src3.shape, tgt3.shape)
        np.copyto(buf.src_host.numpy(), src3)
        np.copyto(buf.tgt_host.numpy(), tgt3)
        if buf.src_host is not buf.src:
            wp.copy(buf.src, buf.src_host)
            wp.copy(buf.tgt, buf.tgt_host)
        inputs = [buf.src, buf.tgt, self.map_src, self.map_tgt, self.alpha, buf.out, buf.coverage]
        runtime.launch_rows(composite_kernel, *self.canvas_shape, inputs, self.device, self.threads)
        out = buf.out.numpy()
        return (out[:, :, 0] if np.ndim(img_src) == 2 else out).copy(), buf.coverage.numpy().copy()
