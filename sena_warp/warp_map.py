"""Step 6: the source sampling map, its numeric inverse for points, and warping an image by it.

``M_s(u) = A_glob^-1 (u - o) + D_guarded(u)`` gives, for canvas pixel u, the source (x, y) to
sample (docs/method.md step 6). Forward positions of source points are found by inverting M_s
numerically, never as ``A s + o + d`` (d is defined at u, not at s).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import warp as wp

from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.affine import invert_affine
from sena_warp.bilinear import sample_bilinear
from sena_warp.kernels import runtime, transfer
from sena_warp.kernels.remap import remap_kernel
from sena_warp.kernels.sampling import source_map_kernel


def source_map_canvas(canvas: Canvas, affine_src_to_tgt: np.ndarray, field_guarded: np.ndarray,
                      cfg: Config) -> np.ndarray:
    """M_s over the canvas: (H, W, 2) float32 source (x, y) per canvas pixel (x, y).

    ``field_guarded`` (H, W, 2) float32: guarded displacement in source pixels (``gate.guard_field``).
    Runs on ``cfg.device`` (resolved, ``runtime.resolve_config``) with ``cfg.cpu_threads``.
    """
    device = cfg.device
    glob_tgt_to_src = invert_affine(affine_src_to_tgt)
    field = transfer.to_device(np.ascontiguousarray(field_guarded, dtype=np.float32), wp.vec2, device, "warp_map")
    map_src = wp.zeros(canvas.shape, dtype=wp.vec2, device=device)
    inputs = [
        wp.vec2d(*canvas.offset_tgt),
        wp.mat22d(glob_tgt_to_src[:, :2]),
        wp.vec2d(glob_tgt_to_src[:, 2]),
        field,
        map_src,
    ]
    runtime.launch_rows(source_map_kernel, canvas.height, canvas.width, inputs, device, cfg.cpu_threads)
    return transfer.download(map_src, "warp_map").reshape(canvas.height, canvas.width, 2)


def forward_points(
    map_src_canvas: np.ndarray,
    affine_src_to_tgt: np.ndarray,
    canvas: Canvas,
    pts_src: np.ndarray,
    cfg: Config,
) -> np.ndarray:
    """Canvas positions (N, 2) float64 (x, y) where M_s takes the source points ``pts_src`` (N, 2).

    Solves M_s(u) = s by chord iterations u <- u + L (s - M_s(u)) from u = A s + o, L the linear
    part of A_glob (M_s's Jacobian is close to L^-1 because the guarded field is smooth), until
    |M_s(u) - s| < cfg.forward_tol_px. Points that do not converge on the canvas (outside it, or
    where the map folds) come back as NaN; ``cfg.forward_max_iters`` caps the iterations.
    """
    affine = np.asarray(affine_src_to_tgt, dtype=np.float64)
    pts_src = np.asarray(pts_src, dtype=np.float64).reshape(-1, 2)
    pts_canvas = canvas.tgt_to_canvas(pts_src @ affine[:, :2].T + affine[:, 2])
    border = np.array([canvas.width - 1.0, canvas.height - 1.0])
    for _ in range(cfg.forward_max_iters):
        # Clamped to the canvas while iterating, so a point that steps outside can come back.
        residual_src = pts_src - sample_bilinear(map_src_canvas, np.clip(pts_canvas, 0.0, border))
        if np.all(np.abs(residual_src) < cfg.forward_tol_px):
            break
        pts_canvas = pts_canvas + residual_src @ affine[:, :2].T
    residual_src = pts_src - sample_bilinear(map_src_canvas, np.clip(pts_canvas, 0.0, border))
    height, width = canvas.shape
    on_canvas = (
        (pts_canvas[:, 0] >= 0) & (pts_canvas[:, 0] <= width - 1) & (pts_canvas[:, 1] >= 0) & (pts_canvas[:, 1] <= height - 1)
    )
    converged = np.all(np.abs(residual_src) < cfg.forward_tol_px, axis=1) & on_canvas
    pts_canvas[~converged] = np.nan
    return pts_canvas


@dataclass(frozen=True)
class CanvasViews:
    """Both views on the working canvas, as the seam stages see them.

    ``src``: (H, W, C) uint8 the source warped by a source map (0 where invalid); ``tgt``: (H, W, C)
    uint8 the target pasted at its offset (0 outside); ``valid_src``, ``valid_tgt``: (H, W) bool.
    """

    src: np.ndarray
    tgt: np.ndarray
    valid_src: np.ndarray
    valid_tgt: np.ndarray

    @property
    def both(self) -> np.ndarray:
        """(H, W) bool: the overlap, where both views are defined."""
        return self.valid_src & self.valid_tgt

    def grey(self) -> tuple[np.ndarray, np.ndarray]:
        """The two views in grey, float32 (H, W), NaN where a view is not defined."""
        def one(img: np.ndarray, valid: np.ndarray) -> np.ndarray:
            grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.shape[2] == 3 else img[:, :, 0]
            return np.where(valid, grey.astype(np.float32), np.float32(np.nan))
        return one(self.src, self.valid_src), one(self.tgt, self.valid_tgt)


def canvas_views(img_src: np.ndarray, img_tgt: np.ndarray, map_src_canvas: np.ndarray, canvas: Canvas,
                 cfg: Config) -> CanvasViews:
    """The source warped by ``map_src_canvas`` and the target pasted at ``canvas.offset_tgt`` (an
    integer offset: no resampling), both (H, W, C) uint8 on the canvas, with their validity."""
    warped, valid_src = remap_image(img_src, map_src_canvas, cfg)
    warped = as_channels(warped)
    placed = np.zeros((*canvas.shape, warped.shape[2]), np.uint8)
    valid_tgt = np.zeros(canvas.shape, bool)
    ox, oy = (int(round(v)) for v in canvas.offset_tgt)
    h, w = img_tgt.shape[:2]
    placed[oy:oy + h, ox:ox + w] = as_channels(img_tgt)
    valid_tgt[oy:oy + h, ox:ox + w] = True
    return CanvasViews(warped, placed, valid_src, valid_tgt)


def as_channels(img: np.ndarray) -> np.ndarray:
    """A uint8 image as contiguous (H, W, C): planes (H, W) gain a channel axis of 1."""
    img = np.asarray(img)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise ValueError(f"expected a uint8 (H, W) or (H, W, C) image, got {img.dtype} {img.shape}")
    return np.ascontiguousarray(img[:, :, None] if img.ndim == 2 else img)


def remap_image(img: np.ndarray, map_canvas: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear remap of uint8 ``img`` (H, W, C) or (H, W) by ``map_canvas`` (Hc, Wc, 2) float32 (x, y)
    sample positions in ``img`` (e.g. M_s: the source warped onto the canvas).

    Returns (warped uint8 (Hc, Wc, C) or (Hc, Wc) like the input, valid bool (Hc, Wc)); a pixel is
    valid when its sample position has all four taps inside img; invalid pixels are 0. Runs on
    ``cfg.device`` (resolved, ``runtime.resolve_config``) with ``cfg.cpu_threads``.
    """
    img3 = as_channels(img)
    height, width = map_canvas.shape[:2]
    device = cfg.device
    img_wp = transfer.to_device(img3, wp.uint8, device, "remap")
    map_wp = transfer.for_reading(map_canvas, wp.vec2, device, "remap")
    out = wp.zeros((height, width, img3.shape[2]), dtype=wp.uint8, device=device)
    valid = wp.zeros((height, width), dtype=wp.uint8, device=device)
    runtime.launch_rows(remap_kernel, height, width, [img_wp, map_wp, out, valid], device, cfg.cpu_threads)
    warped = transfer.download(out, "remap")
    return (warped[:, :, 0] if img.ndim == 2 else warped), transfer.download(valid, "remap").astype(bool)
