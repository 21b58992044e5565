"""SENA step 3: one local affine T_j (source -> target) per grid cell, with confidence and refit.

Per cell c_j, every inlier match gets the Gaussian weight
``w_i = exp(-|p_t_i - c_j|^2 / (2 sigma_j^2))``, ``sigma_j = alpha * diag(c_j)`` (paper, step 3), and
T_j is the ridge regression of those weighted matches pulled toward ``A_glob`` by lambda.

Neighbourhood: the paper fits on the matches "in the cell and its immediate neighbours". Here every
inlier takes part with its Gaussian weight: with alpha = 0.35 a match one cell diagonal away weighs
exp(-1 / (2 * 0.35^2)) ~ 0.017, so the fit is in effect the cell and its neighbours, without a hard
border that would make T_j jump when a match crosses it.

Normalisation (docs/method.md step 3; the authors regress raw pixels, which makes lambda depend on image
size and position): the fit runs in Hartley-style coordinates built from the cell's Gaussian,
target ``(p - c_j) / sigma_j`` and source ``(p - A_glob^-1 c_j) sqrt|det A_glob| / sigma_j``, with
weights normalised to sum 1. There ``A_glob`` becomes ``[L / sqrt|det L| | 0]`` (unit determinant,
no translation), the data term is a weighted mean squared residual in units of sigma_j, and lambda
is free of image size, cell position and match count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .affine import apply_affine, compose_affine, invert_affine, scaling_about
from .cells import Cell
from .config import Config
from .errors import GeometryError, InputError


@dataclass(frozen=True)
class LocalAffines:
    """Result of step 3, one row per cell (J cells), in the order of the cells given.

    ``affines_src_to_tgt``: ``(J, 2, 3)`` float64 T_j; ``centres_tgt``: ``(J, 2)`` float64 cell
    centroids c_j ``(x, y)`` in the target frame; ``conf``: ``(J,)`` conf_j in
    ``[cfg.conf_min, cfg.conf_max]``; ``diag_px``: ``(J,)`` cell diagonals; ``unstable``: ``(J,)``
    bool, the lambda_1 fit failed a stability test and was refitted with lambda_2; ``refit``:
    ``(J,)`` bool, the lambda_2 version was kept (lower score); ``rmse_px``: ``(J,)`` weighted RMSE
    of the kept T_j on the matches (target px); ``score``: ``(J,)`` composite instability score of
    the kept T_j; ``n_in_cell``: ``(J,)`` int, matches whose target point lies in the cell's box.
    """

    affines_src_to_tgt: np.ndarray
    centres_tgt: np.ndarray
    conf: np.ndarray
    diag_px: np.ndarray
    unstable: np.ndarray
    refit: np.ndarray
    rmse_px: np.ndarray
    score: np.ndarray
    n_in_cell: np.ndarray


@dataclass(frozen=True)
class _CellFit:
    """The kept T_j of one cell and its figures (one row of ``LocalAffines``)."""

    affine_src_to_tgt: np.ndarray
    conf: float
    unstable: bool
    refit: bool
    rmse_px: float
    score: float
    n_in_cell: int


@dataclass(frozen=True)
class _Diagnosis:
    """Stability figures of one candidate T_j (paper, step 3, composite score)."""

    rmse_px: float
    det: float
    cond: float
    delta_mean_px: float
    score: float


def _ridge_affine(
    pts_src: np.ndarray,
    pts_tgt: np.ndarray,
    weights: np.ndarray,
    affine_src_to_tgt: np.ndarray,
    centre_tgt: np.ndarray,
    sigma_px: float,
    lam: float,
) -> np.ndarray:
    """Weighted ridge affine (src -> tgt) pulled toward ``A_glob`` in the cell's normalised frame.

    Minimises ``sum_i wn_i |T s_i - t_i|^2 + lam |T - A|_F^2`` over the 6 entries of T, in the
    normalised coordinates of the module docstring (``wn`` = weights / their sum).
    """
    det_glob = abs(float(np.linalg.det(affine_src_to_tgt[:, :2])))
    centre_src = apply_affine(invert_affine(affine_src_to_tgt), centre_tgt[None])[0]
    norm_tgt = scaling_about(centre_tgt, 1.0 / sigma_px)  # target -> normalised target
    norm_src = scaling_about(centre_src, np.sqrt(det_glob) / sigma_px)  # source -> normalised source
    prior = compose_affine(compose_affine(norm_tgt, affine_src_to_tgt), invert_affine(norm_src)).T  # (3, 2)
    design = np.hstack([apply_affine(norm_src, pts_src), np.ones((len(pts_src), 1))])  # (N, 3)
    response = apply_affine(norm_tgt, pts_tgt)  # (N, 2)
    weights_norm = weights / weights.sum()
    gram = design.T @ (weights_norm[:, None] * design) + lam * np.eye(3)
    rhs = design.T @ (weights_norm[:, None] * response) + lam * prior
    theta = np.linalg.solve(gram, rhs)  # (3, 2): normalised affine, transposed
    return compose_affine(compose_affine(invert_affine(norm_tgt), theta.T), norm_src)


def _cell_grid_tgt(bbox_tgt: np.ndarray, n_grid: int) -> np.ndarray:
    """``(n_grid^2, 2)`` target points uniformly covering ``bbox_tgt`` (x0, y0, x1, y1)."""
    xs = np.linspace(bbox_tgt[0], bbox_tgt[2], n_grid)
    ys = np.linspace(bbox_tgt[1], bbox_tgt[3], n_grid)
    grid_x, grid_y = np.meshgrid(xs, ys)
    return np.stack([grid_x.ravel(), grid_y.ravel()], axis=1)


def _diagnose(
    affine_local: np.ndarray,
    affine_glob: np.ndarray,
    pts_src: np.ndarray,
    pts_tgt: np.ndarray,
    weights: np.ndarray,
    bbox_tgt: np.ndarray,
    cfg: Config,
) -> _Diagnosis:
    """RMSE, det, cond, delta_mean and the composite score of a candidate T_j (paper, eq. score)."""
    residual_sq = np.sum((apply_affine(affine_local, pts_src) - pts_tgt) ** 2, axis=1)
    rmse_px = float(np.sqrt(np.dot(weights, residual_sq) / weights.sum())) if weights.sum() > 0 else 0.0
    linear = affine_local[:, :2]
    det = float(np.linalg.det(linear))
    cond = float(np.linalg.cond(linear))
    # delta_mean: T_j vs A_glob on an N_g x N_g grid of the cell, compared in the target frame
    # at the source points A_glob places there.
    grid_tgt = _cell_grid_tgt(bbox_tgt, cfg.instability_grid)
    grid_src = apply_affine(invert_affine(affine_glob), grid_tgt)
    delta_mean_px = float(np.mean(np.linalg.norm(apply_affine(affine_local, grid_src) - grid_tgt, axis=1)))
    score = (
        rmse_px
        + cfg.w_cond * cond
        + cfg.w_det * max(0.0, cfg.tau_det - abs(det))
        + cfg.w_delta * delta_mean_px
    )
    return _Diagnosis(rmse_px=rmse_px, det=det, cond=cond, delta_mean_px=delta_mean_px, score=score)


def _is_unstable(diagnosis: _Diagnosis, n_in_cell: int, cfg: Config) -> bool:
    return (
        n_in_cell < cfg.unstable_min_points
        or diagnosis.rmse_px > cfg.unstable_rmse_px
        or abs(diagnosis.det) < cfg.unstable_min_det
        or diagnosis.cond > cfg.unstable_max_cond
        or diagnosis.delta_mean_px > cfg.unstable_max_disp_px
    )


def confidence(weights: np.ndarray, cfg: Config) -> float:
    """conf_j = clip(sum w / (beta max w), k_min, k_max) (paper, eq. confidence_metric); k_min with no weight."""
    if weights.size == 0 or weights.max() <= 0:
        return cfg.conf_min
    return float(np.clip(weights.sum() / (cfg.beta * weights.max()), cfg.conf_min, cfg.conf_max))


def fit_local_affines(
    pts_src: np.ndarray, pts_tgt: np.ndarray, affine_src_to_tgt: np.ndarray, cells: list[Cell], cfg: Config
) -> LocalAffines:
    """Fit T_j for every cell (docs/method.md step 3).

    ``pts_src``, ``pts_tgt``: float64 ``(N, 2)`` ``(x, y)`` of the RANSAC INLIER matches only;
    ``affine_src_to_tgt``: ``(2, 3)`` A_glob; ``cells``: from ``grid_cells``. A cell whose matches
    all have zero weight (or a one-pixel cell) keeps A_glob with confidence k_min, flagged unstable.
    """
    pts_src = np.asarray(pts_src, dtype=np.float64).reshape(-1, 2)
    pts_tgt = np.asarray(pts_tgt, dtype=np.float64).reshape(-1, 2)
    if pts_src.shape != pts_tgt.shape:
        raise InputError(f"inlier point arrays differ in shape: {pts_src.shape} vs {pts_tgt.shape}")
    if not cells:
        raise GeometryError("the overlap has no grid cells: check that the images overlap")
    affine_glob = np.asarray(affine_src_to_tgt, dtype=np.float64)
    fits = [_fit_cell(pts_src, pts_tgt, affine_glob, cell, cfg) for cell in cells]
    return LocalAffines(
        affines_src_to_tgt=np.stack([fit.affine_src_to_tgt for fit in fits]),
        centres_tgt=np.stack([cell.centroid_tgt for cell in cells]).astype(np.float64),
        conf=np.array([fit.conf for fit in fits], dtype=np.float64),
        diag_px=np.array([cell.diag_px for cell in cells], dtype=np.float64),
        unstable=np.array([fit.unstable for fit in fits], dtype=bool),
        refit=np.array([fit.refit for fit in fits], dtype=bool),
        rmse_px=np.array([fit.rmse_px for fit in fits], dtype=np.float64),
        score=np.array([fit.score for fit in fits], dtype=np.float64),
        n_in_cell=np.array([fit.n_in_cell for fit in fits], dtype=np.int64),
    )


def _fit_cell(pts_src: np.ndarray, pts_tgt: np.ndarray, affine_glob: np.ndarray, cell: Cell, cfg: Config) -> _CellFit:
    """T_j of one cell: the lambda_1 fit, or the better of it and the lambda_2 refit when unstable."""
    centre_tgt = np.asarray(cell.centroid_tgt, dtype=np.float64)
    bbox_tgt = np.asarray(cell.bbox_tgt, dtype=np.float64)
    # A pixel covers +-0.5 px around its centre; bbox_tgt holds centres.
    in_cell = np.all((pts_tgt >= bbox_tgt[:2] - 0.5) & (pts_tgt <= bbox_tgt[2:] + 0.5), axis=1)
    n_in_cell = int(in_cell.sum())
    sigma_px = cfg.alpha * cell.diag_px
    dist_sq = np.sum((pts_tgt - centre_tgt) ** 2, axis=1)
    # A one-pixel cell (diagonal 0) has no Gaussian: it gets no weight and keeps A_glob below.
    weights = np.exp(-dist_sq / (2.0 * sigma_px**2)) if sigma_px > 0 else np.zeros(len(pts_tgt))
    conf = confidence(weights, cfg)
    if weights.sum() <= 0:
        glob = _diagnose(affine_glob, affine_glob, pts_src, pts_tgt, weights, bbox_tgt, cfg)
        return _CellFit(affine_glob.copy(), conf, True, False, glob.rmse_px, glob.score, n_in_cell)
    affine_1 = _ridge_affine(pts_src, pts_tgt, weights, affine_glob, centre_tgt, sigma_px, cfg.lambda1)
    diag_1 = _diagnose(affine_1, affine_glob, pts_src, pts_tgt, weights, bbox_tgt, cfg)
    if not _is_unstable(diag_1, n_in_cell, cfg):
        return _CellFit(affine_1, conf, False, False, diag_1.rmse_px, diag_1.score, n_in_cell)
    affine_2 = _ridge_affine(pts_src, pts_tgt, weights, affine_glob, centre_tgt, sigma_px, cfg.lambda2)
    diag_2 = _diagnose(affine_2, affine_glob, pts_src, pts_tgt, weights, bbox_tgt, cfg)
    if diag_2.score < diag_1.score:
        return _CellFit(affine_2, conf, True, True, diag_2.rmse_px, diag_2.score, n_in_cell)
    return _CellFit(affine_1, conf, True, False, diag_1.rmse_px, diag_1.score, n_in_cell)


def sigma_f(cells_or_local: list[Cell] | LocalAffines, cfg: Config) -> float:
    """sigma_f = alpha_f * mean cell diagonal (px), the FFD blending width of step 4."""
    if isinstance(cells_or_local, LocalAffines):
        diags = cells_or_local.diag_px
    else:
        diags = np.array([cell.diag_px for cell in cells_or_local], dtype=np.float64)
    if diags.size == 0:
        raise GeometryError("the overlap has no grid cells: check that the images overlap")
    return float(cfg.alpha_f * diags.mean())
