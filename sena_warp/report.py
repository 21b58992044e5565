"""What a stitch did, as a JSON-ready dict (``--report``): the run (tool, device, settings), counts,
models, zone, anchors, the quality figures (``docs/evaluation.md``) and the time per stage. Every key is
explained in ``docs/report.md``.

The pipeline does not measure itself: the figures are computed by the caller (the CLI, with
``sena_warp.evaluation.figures.report_figures``) and only formatted here."""

from __future__ import annotations

import json
import os

import numpy as np

from . import __version__
from .affine import similarity_deviation
from .config import Config
from .config_file import non_default
from .outputs import OutputPlan, atomic_output
from .stitch import Panorama

ROUND = 4


def run_info(cfg: Config) -> dict:
    """Which tool ran, where, and with which settings: the report's ``run`` block (``cfg.device`` resolved)."""
    settings = non_default(cfg)
    settings.pop("device", None)  # reported on its own, resolved
    return {"tool": "sena-warp", "version": __version__, "device": cfg.device, "detector": cfg.features,
            "threads": cfg.cpu_threads, "settings": settings}


def image_report(pano: Panorama, img_a: np.ndarray, img_b: np.ndarray, metrics: dict[str, float], cfg: Config,
                 crop_xywh: tuple[int, int, int, int] | None = None) -> dict:
    """The ``--report`` of ``sena-warp image``; ``metrics``: name -> figure (NaN: not measurable);
    ``cfg``: the stitch's, device resolved."""
    maps = pano.maps
    warp, seam = maps.warp, maps.seam
    zone = seam.zone
    return {
        "run": run_info(cfg),
        "inputs": {"a": _size(img_a), "b": _size(img_b)},
        "rig": {"source": maps.rig.source, "target": maps.rig.target, "vertical": maps.rig.vertical,
                "median_dx_px": _num(maps.rig.median_dx_px), "median_dy_px": _num(maps.rig.median_dy_px),
                "shift_x_px": _num(maps.rig.shift_x_px), "shift_y_px": _num(maps.rig.shift_y_px)},
        "features": {"keypoints_a": maps.matches.n_keypoints_a, "keypoints_b": maps.matches.n_keypoints_b,
                     "matches": len(maps.matches)},
        "global_affine": {"model": warp.glob.model, "inliers": warp.glob.n_inliers,
                          "matrix_src_to_tgt": _nums(warp.glob.affine_src_to_tgt)},
        "warp": warp_figures(warp),
        "canvas": {"width": int(pano.image.shape[1]), "height": int(pano.image.shape[0]),
                   "crop_xywh": list(crop_xywh) if crop_xywh is not None else None},
        "zone": {"x0_canvas": _num(zone.x0), "x1_canvas": _num(zone.x1), "fallback": bool(zone.fallback),
                 "clusters": len(zone.clusters), "points": int(len(zone.point_indices))},
        "gains": {"model": seam.gains.model, "source": _nums(seam.gains.gain_src),
                  "target": _nums(seam.gains.gain_tgt), "pixels": seam.gains.pixels},
        "anchors": {"count": int(len(seam.anchors_tgt_canvas)),
                    "src_canvas": _nums(seam.anchors_src_canvas), "tgt_canvas": _nums(seam.anchors_tgt_canvas),
                    "frame": "working (transposed for a vertical rig)"},
        "metrics": {name: _num(value) for name, value in metrics.items()},
        "timing_s": {**{k: _num(v) for k, v in pano.seconds.items()}, "total": _num(sum(pano.seconds.values()))},
    }


def warp_figures(warp) -> dict:
    """Step 3-5 figures of the warp's model: the fitted lattice (``ffd_model="fit"``) or the paper's
    local affines (``"blend"``), and whether a gate damped it."""
    figures: dict = {"ffd_model": "fit" if warp.fit is not None else "blend", "gate": warp.gate_canvas is not None,
                     "lattice_nodes": list(warp.lattice.shape[:2])}
    if warp.fit is not None:
        used = warp.fit.weights > 0
        figures.update(matches_used=int(warp.fit.used.sum()), matches_kept=int(used.sum()),
                       residual_median_px=_num(np.median(warp.fit.residual_px[used])) if used.any() else None)
    if warp.local is not None:
        local = warp.local
        figures.update(cells=len(local.conf), conf=_nums(local.conf), refit=local.refit.tolist(),
                       rmse_px=_nums(local.rmse_px), similarity_deviation=_nums(similarity_deviation(local.affines_src_to_tgt)))
    return figures


def write_json(path: str | os.PathLike, data: dict, plan: OutputPlan | None = None) -> None:
    """``data`` as indented JSON, atomically (with ``plan``: committed with its other outputs)."""
    with atomic_output(path, plan=plan) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")


def _size(img: np.ndarray) -> dict:
    return {"width": int(img.shape[1]), "height": int(img.shape[0])}


def _num(v) -> float | None:
    v = float(v)
    return round(v, ROUND) if np.isfinite(v) else None


def _nums(a: np.ndarray) -> list:
    return np.round(np.asarray(a, np.float64), ROUND).tolist()
