"""Step 4: the FFD displacement field over the canvas (docs/method.md step 4, paper "Locally adaptive image warping").

The field D (source pixels) lives on a lattice over the canvas and is upsampled bicubically
(``cv2.resize``, Keys a = -0.75) to every canvas pixel. Two ways to get the lattice (``cfg.ffd_model``):

* ``"blend"``, the paper's: the local affines T_j of step 3 are blended with Gaussian weights at each
  node (Warp kernel ``kernels/ffd.py``), clipped to d_max and smoothed on the lattice.
* ``"fit"``, ours: the lattice is fitted to the matches by regularised least squares. Where
  neighbouring T_j disagree the paper's blend bends straight lines (paving rows S-kinked, columns
  bent), and the gate that keeps the source's global shape outside the overlap ramps the
  correction in over a band that eats into the overlap, so alignment suffers there. The fitted D
  minimises

      mean_i w_i |D(t_i + o) - (s_i - A_glob^-1 t_i)|^2 + lambda_b L^4 mean(|D_xx|^2 + 2|D_xy|^2 + |D_yy|^2)

  over the matches (s_i, t_i) within ``cfg.fit_match_px`` of A_glob: the residual of the global
  model at each match against the thin-plate bending energy of the field (L = image diagonal, so
  lambda_b is free of image size). Bending energy does not penalise an affine field, so where there
  are no matches (the source-only part of the canvas) the field continues affinely: the source keeps
  an affine shape there and straight lines stay straight without a gate. The weights w_i are Tukey
  biweights of the last fit's residuals (``cfg.fit_tukey_px``), re-estimated ``cfg.fit_iterations``
  times, so wrong matches drop out.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import warp as wp

from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.affine import apply_affine, invert_affine
from sena_warp.errors import GeometryError
from sena_warp.kernels import runtime, transfer
from sena_warp.kernels.ffd import ffd_lattice_kernel

CUBIC_A = -0.75  # cv2.resize's INTER_CUBIC kernel: the fit samples the lattice as the upsampling does
RIDGE = 1e-9  # keeps the fit's normal matrix definite where the data leave an affine field free


@dataclass(frozen=True)
class LatticeFit:
    """The fitted lattice of ``cfg.ffd_model == "fit"``.

    ``lattice`` (Ny, Nx, 2) float32 (dx, dy) source pixels at the cv2.resize node positions of the
    canvas; ``used`` (M,) bool over the matches given: those within ``cfg.fit_match_px`` of A_glob;
    ``residual_px`` (N,) float64 |D(u_i) - r_i| of each used match after the last solve;
    ``weights`` (N,) float64 their final Tukey weights (0: left out as wrong).
    """

    lattice: np.ndarray
    used: np.ndarray
    residual_px: np.ndarray
    weights: np.ndarray


def blended_lattice(
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
        transfer.to_device(np.ascontiguousarray(local_tgt_to_src[:, :, :2]), wp.mat22d, device, "ffd"),
        transfer.to_device(np.ascontiguousarray(local_tgt_to_src[:, :, 2]), wp.vec2d, device, "ffd"),
        transfer.to_device(np.asarray(centres_tgt, dtype=np.float64).reshape(-1, 2), wp.vec2d, device, "ffd"),
        transfer.to_device(np.asarray(conf, dtype=np.float64).reshape(-1), wp.float64, device, "ffd"),
        float(sigma_f),
        float(cfg.d_max_px),
        field,
    ]
    runtime.launch_rows(ffd_lattice_kernel, cfg.lattice_ny, cfg.lattice_nx, inputs, device, cfg.cpu_threads)
    return transfer.download(field, "ffd").reshape(cfg.lattice_ny, cfg.lattice_nx, 2)


def smoothed_blend_lattice(
    canvas: Canvas,
    affine_src_to_tgt: np.ndarray,
    affines_src_to_tgt: np.ndarray,
    centres_tgt: np.ndarray,
    conf: np.ndarray,
    sigma_f: float,
    cfg: Config,
) -> np.ndarray:
    """The paper's lattice: the blend (``blended_lattice``) after a Gaussian blur of sigma_l =
    ``cfg.sigma_l_nodes`` nodes; (N_y, N_x, 2) float32."""
    lattice = blended_lattice(canvas, affine_src_to_tgt, affines_src_to_tgt, centres_tgt, conf, sigma_f, cfg)
    return cv2.GaussianBlur(lattice, (0, 0), cfg.sigma_l_nodes, borderType=cv2.BORDER_REPLICATE)


def field_from_lattice(lattice: np.ndarray, canvas: Canvas) -> np.ndarray:
    """FFD displacement D over the canvas: the lattice upsampled bicubically, (H, W, 2) float32 (dx, dy)
    in source pixels."""
    return cv2.resize(lattice, (canvas.width, canvas.height), interpolation=cv2.INTER_CUBIC)


def lattice_shape(canvas: Canvas, diag_px: float, cfg: Config) -> tuple[int, int]:
    """(Ny, Nx): nodes about ``diag_px / cfg.lattice_nodes`` apart over the canvas, at least 4 per side."""
    spacing = diag_px / cfg.lattice_nodes
    return max(4, int(np.ceil(canvas.height / spacing))), max(4, int(np.ceil(canvas.width / spacing)))


def cubic_weights(t: np.ndarray) -> np.ndarray:
    """(N, 4) Keys cubic-convolution weights (a = -0.75) of the taps i0-1 .. i0+2 at fractions t (N,)."""
    a = CUBIC_A
    x = np.abs(np.stack([t + 1.0, t, 1.0 - t, 2.0 - t], axis=1))
    near = (a + 2.0) * x**3 - (a + 3.0) * x**2 + 1.0
    far = a * x**3 - 5.0 * a * x**2 + 8.0 * a * x - 4.0 * a
    return np.where(x <= 1.0, near, np.where(x < 2.0, far, 0.0))


def _axis_taps(coords: np.ndarray, nodes: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Node indices (N, 4), clamped like cv2.resize's replicated border, and weights along one axis."""
    g = (coords + 0.5) * nodes / size - 0.5
    i0 = np.floor(g).astype(np.int64)
    return np.clip(i0[:, None] + np.arange(-1, 3)[None, :], 0, nodes - 1), cubic_weights(g - i0)


def lattice_taps(pts_canvas: np.ndarray, canvas: Canvas, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(N, 16) flat node indices and weights with which the bicubic upsampling of a (Ny, Nx)
    lattice to the canvas takes its value at canvas points (N, 2) (x, y)."""
    ny, nx = shape
    ix, wx = _axis_taps(pts_canvas[:, 0], nx, canvas.width)
    iy, wy = _axis_taps(pts_canvas[:, 1], ny, canvas.height)
    index = (iy[:, :, None] * nx + ix[:, None, :]).reshape(-1, 16)
    weight = (wy[:, :, None] * wx[:, None, :]).reshape(-1, 16)
    return index, weight


@lru_cache(maxsize=8)
def bending_matrix(ny: int, nx: int, step_x: float, step_y: float) -> np.ndarray:
    """(n, n) B^T B of the lattice's thin-plate energy sum (D_xx^2 + 2 D_xy^2 + D_yy^2) * area per node,
    second differences in canvas pixels (node steps ``step_x``, ``step_y``), n = Ny * Nx."""
    node = np.arange(ny * nx).reshape(ny, nx)
    stencils = [
        (np.stack([node[:, :-2], node[:, 1:-1], node[:, 2:]], -1).reshape(-1, 3), np.array([1.0, -2.0, 1.0]) / step_x**2, 1.0),
        (np.stack([node[:-2], node[1:-1], node[2:]], -1).reshape(-1, 3), np.array([1.0, -2.0, 1.0]) / step_y**2, 1.0),
        (np.stack([node[:-1, :-1], node[:-1, 1:], node[1:, :-1], node[1:, 1:]], -1).reshape(-1, 4),
         np.array([1.0, -1.0, -1.0, 1.0]) / (step_x * step_y), 2.0),
    ]
    n = ny * nx
    matrix = np.zeros(n * n)
    for index, coef, weight in stencils:
        pairs = (index[:, :, None] * n + index[:, None, :]).ravel()
        values = np.broadcast_to(weight * step_x * step_y * np.outer(coef, coef), (len(index), len(coef), len(coef)))
        matrix += np.bincount(pairs, weights=values.ravel(), minlength=n * n)
    return matrix.reshape(n, n)


def bending_regulariser(canvas: Canvas, shape: tuple[int, int], diag_px: float, lambda_bend: float) -> np.ndarray:
    """(n, n) the fit's regulariser for a (Ny, Nx) lattice over ``canvas``: ``lambda_bend`` L^4 / area x the
    thin-plate energy (``bending_matrix``), plus :data:`RIDGE` on the diagonal (L = ``diag_px``)."""
    ny, nx = shape
    bending = bending_matrix(ny, nx, canvas.width / nx, canvas.height / ny)
    return lambda_bend * diag_px**4 / (canvas.width * canvas.height) * bending + RIDGE * np.eye(ny * nx)


class LatticeTerms:
    """The data term of a lattice fit at canvas points (N, 2) (x, y): each point's 16 bicubic taps
    (``lattice_taps``) on a (Ny, Nx) lattice over ``canvas``, and the normal equations they give for
    any per-point weights and values (:meth:`normal`)."""

    def __init__(self, pts_canvas: np.ndarray, canvas: Canvas, shape: tuple[int, int]):
        self.nodes = shape[0] * shape[1]
        self.index, self.weight = lattice_taps(pts_canvas, canvas, shape)
        n = self.nodes
        self._pairs = (self.index[:, :, None] * n + self.index[:, None, :]).reshape(len(self.index), -1)
        self._outer = (self.weight[:, :, None] * self.weight[:, None, :]).reshape(len(self.index), -1)

    def normal(self, w: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, n) sum_i w_i b_i b_i^T and (n, 2) sum_i w_i b_i v_i for weights ``w`` (N,) and values (N, 2),
        b_i the point's taps."""
        n = self.nodes
        normal = np.bincount(self._pairs.ravel(), weights=(w[:, None] * self._outer).ravel(), minlength=n * n)
        rhs = np.stack([np.bincount(self.index.ravel(), weights=(w[:, None] * self.weight * values[:, k:k + 1]).ravel(),
                                    minlength=n) for k in range(2)], axis=1)
        return normal.reshape(n, n), rhs

    def values(self, solution: np.ndarray) -> np.ndarray:
        """(N, 2) the lattice ``solution`` (n, 2) at the points."""
        return np.einsum("nk,nkc->nc", self.weight, solution[self.index])


def tukey_weights(error: np.ndarray, scale_px: float) -> np.ndarray:
    """Tukey biweights of errors (N,) at ``scale_px``."""
    return np.clip(1.0 - (error / scale_px) ** 2, 0.0, None) ** 2


def fit_lattice(pts_canvas: np.ndarray, residual_src: np.ndarray, canvas: Canvas, shape: tuple[int, int],
                diag_px: float, cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IRLS fit of the lattice (Ny, Nx, 2) to residuals (N, 2) at canvas points (N, 2); see the module
    docstring. Returns (lattice float32, |fit - residual| (N,), Tukey weights (N,))."""
    ny, nx = shape
    terms = LatticeTerms(pts_canvas, canvas, shape)
    regulariser = bending_regulariser(canvas, shape, diag_px, cfg.lambda_bend)
    tukey = np.ones(len(pts_canvas))
    for _ in range(max(1, cfg.fit_iterations)):
        w = tukey / max(tukey.sum(), 1e-12)
        normal, rhs = terms.normal(w, residual_src)
        ok, solution = cv2.solve(normal + regulariser, rhs, flags=cv2.DECOMP_CHOLESKY)
        if not ok:
            raise GeometryError("the FFD lattice fit is singular; check that the images overlap")
        error = np.hypot(*(terms.values(solution) - residual_src).T)
        tukey = tukey_weights(error, cfg.fit_tukey_px)
        if tukey.sum() <= 0:
            break
    return solution.reshape(ny, nx, 2).astype(np.float32), error, tukey


def fitted_lattice(canvas: Canvas, affine_src_to_tgt: np.ndarray, pts_src: np.ndarray, pts_tgt: np.ndarray,
                    diag_px: float, cfg: Config) -> LatticeFit:
    """The fitted lattice for matches (N, 2) source / target (x, y), only those within
    ``cfg.fit_match_px`` of A_glob taking part."""
    pts_src = np.asarray(pts_src, np.float64).reshape(-1, 2)
    pts_tgt = np.asarray(pts_tgt, np.float64).reshape(-1, 2)
    residual_src = pts_src - apply_affine(invert_affine(affine_src_to_tgt), pts_tgt)
    near_tgt = apply_affine(affine_src_to_tgt, pts_src) - pts_tgt
    used = np.hypot(*near_tgt.T) <= cfg.fit_match_px
    lattice, error, tukey = fit_lattice(canvas.tgt_to_canvas(pts_tgt[used]), residual_src[used], canvas,
                                        lattice_shape(canvas, diag_px, cfg), diag_px, cfg)
    return LatticeFit(lattice, used, error, tukey)
