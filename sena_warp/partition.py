"""Step 9: partition the canvas at the keypoint chain and build the seam maps (SENA.md step 9, paper
"Partitioning and Reconstruction").

The K anchors cut the canvas into K+1 horizontal bands. In each band the seam x follows the target
anchors, interpolated linearly in y (constant above the first and below the last anchor). The
output row is the source left of its seam and the target right of it, blended by a linear alpha of
width ``cfg.transition_px`` (Gaussian-smoothed with ``cfg.seam_smooth_sigma_px`` across the seam).
The source is resampled so that each source anchor lands on its target anchor: per row, the
anchor residual (dx, dy) = anchor_src - anchor_tgt is interpolated like the seam, applied in full
inside the transition and faded out (smootherstep) over ``cfg.seam_fade_px`` beyond it, so the
source far from the seam keeps its step-6 shape. The per-pixel part is ``kernels/seam.py``.
Convention: the source is the LEFT view on the canvas (the caller transposes/flips other rigs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.errors import GeometryError, InputError
from sena_warp.kernels import runtime
from sena_warp.kernels.seam import seam_maps_kernel

@dataclass(frozen=True)
class SeamRows:
    """Per canvas row y (all (H,) float32): seam x ``s(y)``, the source row ``y + dy(y)`` that
    row y samples at the seam, and the x shift ``dx(y)`` applied there."""

    seam_x: np.ndarray
    src_row_y: np.ndarray
    shift_x: np.ndarray


@dataclass
class SeamMaps:
    """The three per-pixel maps of the stitch and the anchors they were built from, in the working
    frame (``stitch.StitchMaps`` holds them in the input frame).

    map_src_canvas, map_tgt_canvas: (H, W, 2) float32 (x, y) sample positions in the working-frame
    source and target images, per working-canvas pixel (map_tgt = u - o); alpha_canvas: (H, W)
    float32 weight of the source; seam_x_canvas: (H,) float32 seam x per canvas row;
    anchors_*_canvas: (K, 2) float64 (x, y) on the working canvas.
    """

    map_src_canvas: np.ndarray
    map_tgt_canvas: np.ndarray
    alpha_canvas: np.ndarray
    seam_x_canvas: np.ndarray
    anchors_src_canvas: np.ndarray
    anchors_tgt_canvas: np.ndarray


def seam_rows(anchors_src_canvas: np.ndarray, anchors_tgt_canvas: np.ndarray, height: int) -> SeamRows:
    """Interpolate seam x and the anchor residual over canvas rows 0..height-1.

    anchors_*_canvas: (K, 2) float64 (x, y), K >= 1, target y strictly increasing. Linear between
    anchors in target y, constant beyond the first and last anchor.
    """
    anchors_src = np.asarray(anchors_src_canvas, np.float64)
    anchors_tgt = np.asarray(anchors_tgt_canvas, np.float64)
    if len(anchors_tgt) == 0 or anchors_src.shape != anchors_tgt.shape:
        raise GeometryError("the seam needs at least one anchor, with as many source as target anchors")
    if np.any(np.diff(anchors_tgt[:, 1]) <= 0):
        raise GeometryError("seam anchors must be sorted by strictly increasing target y")
    rows = np.arange(height, dtype=np.float64)
    residual = anchors_src - anchors_tgt
    return SeamRows(
        seam_x=np.interp(rows, anchors_tgt[:, 1], anchors_tgt[:, 0]).astype(np.float32),
        src_row_y=(rows + np.interp(rows, anchors_tgt[:, 1], residual[:, 1])).astype(np.float32),
        shift_x=np.interp(rows, anchors_tgt[:, 1], residual[:, 0]).astype(np.float32),
    )


def seam_maps(
    map_src_canvas: np.ndarray,
    canvas: Canvas,
    anchors_src_canvas: np.ndarray,
    anchors_tgt_canvas: np.ndarray,
    cfg: Config,
) -> SeamMaps:
    """SENA step 9: source map, target map and alpha of the stitch (Warp kernel ``seam_maps_kernel``).

    map_src_canvas: (H, W, 2) float32 step-6 source sampling map; canvas: its size and target offset;
    anchors_*_canvas: (K, 2) float64 (x, y) from ``keypoint_chain`` (warped source / target
    positions). Runs on ``cfg.device`` (resolved, ``runtime.resolve_config``) with ``cfg.cpu_threads``.
    """
    if map_src_canvas.shape != (canvas.height, canvas.width, 2):
        raise InputError(f"source map shape {map_src_canvas.shape} does not match the canvas {canvas.shape}")
    if cfg.transition_px < 1 or cfg.seam_fade_px <= 0:
        raise InputError("transition_px must be >= 1 and seam_fade_px > 0")
    rows = seam_rows(anchors_src_canvas, anchors_tgt_canvas, canvas.height)
    shape = canvas.shape
    device = cfg.device
    map_src_out = wp.empty(shape, dtype=wp.vec2, device=device)
    map_tgt_out = wp.empty(shape, dtype=wp.vec2, device=device)
    alpha_out = wp.empty(shape, dtype=float, device=device)
    inputs = [
        wp.array(np.ascontiguousarray(map_src_canvas, np.float32), dtype=wp.vec2, device=device),
        wp.array(rows.seam_x, dtype=float, device=device),
        wp.array(rows.src_row_y, dtype=float, device=device),
        wp.array(rows.shift_x, dtype=float, device=device),
        wp.vec2(*canvas.offset_tgt),
        float(cfg.transition_px),
        float(cfg.seam_smooth_sigma_px),
        float(cfg.seam_fade_px),
        map_src_out,
        map_tgt_out,
        alpha_out,
    ]
    runtime.launch_rows(seam_maps_kernel, canvas.height, canvas.width, inputs, device, cfg.cpu_threads)
    return SeamMaps(
        map_src_canvas=map_src_out.numpy().reshape(*shape, 2),
        map_tgt_canvas=map_tgt_out.numpy().reshape(*shape, 2),
        alpha_canvas=alpha_out.numpy(),
        seam_x_canvas=rows.seam_x,
        anchors_src_canvas=np.asarray(anchors_src_canvas, np.float64),
        anchors_tgt_canvas=np.asarray(anchors_tgt_canvas, np.float64),
    )
