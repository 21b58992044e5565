"""Step 5: the seam guard G and the guarded field (SENA.md step 5).

G is 0 outside the overlap so the source keeps its global affine shape there, rises over a ramp
of width b inside it, and is damped (floor gamma_min) where few inliers support the local model.
"""

from __future__ import annotations

import cv2
import numpy as np
import warp as wp

from sena_warp.config import Config
from sena_warp.kernels import runtime
from sena_warp.kernels.gate import gate_kernel, gated_field_kernel


def ramp_width_px(diag_px: float, cfg: Config) -> float:
    """b = max(ramp_min_px, ramp_diag_ratio * image diagonal), in pixels."""
    return max(cfg.ramp_min_px, cfg.ramp_diag_ratio * diag_px)


def inside_distance_px(overlap_mask_canvas: np.ndarray) -> np.ndarray:
    """(H, W) float32 Euclidean distance to the nearest pixel outside the overlap; 0 outside."""
    mask = np.asarray(overlap_mask_canvas, dtype=bool).astype(np.uint8)
    return cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def inlier_density(shape: tuple[int, int], inliers_canvas: np.ndarray, sigma_px: float) -> np.ndarray:
    """(H, W) float32 in [0, 1]: Gaussian-blurred splat of inlier (x, y) canvas positions, max = 1."""
    splat = np.zeros(shape, dtype=np.float32)
    pts = np.rint(np.asarray(inliers_canvas, dtype=np.float64).reshape(-1, 2)).astype(np.int64)
    keep = (pts[:, 0] >= 0) & (pts[:, 0] < shape[1]) & (pts[:, 1] >= 0) & (pts[:, 1] < shape[0])
    np.add.at(splat, (pts[keep, 1], pts[keep, 0]), 1.0)
    density = cv2.GaussianBlur(splat, (0, 0), sigma_px)
    peak = float(density.max())
    return density / peak if peak > 0 else density


def gate_canvas(
    overlap_mask_canvas: np.ndarray,
    inliers_canvas: np.ndarray,
    diag_px: float,
    long_side_px: float,
    cfg: Config,
) -> np.ndarray:
    """Gate G over the canvas: (H, W) float32 in [0, 1].

    ``overlap_mask_canvas`` (H, W) bool; ``inliers_canvas`` (N, 2) float64 (x, y) inlier target
    positions on the canvas; ``diag_px`` and ``long_side_px``: diagonal and long side of the input
    image, which set the ramp b and the density blur sigma_d = cfg.sigma_d_ratio * long side.
    """
    shape = np.asarray(overlap_mask_canvas).shape
    device = runtime.resolve_device(cfg.device)
    sdf = wp.array(inside_distance_px(overlap_mask_canvas), dtype=float, device=device)
    density_np = inlier_density(shape, inliers_canvas, cfg.sigma_d_ratio * long_side_px)
    density = wp.array(density_np, dtype=float, device=device)
    gate = wp.zeros(shape, dtype=float, device=device)
    inputs = [sdf, density, ramp_width_px(diag_px, cfg), cfg.gamma_p, cfg.gamma_min, gate]
    runtime.launch_rows(gate_kernel, shape[0], shape[1], inputs, device, cfg.cpu_threads)
    return gate.numpy()


def guard_field(field: np.ndarray, gate: np.ndarray, cfg: Config) -> np.ndarray:
    """D_guarded = GaussianBlur_{sigma_g}(G * D) on x and y: (H, W, 2) float32 from field (H, W, 2), gate (H, W)."""
    height, width = gate.shape
    device = runtime.resolve_device(cfg.device)
    field_wp = wp.array(np.ascontiguousarray(field, dtype=np.float32), dtype=wp.vec2, device=device)
    gate_wp = wp.array(np.ascontiguousarray(gate, dtype=np.float32), dtype=float, device=device)
    gated = wp.zeros((height, width), dtype=wp.vec2, device=device)
    runtime.launch_rows(gated_field_kernel, height, width, [field_wp, gate_wp, gated], device, cfg.cpu_threads)
    gated_np = gated.numpy().reshape(height, width, 2)
    return cv2.GaussianBlur(gated_np, (0, 0), cfg.sigma_g_px)
