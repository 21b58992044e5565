"""What moves, left out of the first estimate: a rig's maps must align its still background.

A person close to two fixed cameras can hold more matches than the room behind him, and the global
affine (step 1) then aligns him: the background is shown twice across the overlap, a parallax apart.
Over the first estimate's frame pairs (a second of video) the two are told apart by time. On a fixed
rig a still background's keypoints are found again at the same places, in both views, in pair after
pair; a moving person's are not (he moves by more than a pixel between pairs a quarter of a second
apart). So, per pair:

1. *Recurring matches* (:func:`recurring`): those found again, both ends within
   ``video_recur_px``, in at least two of the other pairs.
2. *The models in turn* (:func:`moving_models`): step 1's fit, then the fit of the matches it left
   out, and so on. A model whose inliers almost never recur (``video_moving_recur``) belongs to
   something that moves; the first model whose inliers recur as a still scene's do
   (``video_still_recur``) is the background. Only where something moving comes first and the
   background follows are the moving models' matches left out (:func:`without_models`). A still
   scene's first model recurs; a moving rig's matches recur nowhere (the whole view moves), and a
   model in between says nothing: the matches are kept as they are.

A keypoint is found again only to about a pixel, and only about half a still scene's are found again
at all (the detector's own noise), hence the two shares far apart.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from ..config import Config
from ..errors import MatchError
from ..features import Matches
from ..global_affine import fit_global_affine, near_model

RECUR_PAIRS = 2  # a match recurs when found again in this many other pairs at least


def recurring(matches: Matches, others: list[Matches], tol_px: float) -> np.ndarray:
    """(N,) bool: the matches of one pair (input pixels, a -> b) found again, both ends within
    ``tol_px``, in at least :data:`RECUR_PAIRS` of the ``others`` (the same rig's other pairs)."""
    found = np.zeros(len(matches), np.int32)
    for other in others:
        if len(other) == 0:
            continue
        near_a = _near(matches.pts_a, other.pts_a, tol_px)
        near_b = _near(matches.pts_b, other.pts_b, tol_px)
        found += (near_a & near_b).any(axis=1)
    return found >= RECUR_PAIRS


def _near(pts: np.ndarray, pts_other: np.ndarray, tol_px: float) -> np.ndarray:
    """(N, M) bool: point i of ``pts`` (N, 2) within ``tol_px`` of point j of ``pts_other`` (M, 2)."""
    delta = pts[:, None, :] - pts_other[None, :, :]
    return np.einsum("nmk,nmk->nm", delta, delta) <= tol_px * tol_px


def models_in_turn(matches: Matches, others: list[Matches], tol_px: float, cfg: Config
                   ) -> Iterator[tuple[np.ndarray, float]]:
    """Step 1's model of ``matches``, then the model of what it left out, and so on (at most
    ``video_moving_models`` + 1, fitted as they are asked for): each model's (2, 3) a -> b affine and
    the share of its inliers that recur in the ``others`` (:func:`recurring`)."""
    again = recurring(matches, others, tol_px)
    left = np.ones(len(matches), bool)
    for _ in range(cfg.video_moving_models + 1):
        try:
            model = fit_global_affine(matches.pts_a[left], matches.pts_b[left], cfg)
        except MatchError:
            return
        inliers = np.flatnonzero(left)[model.inliers]
        yield model.affine_src_to_tgt, float(again[inliers].mean())
        left[inliers] = False


def judged_models(turns: Iterable[tuple[np.ndarray, float]], cfg: Config) -> tuple[list[np.ndarray], bool]:
    """Of a pair's :func:`models_in_turn`: the affines of the models that move and lead the background,
    and whether the background was found after them (or first, with no moving model before it); no
    models where it was not."""
    moving: list[np.ndarray] = []
    for affine, share in turns:
        if share >= cfg.video_still_recur:
            return moving, True
        if share > cfg.video_moving_recur:
            break
        moving.append(affine)
    return [], False


def moving_models(matches: Matches, others: list[Matches], tol_px: float, cfg: Config
                  ) -> tuple[list[np.ndarray], bool]:
    """The (2, 3) a -> b affines of the models (module docstring, 2) in ``matches`` that move and lead
    the background, and whether the background was found (:func:`judged_models`)."""
    return judged_models(models_in_turn(matches, others, tol_px, cfg), cfg)


def without_models(matches: Matches, models: list[np.ndarray], max_px: float) -> Matches:
    """``matches`` less those within ``max_px`` of any of ``models`` ((2, 3) a -> b affines)."""
    keep = np.ones(len(matches), bool)
    for model in models:
        keep &= ~near_model(model, matches.pts_a, matches.pts_b, max_px)
    return Matches(matches.pts_a[keep], matches.pts_b[keep], matches.scores[keep], matches.n_keypoints_a,
                   matches.n_keypoints_b)
