"""Confidence-weighted FFD blend on the lattice (docs/method.md step 4).

For each lattice node ``u`` (canvas pixels): ``p_t = u - o``, ``p_base = A_glob^-1 p_t``,
``p_j = T_j^-1 p_t``, ``D_j = p_j - p_base`` and ``D = sum_j w_j D_j`` with
``w_j ∝ conf_j exp(-|p_t - c_j|^2 / 2 sigma_f^2)`` normalised, each component clipped to
``+-d_max``. Geometry is computed in float64 (canvas coordinates of thousands of pixels), the
displacement is stored as float32.
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring


@wp.func
def lattice_node_canvas(row: int, col: int, node_step: wp.vec2d) -> wp.vec2d:
    """Canvas (x, y) of lattice node (row, col), placed at the sample positions cv2.resize uses,
    so bicubic upsampling of the lattice lands exactly on the nodes."""
    half = wp.float64(0.5)
    return wp.vec2d((wp.float64(col) + half) * node_step[0] - half, (wp.float64(row) + half) * node_step[1] - half)


@wp.func
def affine_apply(linear: wp.mat22d, translation: wp.vec2d, p: wp.vec2d) -> wp.vec2d:
    return linear @ p + translation


@wp.kernel
def ffd_lattice_kernel(
    row0: int,
    node_step: wp.vec2d,
    offset_tgt: wp.vec2d,
    glob_linear_tgt_to_src: wp.mat22d,
    glob_translation_tgt_to_src: wp.vec2d,
    local_linear_tgt_to_src: wp.array(dtype=wp.mat22d),
    local_translation_tgt_to_src: wp.array(dtype=wp.vec2d),
    centres_tgt: wp.array(dtype=wp.vec2d),
    conf: wp.array(dtype=wp.float64),
    sigma_f: wp.float64,
    d_max: wp.float64,
    field_lattice: wp.array2d(dtype=wp.vec2),
):
    """field_lattice[row, col] = blended source-pixel displacement D (x, y) at that node."""
    i, col = wp.tid()
    row = row0 + i
    p_tgt = lattice_node_canvas(row, col, node_step) - offset_tgt
    p_base = affine_apply(glob_linear_tgt_to_src, glob_translation_tgt_to_src, p_tgt)
    inv_two_sigma_sq = wp.float64(1.0) / (wp.float64(2.0) * sigma_f * sigma_f)
    d_sum = wp.vec2d(wp.float64(0.0), wp.float64(0.0))
    w_sum = wp.float64(0.0)
    for j in range(conf.shape[0]):
        p_j = affine_apply(local_linear_tgt_to_src[j], local_translation_tgt_to_src[j], p_tgt)
        r = p_tgt - centres_tgt[j]
        w = conf[j] * wp.exp(-wp.dot(r, r) * inv_two_sigma_sq)
        d_sum = d_sum + w * (p_j - p_base)
        w_sum = w_sum + w
    d = wp.vec2d(wp.float64(0.0), wp.float64(0.0))
    if w_sum > wp.float64(0.0):
        d = d_sum / w_sum
    field_lattice[row, col] = wp.vec2(
        wp.float32(wp.clamp(d[0], -d_max, d_max)), wp.float32(wp.clamp(d[1], -d_max, d_max))
    )
