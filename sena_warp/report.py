"""What a stitch did, as a JSON-ready dict (``--report``): counts, models, zone, anchors, the
figures of SENA.md "Measuring" and the time per stage."""

from __future__ import annotations

import json
import os

import numpy as np

from .config import Config
from .imageio import atomic_output
from .affine import similarity_deviation
from .metrics import overlap_psnr_ssim
from .partition import anchor_residuals_px, transition_mad
from .rig import image_to_working
from .stitch import Panorama
from .warp_map import remap_image

ROUND = 4


def alignment_figures(pano: Panorama, img_a: np.ndarray, img_b: np.ndarray, cfg: Config) -> dict:
    """Overlap PSNR/SSIM of the step-6 warp and the seam figures of the final maps.

    Computed in the working frame, where the seam runs top to bottom and ``seam_x_canvas`` is per row;
    ``cfg.device`` resolved.
    """
    maps = pano.maps
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    seam = maps.seam
    warped, valid_src = remap_image(img_src, maps.warp.map_src_canvas, cfg)
    placed, valid_tgt = remap_image(img_tgt, seam.maps.map_tgt_canvas, cfg)
    seam_src, valid_seam = remap_image(img_src, seam.maps.map_src_canvas, cfg)
    psnr_db, ssim_val = overlap_psnr_ssim(warped, valid_src, placed, valid_tgt)
    residuals = anchor_residuals_px(maps.warp.map_src_canvas, seam.maps.map_src_canvas,
                                    seam.anchors_src_canvas, seam.anchors_tgt_canvas)
    mad = transition_mad(seam_src, placed, valid_seam & valid_tgt, seam.maps.seam_x_canvas, cfg.transition_px)
    finite = residuals[np.isfinite(residuals)]
    return {
        "overlap_psnr_db": _num(psnr_db),
        "overlap_ssim": _num(ssim_val),
        "anchor_residual_median_px": _num(np.median(finite)) if finite.size else None,
        "anchor_residual_max_px": _num(finite.max()) if finite.size else None,
        "transition_mad_grey": _num(mad),
    }


def image_report(pano: Panorama, img_a: np.ndarray, img_b: np.ndarray, cfg: Config,
                 crop_xywh: tuple[int, int, int, int] | None = None) -> dict:
    """The ``--report`` of ``sena-warp image``."""
    maps = pano.maps
    warp, seam, local = maps.warp, maps.seam, maps.warp.local
    zone = seam.zone
    return {
        "inputs": {"a": _size(img_a), "b": _size(img_b)},
        "rig": {"source": maps.rig.source, "target": maps.rig.target, "vertical": maps.rig.vertical,
                "median_dx_px": _num(maps.rig.median_dx_px), "median_dy_px": _num(maps.rig.median_dy_px)},
        "features": {"keypoints_a": maps.matches.n_keypoints_a, "keypoints_b": maps.matches.n_keypoints_b,
                     "matches": len(maps.matches)},
        "global_affine": {"model": warp.glob.model, "inliers": warp.glob.n_inliers,
                          "matrix_src_to_tgt": _nums(warp.glob.affine_src_to_tgt)},
        "local_affines": {"cells": len(local.conf), "conf": _nums(local.conf), "refit": local.refit.tolist(),
                          "rmse_px": _nums(local.rmse_px),
                          "similarity_deviation": _nums(similarity_deviation(local.affines_src_to_tgt))},
        "canvas": {"width": int(pano.image.shape[1]), "height": int(pano.image.shape[0]),
                   "crop_xywh": list(crop_xywh) if crop_xywh is not None else None},
        "zone": {"x0_canvas": _num(zone.x0), "x1_canvas": _num(zone.x1), "fallback": bool(zone.fallback),
                 "clusters": len(zone.clusters), "points": int(len(zone.point_indices))},
        "anchors": {"count": int(len(seam.anchors_tgt_canvas)),
                    "src_canvas": _nums(seam.anchors_src_canvas), "tgt_canvas": _nums(seam.anchors_tgt_canvas),
                    "frame": "working (transposed for a vertical rig)"},
        "metrics": alignment_figures(pano, img_a, img_b, cfg),
        "seconds": {k: _num(v) for k, v in pano.seconds.items()},
    }


def write_json(path: str | os.PathLike, data: dict) -> None:
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")


def _size(img: np.ndarray) -> dict:
    return {"width": int(img.shape[1]), "height": int(img.shape[0])}


def _num(v) -> float | None:
    v = float(v)
    return round(v, ROUND) if np.isfinite(v) else None


def _nums(a: np.ndarray) -> list:
    return np.round(np.asarray(a, np.float64), ROUND).tolist()
