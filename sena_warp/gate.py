"""Step 5: the seam guard G and the guarded field (docs/method.md step 5).

G is 0 where the source is shown alone (outside the overlap), so the source keeps its global affine
shape there; it rises over a ramp of width b from that region's border into the overlap, and is
damped (floor gamma_min) where few matches support the local model. Only the border with the
source-only region needs the ramp: across the overlap's other borders (where the source ends, or
neither image continues) nothing of the source is shown beyond, so the gate simply carries on
there; a ramp or a step to 0 at those borders would only keep the local alignment from the
overlap's edge or fold the source where the field drops.
"""

from __future__ import annotations

import cv2
import numpy as np
import warp as wp

from sena_warp.config import Config
from sena_warp.kernels import runtime, transfer
from sena_warp.kernels.gate import gate_kernel, gated_field_kernel

DENSITY_CELLS_PER_SIGMA = 4.0  # coarse-grid cells per sigma_d of the density blur (see inlier_density)


def ramp_width_px(diag_px: float, cfg: Config) -> float:
    """b = max(ramp_min_px, ramp_diag_ratio * image diagonal), in pixels."""
    return max(cfg.ramp_min_px, cfg.ramp_diag_ratio * diag_px)


def open_border_distance_px(source_only_canvas: np.ndarray) -> np.ndarray:
    """(H, W) float32 distance from each canvas pixel to the nearest source-only pixel (0 on them).

    Without any source-only pixel (the source lies inside the target) every pixel gets the canvas
    diagonal, so the ramp is 1 everywhere.
    """
    open_border = np.asarray(source_only_canvas, dtype=bool)
    if not open_border.any():
        return np.full(open_border.shape, float(np.hypot(*open_border.shape)), np.float32)
    return cv2.distanceTransform((~open_border).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def inlier_density(shape: tuple[int, int], inliers_canvas: np.ndarray, sigma_px: float) -> np.ndarray:
    """(H, W) float32 in [0, 1]: Gaussian-blurred splat of inlier (x, y) canvas positions, max = 1.

    The blur is wide (sigma_d is ~5 % of the long side: ~90 px at 1080p), so it runs on a grid
    ``DENSITY_CELLS_PER_SIGMA`` times coarser than sigma and is resized up bilinearly: the same
    density to about 1 % of its peak, in milliseconds instead of a second per estimate.
    """
    step = max(1, int(sigma_px / DENSITY_CELLS_PER_SIGMA))
    coarse_shape = (-(-shape[0] // step) + 1, -(-shape[1] // step) + 1)  # one cell beyond the last pixel
    splat = np.zeros(coarse_shape, dtype=np.float32)
    pts = np.asarray(inliers_canvas, dtype=np.float64).reshape(-1, 2)
    keep = (pts[:, 0] >= 0) & (pts[:, 0] < shape[1]) & (pts[:, 1] >= 0) & (pts[:, 1] < shape[0])
    # Bilinear splat: each point spreads over its four nearest cells, so no point moves by rounding.
    cell = pts[keep] / step
    base = np.floor(cell).astype(np.int64)
    frac = (cell - base).astype(np.float32)
    for dy in (0, 1):
        for dx in (0, 1):
            weight = np.abs(1 - dx - frac[:, 0]) * np.abs(1 - dy - frac[:, 1])
            np.add.at(splat, (base[:, 1] + dy, base[:, 0] + dx), weight)
    coarse = cv2.GaussianBlur(splat, (0, 0), sigma_px / step, borderType=cv2.BORDER_CONSTANT)  # no points beyond
    # Coarse cell k sits at pixel k * step: sample it at (x / step, y / step), without canvas-sized maps.
    to_coarse = np.array([[1.0 / step, 0.0, 0.0], [0.0, 1.0 / step, 0.0]])
    density = cv2.warpAffine(coarse, to_coarse, (shape[1], shape[0]), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    peak = float(density.max())
    if peak > 0:
        density /= peak
    return density


def gate_canvas(
    source_only_canvas: np.ndarray,
    inliers_canvas: np.ndarray,
    diag_px: float,
    long_side_px: float,
    cfg: Config,
) -> np.ndarray:
    """Gate G over the canvas: (H, W) float32 in [0, 1].

    ``source_only_canvas`` (H, W) bool where the source is shown alone (``overlap.source_only_mask``);
    ``inliers_canvas`` (N, 2) float64 (x, y) inlier target
    positions on the canvas; ``diag_px`` and ``long_side_px``: diagonal and long side of the input
    image, which set the ramp b and the density blur sigma_d = cfg.sigma_d_ratio * long side.
    Runs on ``cfg.device`` (resolved, ``runtime.resolve_config``) with ``cfg.cpu_threads``.
    """
    shape = np.asarray(source_only_canvas).shape
    device = cfg.device
    sdf = transfer.to_device(open_border_distance_px(source_only_canvas), float, device, "gate")
    density_np = inlier_density(shape, inliers_canvas, cfg.sigma_d_ratio * long_side_px)
    density = transfer.to_device(density_np, float, device, "gate")
    gate = wp.zeros(shape, dtype=float, device=device)
    inputs = [sdf, density, ramp_width_px(diag_px, cfg), cfg.gamma_p, cfg.gamma_min, gate]
    runtime.launch_rows(gate_kernel, shape[0], shape[1], inputs, device, cfg.cpu_threads)
    return transfer.download(gate, "gate")


def guard_field(field: np.ndarray, gate: np.ndarray, cfg: Config) -> np.ndarray:
    """D_guarded = GaussianBlur_{sigma_g}(G * D) on x and y: (H, W, 2) float32 from field (H, W, 2), gate (H, W)."""
    height, width = gate.shape
    device = cfg.device
    field_wp = transfer.to_device(np.ascontiguousarray(field, dtype=np.float32), wp.vec2, device, "gate")
    gate_wp = transfer.to_device(np.ascontiguousarray(gate, dtype=np.float32), float, device, "gate")
    gated = wp.zeros((height, width), dtype=wp.vec2, device=device)
    runtime.launch_rows(gated_field_kernel, height, width, [field_wp, gate_wp, gated], device, cfg.cpu_threads)
    gated_np = transfer.download(gated, "gate").reshape(height, width, 2)
    return cv2.GaussianBlur(gated_np, (0, 0), cfg.sigma_g_px)
