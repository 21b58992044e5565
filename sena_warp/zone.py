"""Step 7: the adequate (parallax-minimised) zone of the overlap (docs/method.md step 7, paper Algorithm 1).

Inlier matches after the warp give a residual disparity ``d = x_src' - x_tgt'`` on the canvas. Points
in flat regions are dropped, the rest are binned by canvas x into ``cfg.zone_classes`` classes across
the overlap, consecutive classes whose mean disparities step by at most ``v`` form clusters
(Algorithm 1), and the cluster with the HIGHEST score ``w = C / (sigma + lambda |mu_c - mu_g| + eps)``
(paper Eq. ratio) is the zone. The authors' code picks the lowest score and can loop forever; we
follow the paper's text.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sena_warp.config import Config
from sena_warp.errors import GeometryError


@dataclass(frozen=True)
class DisparityClasses:
    """Points binned by canvas x into equal-width classes over [x0, x1).

    ``class_of_point`` (N,) int64 class index per point; ``means_px`` (n,) float64 mean disparity
    per class (NaN where the class is empty); ``counts`` (n,) int64 points per class.
    """

    class_of_point: np.ndarray
    means_px: np.ndarray
    counts: np.ndarray
    x0: float
    x1: float

    @property
    def class_width_px(self) -> float:
        return (self.x1 - self.x0) / len(self.means_px)


@dataclass(frozen=True)
class ZoneCluster:
    """One cluster of consecutive classes: class indices, point count C, std sigma, mean mu_c, score w."""

    classes: tuple[int, ...]
    n_points: int
    std_px: float
    mean_px: float
    score: float


@dataclass(frozen=True)
class Zone:
    """The adequate zone: canvas x-range [x0, x1), the indices of the points inside it.

    ``point_indices`` (M,) int64 index the point arrays given to ``adequate_zone`` (textured points in
    the overlap whose class is in the chosen cluster). ``clusters`` are all kept clusters with their
    scores, ``chosen`` the index of the winner in ``clusters`` (-1 on fallback). ``fallback`` is True
    when no cluster of >= 2 classes exists and the zone is the whole overlap.
    """

    x0: float
    x1: float
    point_indices: np.ndarray
    clusters: tuple[ZoneCluster, ...]
    chosen: int
    fallback: bool


def disparity_px(pts_src_canvas: np.ndarray, pts_tgt_canvas: np.ndarray) -> np.ndarray:
    """(N,) float64 residual disparity ``x_src' - x_tgt'`` of matched (N, 2) (x, y) canvas points."""
    return np.asarray(pts_src_canvas, np.float64)[:, 0] - np.asarray(pts_tgt_canvas, np.float64)[:, 0]


def patch_values(grey_canvas: np.ndarray, pts_canvas: np.ndarray, patch_px: int) -> np.ndarray:
    """Grey values of the ``patch_px`` x ``patch_px`` patch centred on each point's nearest pixel.

    grey_canvas: (H, W) float32, NaN where not covered. pts_canvas: (N, 2) float64 (x, y).
    Returns (N, patch_px * patch_px) float64; pixels outside the canvas are NaN, so any statistic
    over a patch that leaves the covered area is NaN (and every comparison with it is False). A
    point with a NaN coordinate (a forward point that did not converge, ``forward_points``) gets an
    all-NaN patch.
    """
    height, width = grey_canvas.shape
    half = patch_px // 2
    steps = np.arange(patch_px) - half
    centres, finite = _nearest_pixels(pts_canvas)
    cols = centres[:, 0, None, None] + steps[None, None, :]
    rows = centres[:, 1, None, None] + steps[None, :, None]
    inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height) & finite[:, None, None]
    values = grey_canvas[np.clip(rows, 0, height - 1), np.clip(cols, 0, width - 1)].astype(np.float64)
    values[~inside] = np.nan
    return values.reshape(len(pts_canvas), patch_px * patch_px)


def textured(grey_canvas: np.ndarray, pts_canvas: np.ndarray, cfg: Config) -> np.ndarray:
    """(N,) bool: the local grey std over a ``cfg.flat_patch_px`` patch is >= ``cfg.flat_min_std``.

    Flat regions give unstable matches (paper, "Determination of an Adequate Parallax-Free Zone").
    """
    std = np.std(patch_values(grey_canvas, pts_canvas, cfg.flat_patch_px), axis=1)
    return std >= cfg.flat_min_std


def overlap_x_extent(overlap_mask_canvas: np.ndarray) -> tuple[float, float]:
    """Canvas x-range [x0, x1) of the columns holding any overlap pixel; GeometryError if empty."""
    columns = np.flatnonzero(overlap_mask_canvas.any(axis=0))
    if columns.size == 0:
        raise GeometryError("the overlap mask is empty: the images do not overlap on the canvas")
    return float(columns[0]), float(columns[-1] + 1)


def disparity_classes(
    x_canvas: np.ndarray, disparity: np.ndarray, x0: float, x1: float, n_classes: int
) -> DisparityClasses:
    """Bin points by canvas x into ``n_classes`` classes of width (x1 - x0) / n_classes.

    x_canvas, disparity: (N,) float64. Points outside [x0, x1) are clipped into the end classes.
    """
    class_width = (x1 - x0) / n_classes
    class_of_point = np.clip(np.floor((x_canvas - x0) / class_width), 0, n_classes - 1).astype(np.int64)
    counts = np.bincount(class_of_point, minlength=n_classes)
    sums = np.bincount(class_of_point, weights=disparity, minlength=n_classes)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return DisparityClasses(class_of_point, means, counts, float(x0), float(x1))


def cluster_classes(class_means: np.ndarray, jump_px: float) -> list[list[int]]:
    """Algorithm 1: consecutive classes whose mean disparities step by <= ``jump_px`` (v).

    class_means: (n,) float64, NaN for an empty class. Walks left to right; class i joins the
    current cluster while |d_i - d_(i-1)| <= v; clusters of fewer than 2 classes are dropped.
    An empty class ends the current cluster and belongs to none: with no points there is no evidence
    that the disparity is continuous across it, and a zone must be supported everywhere.
    Returns clusters as lists of class indices, left to right.
    """
    clusters: list[list[int]] = []
    current: list[int] = []
    for i, mean in enumerate(np.asarray(class_means, np.float64)):
        if np.isnan(mean):
            clusters, current = _close(clusters, current), []
        elif current and abs(mean - class_means[current[-1]]) <= jump_px:
            current.append(i)
        else:
            clusters, current = _close(clusters, current), [i]
    return _close(clusters, current)


def _close(clusters: list[list[int]], current: list[int]) -> list[list[int]]:
    """``clusters`` with ``current`` appended when it holds at least two classes."""
    return clusters + [current] if len(current) >= 2 else clusters


def cluster_score(
    n_points: int, cluster_means_px: np.ndarray, global_mean_px: float, lam: float, eps: float
) -> float:
    """Paper Eq. (ratio): w = C / (sigma + lambda * |mu_c - mu_g| + eps).

    C = ``n_points``; sigma, mu_c = population std and mean of the cluster's class means (px);
    mu_g = ``global_mean_px``, the mean over all non-empty class means.
    """
    sigma = float(np.std(cluster_means_px))
    delta_mu = abs(float(np.mean(cluster_means_px)) - global_mean_px)
    return n_points / (sigma + lam * delta_mu + eps)


def adequate_zone(
    pts_src_canvas: np.ndarray,
    pts_tgt_canvas: np.ndarray,
    overlap_mask_canvas: np.ndarray,
    grey_src_canvas: np.ndarray,
    grey_tgt_canvas: np.ndarray,
    cfg: Config,
) -> Zone:
    """SENA step 7: the canvas x-range of the best-scoring disparity cluster.

    pts_src_canvas: (N, 2) float64 (x, y) warped source points; pts_tgt_canvas: (N, 2) the same
    matches' target points on the canvas. overlap_mask_canvas: (H, W) bool. grey_*_canvas: (H, W)
    float32, NaN where not covered. Points outside the overlap or flat (in either image) are
    ignored. Classes are binned on the target x, the frame the seam follows.
    """
    pts_src_canvas = np.asarray(pts_src_canvas, np.float64)
    pts_tgt_canvas = np.asarray(pts_tgt_canvas, np.float64)
    x0, x1 = overlap_x_extent(overlap_mask_canvas)
    keep = (
        _in_mask(overlap_mask_canvas, pts_tgt_canvas)
        & textured(grey_src_canvas, pts_src_canvas, cfg)
        & textured(grey_tgt_canvas, pts_tgt_canvas, cfg)
    )
    kept = np.flatnonzero(keep)
    classes = disparity_classes(
        pts_tgt_canvas[kept, 0], disparity_px(pts_src_canvas[kept], pts_tgt_canvas[kept]), x0, x1, cfg.zone_classes
    )
    groups = cluster_classes(classes.means_px, cfg.zone_jump_px)
    if not groups:
        return Zone(x0, x1, kept, (), -1, True)
    global_mean = float(np.nanmean(classes.means_px))
    clusters = tuple(_cluster(group, classes, global_mean, cfg) for group in groups)
    chosen = int(np.argmax([cluster.score for cluster in clusters]))
    best = clusters[chosen]
    width = classes.class_width_px
    inside = np.isin(classes.class_of_point, best.classes)
    return Zone(
        x0=x0 + best.classes[0] * width,
        x1=x0 + (best.classes[-1] + 1) * width,
        point_indices=kept[inside],
        clusters=clusters,
        chosen=chosen,
        fallback=False,
    )


def _cluster(group: list[int], classes: DisparityClasses, global_mean_px: float, cfg: Config) -> ZoneCluster:
    """The ZoneCluster of one Algorithm-1 group of class indices, with its score."""
    means = classes.means_px[group]
    n_points = int(classes.counts[group].sum())
    return ZoneCluster(
        classes=tuple(group),
        n_points=n_points,
        std_px=float(np.std(means)),
        mean_px=float(np.mean(means)),
        score=cluster_score(n_points, means, global_mean_px, cfg.zone_lambda, cfg.zone_eps),
    )


def _nearest_pixels(pts_canvas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, 2) int64 (col, row) of the pixel nearest each (x, y) point, (N,) bool: the point is finite).

    NaN points get pixel (0, 0) and False: casting NaN to an integer is undefined (numpy warns).
    """
    finite = np.isfinite(pts_canvas).all(axis=1)
    return np.rint(np.where(finite[:, None], pts_canvas, 0.0)).astype(np.int64), finite


def _in_mask(mask_canvas: np.ndarray, pts_canvas: np.ndarray) -> np.ndarray:
    """(N,) bool: the pixel nearest each (x, y) canvas point is inside the canvas and the mask (False
    for NaN points)."""
    height, width = mask_canvas.shape
    centres, finite = _nearest_pixels(pts_canvas)
    cols, rows = centres[:, 0], centres[:, 1]
    inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height) & finite
    hit = np.zeros(len(pts_canvas), dtype=bool)
    hit[inside] = mask_canvas[rows[inside], cols[inside]]
    return hit
