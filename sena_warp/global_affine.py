"""SENA step 1: the global affine ``A_glob`` (source -> target) by RANSAC.

Two models are tried on the same matches, OpenCV's full affine (6 dof) and its partial affine
(similarity: rotation, uniform scale, translation; 4 dof). docs/method.md step 1 keeps the one with more
RANSAC inliers (``global_model_choice = "inliers"``); ours keeps the one more matches lie within
``fit_match_px`` of ("support"): the fitted lattice follows all of those, so that is the model it can
best correct, where a 3 px inlier count only says which single scene plane the model fits. On a
parallax scene the two can disagree by 30 % in scale (spw_2: the affine has 200 inliers and 880
matches within 50 px, the similarity 156 and 1261; docs/evaluation.md). A tie goes to the similarity,
the more rigid model; where the supports are within ``global_model_margin`` of each other, the
inliers decide. Only the kept model's inliers go on to the local models.

Inliers alone do not prove the views show one scene: two images of noise give 875 mutual matches of
which 24-30 agree on an identity by chance, more than ``min_inliers``. So the kept model must also
align what the views show (:func:`check_views_alike`): aligned by ``A_glob`` and blurred past small
parallax, the overlaps of every pair in ``shared/data`` correlate by 0.47 or more, noise by 0.0,
unrelated photos that pass RANSAC by -0.2 to 0.6 (``docs/evaluation.md``).

Affines and points follow ``sena_warp.affine``: ``(2, 3)`` float64 matrices named by direction,
float64 ``(N, 2)`` arrays of ``(x, y)`` pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .affine import apply_affine
from .config import Config
from .errors import InputError, MatchError

MODEL_AFFINE = "affine"
MODEL_SIMILARITY = "similarity"
ALIKE_SIDE_PX = 512  # the views are compared at this long side at most ...
ALIKE_SIGMA_PX = 2.0  # ... blurred by this (at that size): parallax and resampling do not count
ALIKE_MIN_STD = 1.0  # an overlap flatter than this (grey levels) has nothing to compare: not checked


@dataclass(frozen=True)
class GlobalAffine:
    """Result of step 1.

    ``affine_src_to_tgt``: ``(2, 3)`` float64 ``A_glob``; ``inliers``: ``(N,)`` bool over the input
    matches; ``model``: ``"affine"`` or ``"similarity"``; ``n_matches``, ``n_inliers``: counts.
    """

    affine_src_to_tgt: np.ndarray
    inliers: np.ndarray
    model: str
    n_matches: int
    n_inliers: int


def _validated_matches(pts_src: np.ndarray, pts_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts_src = np.asarray(pts_src, dtype=np.float64)
    pts_tgt = np.asarray(pts_tgt, dtype=np.float64)
    if pts_src.ndim != 2 or pts_src.shape[1] != 2 or pts_src.shape != pts_tgt.shape:
        raise InputError(
            f"matched points must be two (N, 2) arrays of equal length, got {pts_src.shape} and {pts_tgt.shape}"
        )
    if not (np.isfinite(pts_src).all() and np.isfinite(pts_tgt).all()):
        raise InputError("matched points contain NaN or infinite coordinates")
    return pts_src, pts_tgt


def _ransac(estimator, pts_src: np.ndarray, pts_tgt: np.ndarray, cfg: Config) -> tuple[np.ndarray | None, np.ndarray]:
    """Run one OpenCV RANSAC estimator; returns (affine or None, inlier mask (N,) bool)."""
    affine, mask = estimator(
        pts_src,
        pts_tgt,
        method=cv2.RANSAC,
        ransacReprojThreshold=cfg.ransac_reproj_px,
        maxIters=cfg.ransac_max_iters,
        confidence=cfg.ransac_confidence,
    )
    if affine is None or mask is None:
        return None, np.zeros(len(pts_src), dtype=bool)
    return affine.astype(np.float64), mask.reshape(-1).astype(bool)


def _similarity_kept(affine_sim: np.ndarray, inliers_sim: np.ndarray, affine_full: np.ndarray | None,
                     inliers_full: np.ndarray, pts_src: np.ndarray, pts_tgt: np.ndarray, cfg: Config) -> bool:
    """Whether the similarity is kept over the full affine (module docstring).

    By RANSAC inliers (``global_model_choice`` "inliers", docs/method.md step 1), a tie going to the similarity,
    the more rigid model. By "support", the model with more matches within ``fit_match_px`` wins, and
    where the two are within ``global_model_margin`` of each other (every match near both: a sheared
    view, or a grey copy of an image that flips a near tie) the inliers decide as above.
    """
    if affine_full is None:
        return True
    if cfg.global_model_choice == "support":
        near_sim, near_full = (int(near_model(a, pts_src, pts_tgt, cfg.fit_match_px).sum())
                               for a in (affine_sim, affine_full))
        if abs(near_sim - near_full) > cfg.global_model_margin * max(near_sim, near_full):
            return near_sim > near_full
    return int(inliers_sim.sum()) >= int(inliers_full.sum())


def fit_global_affine(pts_src: np.ndarray, pts_tgt: np.ndarray, cfg: Config) -> GlobalAffine:
    """Fit ``A_glob`` (src -> tgt) to matches with RANSAC, affine vs similarity (docs/method.md step 1).

    ``pts_src``, ``pts_tgt``: float64 ``(N, 2)`` ``(x, y)`` pixel positions of the same matches.
    Raises ``MatchError`` when fewer than ``cfg.min_inliers`` matches or inliers are available.
    """
    pts_src, pts_tgt = _validated_matches(pts_src, pts_tgt)
    n_matches = len(pts_src)
    if n_matches < cfg.min_inliers:
        raise MatchError(
            f"only {n_matches} matches between the images, {cfg.min_inliers} inliers are needed: check that "
            f"the images overlap, or try the other detector (--features sift / xfeat)"
        )
    affine_full, inliers_full = _ransac(cv2.estimateAffine2D, pts_src, pts_tgt, cfg)
    affine_sim, inliers_sim = _ransac(cv2.estimateAffinePartial2D, pts_src, pts_tgt, cfg)
    if affine_sim is not None and _similarity_kept(affine_sim, inliers_sim, affine_full, inliers_full, pts_src,
                                                   pts_tgt, cfg):
        affine, inliers, model = affine_sim, inliers_sim, MODEL_SIMILARITY
    else:
        affine, inliers, model = affine_full, inliers_full, MODEL_AFFINE
    n_inliers = int(inliers.sum())
    if affine is None or n_inliers < cfg.min_inliers:
        raise MatchError(
            f"only {n_inliers} of {n_matches} matches agree on one affine model (RANSAC "
            f"{cfg.ransac_reproj_px} px), {cfg.min_inliers} are needed: check that the images overlap, "
            f"or try the other detector (--features sift / xfeat)"
        )
    return GlobalAffine(
        affine_src_to_tgt=affine,
        inliers=inliers,
        model=model,
        n_matches=n_matches,
        n_inliers=n_inliers,
    )


def near_model(affine_src_to_tgt: np.ndarray, pts_src: np.ndarray, pts_tgt: np.ndarray, max_px: float) -> np.ndarray:
    """(N,) bool: matches whose target point lies within ``max_px`` of where ``affine_src_to_tgt`` puts
    their source point. With ``max_px`` above the RANSAC threshold this keeps the parallax matches
    the local affines are there to follow (step 3), while A_glob itself stays a strict fit."""
    residual = apply_affine(affine_src_to_tgt, pts_src) - np.asarray(pts_tgt, dtype=np.float64)
    return np.hypot(residual[:, 0], residual[:, 1]) <= max_px



def overlap_correlation(img_src: np.ndarray, img_tgt: np.ndarray, affine_src_to_tgt: np.ndarray) -> float | None:
    """Pearson correlation of the grey views where ``affine_src_to_tgt`` lays the source (BGR uint8) over
    the target, both reduced to ``ALIKE_SIDE_PX`` and blurred by ``ALIKE_SIGMA_PX``; None when the overlap
    is too small or flat to say."""
    scale = min(1.0, ALIKE_SIDE_PX / max(*img_src.shape[:2], *img_tgt.shape[:2]))
    grey_src, grey_tgt = (cv2.GaussianBlur(cv2.resize(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), None, fx=scale, fy=scale,
                                                      interpolation=cv2.INTER_AREA).astype(np.float32),
                                           (0, 0), ALIKE_SIGMA_PX) for img in (img_src, img_tgt))
    affine = np.array(affine_src_to_tgt, np.float64)
    affine[:, 2] *= scale  # the same map between the reduced images
    size = grey_tgt.shape[::-1]
    warped = cv2.warpAffine(grey_src, affine, size, flags=cv2.INTER_LINEAR)
    covered = cv2.warpAffine(np.ones_like(grey_src, np.uint8), affine, size, flags=cv2.INTER_NEAREST)
    covered = cv2.erode(covered, np.ones((5, 5), np.uint8)) > 0  # no border pixels blended with black
    seen_src, seen_tgt = warped[covered], grey_tgt[covered]
    if seen_src.size < 100 or min(seen_src.std(), seen_tgt.std()) < ALIKE_MIN_STD:
        return None
    return float(np.corrcoef(seen_src, seen_tgt)[0, 1])


def check_views_alike(img_src: np.ndarray, img_tgt: np.ndarray, glob: GlobalAffine, cfg: Config) -> None:
    """MatchError when the views that ``glob`` aligns do not look alike where they overlap (correlation
    below ``cfg.min_overlap_correlation``): its inliers agree by chance (noise, unrelated pictures)."""
    correlation = overlap_correlation(img_src, img_tgt, glob.affine_src_to_tgt)
    if correlation is not None and correlation < cfg.min_overlap_correlation:
        raise MatchError(
            f"the {glob.n_inliers} matches that agree on one model align views that do not look alike (overlap "
            f"correlation {correlation:.2f}, at least {cfg.min_overlap_correlation:g} needed): check that the "
            f"images overlap, or try the other detector (--features sift / xfeat)"
        )
