"""Warp alignment of SENA steps 1-6 on one pair: SENA's map against the global affine and a
SIFT + RANSAC homography, in the target frame, with the shape cost of the local warp.

Used by ``benchmarks/eval_warp.py`` (tables, sweeps, timing) and by ``tests/test_warp_quality.py``, so
the tests check the numbers the benchmark reports. Figures: overlap PSNR / SSIM (UDIS-D protocol of
``metrics``) of the source warped onto the target: the canvas maps are cropped to the target rectangle
at the canvas's integer offset (``figures.map_in_target_frame``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.features import match_images
from sena_warp.imageio import read_image
from sena_warp.rig import Rig, detect_rig, image_to_working, matches_to_working
from sena_warp.stitch import StageClock, Warp, estimate_warp

from .baselines import HOMOGRAPHY_RANSAC_PX, affine_map_canvas, homography_to_target
from .figures import in_target_frame, map_in_target_frame
from .metrics import overlap_psnr_ssim

# The sweep's best setting that does not fold the source (docs/evaluation.md, "Warp alignment, steps 1-6"):
# meets the wins and gain targets, not the homography one; kept out of the defaults (see there).
TUNED_SETTING = "ransac_reproj_px=25,grid_x=6,grid_y=6,lambda1=0.005,gamma_min=0.9"


@dataclass(frozen=True)
class PairInputs:
    """One pair in the working frame (source left, vertical rigs transposed), with both match sets.

    ``pts_*`` (N, 2) float64 (x, y) XFeat matches; ``sift_*`` (M, 2) the SIFT matches, same frames.
    """

    name: str
    rig: Rig
    img_src: np.ndarray
    img_tgt: np.ndarray
    pts_src: np.ndarray
    pts_tgt: np.ndarray
    sift_src: np.ndarray
    sift_tgt: np.ndarray


@dataclass(frozen=True)
class PairFigures:
    """Overlap (PSNR dB, SSIM) of the three warps on one pair, and the match counts."""

    name: str
    matches: int
    inliers: int
    sena: tuple[float, float]
    affine: tuple[float, float]
    homography: tuple[float, float]
    stretch: float  # field_stretch of the SENA map: its departure from A_glob's shape
    folded: float  # folded_fraction of the SENA map over the overlap

    @property
    def gain_db(self) -> float:
        return self.sena[0] - self.affine[0]


def load_pair(folder: Path, cfg: Config) -> PairInputs:
    """Read ``folder/a.*`` and ``folder/b.*``, match them (cfg's detector and SIFT) and orient the rig."""
    img_a, img_b = read_image(next(folder.glob("a.*"))), read_image(next(folder.glob("b.*")))
    matches = match_images(img_a, img_b, cfg)
    sift = match_images(img_a, img_b, cfg.replace(features="sift"))
    rig = detect_rig(matches.pts_a, matches.pts_b, img_a.shape)
    img_src, img_tgt = (image_to_working(img, rig) for img in rig.pick(img_a, img_b))
    pts_src, pts_tgt = matches_to_working(matches.pts_a, matches.pts_b, rig)
    sift_src, sift_tgt = matches_to_working(sift.pts_a, sift.pts_b, rig)
    return PairInputs(folder.name, rig, img_src, img_tgt, pts_src, pts_tgt, sift_src, sift_tgt)


def field_stretch(field_canvas: np.ndarray, mask_canvas: np.ndarray) -> float:
    """99th percentile over ``mask_canvas`` of |dD/du| (Frobenius norm, source px per canvas px).

    ``field_canvas`` (H, W, 2): how far M_s leaves A_glob. 0 for a pure affine; the shape cost of the
    local warp (0.1 changes a 10 px segment's length or direction by up to about 1 px).
    """
    if not mask_canvas.any():
        return 0.0
    grads = [np.gradient(field_canvas[:, :, k].astype(np.float64)) for k in range(2)]
    norm = np.sqrt(sum(g * g for pair_of_grads in grads for g in pair_of_grads))
    return float(np.percentile(norm[mask_canvas], 99))


def folded_fraction(map_src_canvas: np.ndarray, mask_canvas: np.ndarray) -> float:
    """Fraction of ``mask_canvas`` where M_s (H, W, 2) folds: det(dM_s/du) <= 0 (source content mirrored)."""
    if not mask_canvas.any():
        return 0.0
    # np.gradient returns (d/drow, d/dcol) = (d/dy, d/dx) of each map component.
    dsx_dy, dsx_dx = np.gradient(map_src_canvas[:, :, 0].astype(np.float64))
    dsy_dy, dsy_dx = np.gradient(map_src_canvas[:, :, 1].astype(np.float64))
    det = dsx_dx * dsy_dy - dsx_dy * dsy_dx
    return float(np.mean(det[mask_canvas] <= 0.0))


def homography_figures(pair: PairInputs) -> tuple[float, float]:
    """Overlap figures of the SIFT + RANSAC (3 px) homography baseline, target frame; nan when it fails."""
    if len(pair.sift_src) < 4:
        return float("nan"), float("nan")
    homography, _ = cv2.findHomography(pair.sift_src, pair.sift_tgt, cv2.RANSAC, HOMOGRAPHY_RANSAC_PX)
    if homography is None:
        return float("nan"), float("nan")
    warped, valid = homography_to_target(pair.img_src, homography, pair.img_tgt.shape)
    return overlap_psnr_ssim(warped, valid, pair.img_tgt, np.ones(valid.shape, bool))


def evaluate_pair(pair: PairInputs, cfg: Config) -> tuple[Warp, PairFigures]:
    """SENA steps 1-6 on one loaded pair and all three warps' overlap figures; ``cfg.device`` resolved."""
    warp = estimate_warp(pair.img_src, pair.img_tgt, pair.pts_src, pair.pts_tgt, cfg, StageClock())
    map_affine = affine_map_canvas(warp, cfg)
    sena, affine = (
        in_target_frame(pair.img_src, map_in_target_frame(map_src, warp, pair.img_tgt.shape), pair.img_tgt, cfg)
        for map_src in (warp.map_src_canvas, map_affine)
    )
    stretch = field_stretch(warp.map_src_canvas - map_affine, warp.overlap.mask_canvas)
    folded = folded_fraction(warp.map_src_canvas, warp.overlap.mask_canvas)
    figures = PairFigures(pair.name, len(pair.pts_src), warp.glob.n_inliers, sena, affine,
                          homography_figures(pair), stretch, folded)
    return warp, figures


def parse_setting(text: str, base: Config) -> Config:
    """``default`` or ``NAME=VALUE[,NAME=VALUE...]`` -> a Config; each VALUE is cast to its field's type."""
    if text == "default":
        return base
    types = {f.name: type(getattr(base, f.name)) for f in dataclasses.fields(base)}
    changes = {}
    for item in text.split(","):
        name, _, value = item.partition("=")
        if name not in types:
            raise InputError(f"unknown Config field {name!r} in {text!r}")
        changes[name] = types[name](value)
    return base.replace(**changes)
