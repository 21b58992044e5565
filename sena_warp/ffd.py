"""Step 4: the FFD displacement field over the canvas (SENA.md step 4, paper "Locally adaptive image warping").

The local affines T_j are blended on a coarse lattice (Warp kernel ``kernels/ffd.py``), smoothed
there, and upsampled bicubically to every canvas pixel.
"""

from __future__ import annotations

import cv2
import numpy as np
import warp as wp

from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.affine import invert_affine
from sena_warp.kernels import runtime
from sena_warp.kernels.ffd import ffd_lattice_kernel


def ffd_lattice(
    canvas: Canvas,
    affine_src_to_tgt: np.ndarray,
    affines_src_to_tgt: np.ndarray,
    centres_tgt: np.ndarray,
    conf: np.ndarray,
    sigma_f: float,
    cfg: Config,
) -> np.ndarray:
    """Blended, clipped displacement on the (cfg.lattice_ny, cfg.lattice_nx) lattice, before its blur.

    Node (r, c) sits at canvas ((c + 0.5) W / N_x - 0.5, (r + 0.5) H / N_y - 0.5), where cv2.resize
    samples. Returns (N_y, N_x, 2) float32 (dx, dy) in source pixels. ``centres_tgt`` (J, 2) are
    cell centres in target (x, y); ``conf`` (J,) their confidences; ``sigma_f`` in target pixels.
    Runs on ``cfg.device`` (resolved, ``runtime.resolve_config``) with ``cfg.cpu_threads``.
    """
    device = cfg.device
    glob_tgt_to_src = invert_affine(affine_src_to_tgt)
    local_tgt_to_src = invert_affine(np.asarray(affines_src_to_tgt, dtype=np.float64).reshape(-1, 2, 3))
    node_step = wp.vec2d(canvas.width / cfg.lattice_nx, canvas.height / cfg.lattice_ny)
    field = wp.zeros((cfg.lattice_ny, cfg.lattice_nx), dtype=wp.vec2, device=device)
    inputs = [
        node_step,
        wp.vec2d(*canvas.offset_tgt),
        wp.mat22d(glob_tgt_to_src[:, :2]),
        wp.vec2d(glob_tgt_to_src[:, 2]),
        wp.array(np.ascontiguousarray(local_tgt_to_src[:, :, :2]), dtype=wp.mat22d, device=device),
        wp.array(np.ascontiguousarray(local_tgt_to_src[:, :, 2]), dtype=wp.vec2d, device=device),
        wp.array(np.asarray(centres_tgt, dtype=np.float64).reshape(-1, 2), dtype=wp.vec2d, device=device),
        wp.array(np.asarray(conf, dtype=np.float64).reshape(-1), dtype=wp.float64, device=device),
        float(sigma_f),
        float(cfg.d_max_px),
        field,
    ]
    runtime.launch_rows(ffd_lattice_kernel, cfg.lattice_ny, cfg.lattice_nx, inputs, device, cfg.cpu_threads)
    return field.numpy().reshape(cfg.lattice_ny, cfg.lattice_nx, 2)


def ffd_field_canvas(
    canvas: Canvas,
    affine_src_to_tgt: np.ndarray,
    affines_src_to_tgt: np.ndarray,
    centres_tgt: np.ndarray,
    conf: np.ndarray,
    sigma_f: float,
    cfg: Config,
) -> np.ndarray:
    """FFD displacement D over the canvas: (H, W, 2) float32 (dx, dy) in source pixels.

    Lattice blend (``ffd_lattice``), Gaussian blur of sigma_l = cfg.sigma_l_nodes nodes on the
    lattice, bicubic upsampling to (canvas.height, canvas.width).
    """
    lattice = ffd_lattice(canvas, affine_src_to_tgt, affines_src_to_tgt, centres_tgt, conf, sigma_f, cfg)
    lattice = cv2.GaussianBlur(lattice, (0, 0), cfg.sigma_l_nodes, borderType=cv2.BORDER_REPLICATE)
    return cv2.resize(lattice, (canvas.width, canvas.height), interpolation=cv2.INTER_CUBIC)
