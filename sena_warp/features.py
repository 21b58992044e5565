"""Keypoints, descriptors and matches between two images (docs/method.md step 0).

``cfg.features`` picks the detector: "xfeat" (sparse XFeat on onnxruntime, ``xfeat.py``) matched by
mutual nearest neighbour on cosine similarity, or "sift" (OpenCV) matched with Lowe's ratio test.
Points are float64 ``(N, 2)`` arrays of ``(x, y)`` in pixels of the image their name says.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .config import CHOICES, Config
from .errors import InputError
from .xfeat import detect_xfeat

DETECTORS = CHOICES["features"]


@dataclass(frozen=True)
class Matches:
    """Corresponding points of image a and image b.

    ``pts_a[i]`` in image a matches ``pts_b[i]`` in image b, both float64 ``(x, y)`` pixels;
    ``scores`` float64 (N,), higher is better: cosine similarity (XFeat) or ``1 - d1 / d2`` (SIFT).
    ``n_keypoints_a/b``: keypoints detected in each image before matching.
    """

    pts_a: np.ndarray
    pts_b: np.ndarray
    scores: np.ndarray
    n_keypoints_a: int
    n_keypoints_b: int

    def __len__(self) -> int:
        return len(self.pts_a)


def _check_detector(cfg: Config) -> None:
    if cfg.features not in DETECTORS:
        raise InputError(f"unknown feature detector {cfg.features!r}; choose one of {', '.join(DETECTORS)}")


def detect_sift(img_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV SIFT on a BGR uint8 (H, W, 3) image at native resolution.

    Returns ``pts`` float64 (N, 2) ``(x, y)``, ``desc`` float32 (N, 128), ``scores`` float32 (N,)
    (detector response); N = 0 on a featureless image.
    """
    grey = cv2.cvtColor(img_bgr, cv2.COLOR_BGR2GRAY)
    keypoints, desc = cv2.SIFT_create().detectAndCompute(grey, None)
    if desc is None:
        return np.zeros((0, 2)), np.zeros((0, 128), np.float32), np.zeros(0, np.float32)
    pts = np.array([kp.pt for kp in keypoints], np.float64).reshape(-1, 2)
    scores = np.array([kp.response for kp in keypoints], np.float32)
    return pts, desc.astype(np.float32), scores


def detect(img_bgr: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keypoints of a BGR uint8 (H, W, 3) image with the detector ``cfg.features``.

    Returns ``pts`` float64 (N, 2) ``(x, y)`` input pixels, ``desc`` float32 (N, D) (D = 64 XFeat,
    128 SIFT), ``scores`` float32 (N,).
    """
    _check_detector(cfg)
    if cfg.features == "xfeat":
        return detect_xfeat(img_bgr, cfg)
    return detect_sift(img_bgr)


def match_mutual_nn(desc_a: np.ndarray, desc_b: np.ndarray,
                    min_cossim: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mutual nearest neighbours on cosine similarity of L2-normalised descriptors (N_a, D), (N_b, D).

    Pair (i, j) is kept when j is i's most similar descriptor in b, i is j's in a, and their
    cosine similarity is >= min_cossim. Returns int64 index arrays into a and b and the similarities.
    """
    if len(desc_a) == 0 or len(desc_b) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    cossim = desc_a @ desc_b.T
    best_b = np.argmax(cossim, axis=1)
    idx_a = np.arange(len(desc_a))
    best_sim = cossim[idx_a, best_b]
    # i is j's best in a when it reaches j's column maximum: a max down the columns reads the matrix row
    # by row, where an argmax down them strides across it (2.8 vs 126 ms for 4096 x 4096 on this CPU).
    # Of rows tied at a column's maximum, the first is kept.
    reaches = best_sim == cossim.max(axis=0)[best_b]
    rows = idx_a[reaches]
    keep_rows = rows[np.unique(best_b[rows], return_index=True)[1]]
    mutual = np.zeros(len(desc_a), bool)
    mutual[keep_rows] = True
    keep = mutual & (best_sim >= min_cossim)
    return idx_a[keep], best_b[keep], best_sim[keep].astype(np.float64)


def match_ratio(desc_a: np.ndarray, desc_b: np.ndarray,
                ratio: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lowe's ratio test on L2 distances of descriptors (N_a, D), (N_b, D).

    Pair (i, j) is kept when j is i's nearest descriptor in b and its distance is < ratio x the
    second-nearest one's. Returns int64 indices into a and b and scores ``1 - d1 / d2``.
    """
    if len(desc_a) == 0 or len(desc_b) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(desc_a, desc_b, k=2)
    pairs = np.array([(m.queryIdx, m.trainIdx, m.distance, n.distance) for m, n in knn], np.float64)
    dist_ratio = pairs[:, 2] / np.maximum(pairs[:, 3], np.finfo(np.float64).tiny)
    keep = pairs[:, 2] < ratio * pairs[:, 3]
    return pairs[keep, 0].astype(np.int64), pairs[keep, 1].astype(np.int64), 1.0 - dist_ratio[keep]


def match_descriptors(desc_a: np.ndarray, desc_b: np.ndarray,
                      cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Match descriptors the way ``cfg.features`` needs: (idx_a, idx_b, scores), higher score better."""
    _check_detector(cfg)
    if cfg.features == "xfeat":
        return match_mutual_nn(desc_a, desc_b, cfg.min_cossim)
    return match_ratio(desc_a, desc_b, cfg.sift_ratio)


def drop_transparent(found: tuple[np.ndarray, np.ndarray, np.ndarray], transparent: np.ndarray | None,
                     margin_px: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The keypoints of ``detect`` (pts, desc, scores) that lie at least ``margin_px`` from every pixel
    of ``transparent`` ((H, W) bool, True = not content; None keeps them all)."""
    if transparent is None:
        return found
    side = 2 * margin_px + 1
    near = cv2.dilate(transparent.astype(np.uint8), np.ones((side, side), np.uint8)) > 0
    pts = found[0]
    cols = np.clip(np.round(pts[:, 0]).astype(np.int64), 0, near.shape[1] - 1)
    rows = np.clip(np.round(pts[:, 1]).astype(np.int64), 0, near.shape[0] - 1)
    keep = ~near[rows, cols]
    return tuple(a[keep] for a in found)


def match_images(img_a: np.ndarray, img_b: np.ndarray, cfg: Config,
                 transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> Matches:
    """Detect keypoints in two BGR uint8 images and match them (docs/method.md step 0).

    The images may differ in size. ``transparent``: per image, (H, W) bool masks of pixels that are
    not content (alpha 0) or None; no keypoint is kept there (see :func:`drop_transparent`). An
    image without keypoints gives an empty ``Matches``.
    """
    pts_a, desc_a, _ = drop_transparent(detect(img_a, cfg), transparent[0], cfg.alpha_margin_px)
    pts_b, desc_b, _ = drop_transparent(detect(img_b, cfg), transparent[1], cfg.alpha_margin_px)
    idx_a, idx_b, scores = match_descriptors(desc_a, desc_b, cfg)
    return Matches(pts_a=pts_a[idx_a], pts_b=pts_b[idx_b], scores=scores,
                   n_keypoints_a=len(pts_a), n_keypoints_b=len(pts_b))


def neighbour_supported(pts_src: np.ndarray, pts_tgt: np.ndarray, neighbours: int, tol_px: float,
                        min_support: int) -> np.ndarray:
    """(N,) bool: matches whose displacement ``pts_tgt - pts_src`` is shared, within ``tol_px``, by at
    least ``min_support`` of their ``neighbours`` nearest matches (by target position).

    A wrong match on a periodic pattern (tiles, windows, fence rails) is displaced by a whole period
    from its correct neighbours and finds no support; a true match on something at another depth, or
    on something that moved, has neighbours on the same object that move with it.
    """
    pts_src = np.asarray(pts_src, np.float32).reshape(-1, 2)
    pts_tgt = np.asarray(pts_tgt, np.float32).reshape(-1, 2)
    if len(pts_tgt) <= min_support:
        return np.zeros(len(pts_tgt), bool)
    k = min(neighbours + 1, len(pts_tgt))
    nearest = cv2.BFMatcher(cv2.NORM_L2).knnMatch(pts_tgt, pts_tgt, k=k)
    index = np.array([[m.trainIdx for m in row] + [row[-1].trainIdx] * (k - len(row)) for row in nearest])
    displacement = pts_tgt - pts_src
    agree = np.linalg.norm(displacement[index] - displacement[:, None, :], axis=2) <= tol_px
    return agree.sum(axis=1) - 1 >= min_support  # the point itself is among its nearest
