"""The figures of a finished SENA stitch (``docs/evaluation.md``), one definition each.

``sena-warp eval`` records them per pair, the benchmarks print them, and the CLI's ``image --report``
adds them to the report: all three call the functions here. Seam figures are measured in the working
frame (source left, vertical rigs transposed), where the seam runs top to bottom; overlap PSNR / SSIM
in the target frame (the UDIS-D protocol: the warped source against the target).
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.composite import FrameState, composite_image, composite_plan
from sena_warp.gains import compensated, compensated_views
from sena_warp.rig import image_to_working, matches_to_working
from sena_warp.stitch import Panorama, Warp
from sena_warp.switch_align import shown_labels, switch_pixels
from sena_warp.warp_map import CanvasViews, canvas_views, forward_points, remap_image
from sena_warp.zone import overlap_x_extent

from . import dense, naturalness

from .metrics import (Forward, anchor_residuals_px, forward_anisotropy, line_bend_pct, long_segments,
                      overlap_psnr_ssim, transition_mad)

SHAPE_GRID = 12  # points per side of the grid over each view where the anisotropy is measured


def map_in_target_frame(map_src_canvas: np.ndarray, warp: Warp, shape_tgt: tuple[int, ...]) -> np.ndarray:
    """The part of a working-canvas map (H, W, 2) over the target rectangle: (h_tgt, w_tgt, 2), same dtype.

    The canvas offset is integer (``plan_overlap``) and the canvas contains the target rectangle.
    """
    ox, oy = (int(round(v)) for v in warp.overlap.canvas.offset_tgt)
    height, width = shape_tgt[:2]
    return np.ascontiguousarray(map_src_canvas[oy:oy + height, ox:ox + width])


def in_target_frame(img_src: np.ndarray, map_src_tgt: np.ndarray, img_tgt: np.ndarray, cfg: Config
                    ) -> tuple[float, float]:
    """Overlap (PSNR dB, SSIM) of ``img_src`` warped by a target-frame (x, y) map against ``img_tgt``.

    ``cfg.device`` resolved (``runtime.resolve_config``).
    """
    warped, valid = remap_image(img_src, map_src_tgt, cfg)
    return overlap_psnr_ssim(warped, valid, img_tgt, np.ones(valid.shape, bool))


def overlap_figures(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config) -> tuple[float, float]:
    """Overlap (PSNR dB, SSIM) of SENA's step-6 warp of a finished stitch of (img_a, img_b), target frame."""
    maps = pano.maps
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    return in_target_frame(img_src, map_in_target_frame(maps.warp.map_src_canvas, maps.warp, img_tgt.shape),
                           img_tgt, cfg)


def seam_figures(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config) -> dict:
    """SENA's seam figures of a finished stitch of (img_a, img_b), in the working frame on the canvas.

    ``anchors``: step-8 anchors (edge extensions included); ``anchor_residual_px`` /
    ``anchor_residual_max_px``: median / largest over them of where the warped-source anchor lands
    after step 9 vs its target anchor (``anchor_residuals_px``; NaN when none can be located);
    ``seam_mad``: mean |src - tgt| (grey levels) of the seam-corrected source and the placed target
    where both are valid within T/2 of the seam (T = ``transition_px``: where the alpha blends);
    ``feather_mad``: the same for the step-6 source over the overlap's whole x-extent, the band a
    plain linear feather across the overlap would blend in. Both views with their gains, as the
    panorama shows them. ``cfg.device`` resolved.
    """
    maps = pano.maps
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    warp, seam = maps.warp, maps.seam
    gains = seam.gains
    img_src = compensated(img_src, gains.gain_src, gains.bias_src, gains.knee_grey, gains.knee_peak)
    img_tgt = compensated(img_tgt, gains.gain_tgt, gains.bias_tgt, gains.knee_grey, gains.knee_peak)
    placed_tgt, valid_tgt = remap_image(img_tgt, seam.maps.map_tgt_canvas, cfg)
    seam_src, valid_seam_src = remap_image(img_src, seam.maps.map_src_canvas, cfg)
    seam_mad = transition_mad(seam_src, placed_tgt, valid_seam_src & valid_tgt, seam.maps.seam_x_canvas,
                              cfg.transition_px)
    del seam_src, valid_seam_src  # one canvas image fewer alive at a time (a large pair's peak memory)
    step6_src, valid_step6_src = remap_image(img_src, warp.map_src_canvas, cfg)
    residuals = anchor_residuals_px(seam.map_cut_canvas, seam.maps.map_src_canvas,
                                    seam.anchors_src_canvas, seam.anchors_tgt_canvas)
    finite = residuals[np.isfinite(residuals)]
    return {
        "anchors": int(len(seam.anchors_tgt_canvas)),
        "anchor_residual_px": float(np.median(finite)) if finite.size else math.nan,
        "anchor_residual_max_px": float(finite.max()) if finite.size else math.nan,
        "seam_mad": seam_mad,
        "feather_mad": feather_mad(step6_src, valid_step6_src, placed_tgt, valid_tgt, warp.overlap.mask_canvas),
    }


def feather_mad(warped_src: np.ndarray, valid_src: np.ndarray, placed_tgt: np.ndarray, valid_tgt: np.ndarray,
                overlap_mask_canvas: np.ndarray) -> float:
    """Mean |src - tgt| over the blending region of a linear feather across the overlap's x-extent.

    warped_src, placed_tgt: (H, W, C) uint8 canvas images; valid_*: (H, W) bool; overlap_mask_canvas:
    (H, W) bool step-2 overlap. The feather's alpha ramps from 1 to 0 over [x0, x1) of the overlap,
    so its band is that whole extent: ``transition_mad`` with the seam at its middle and width x1 - x0.
    """
    x0, x1 = overlap_x_extent(overlap_mask_canvas)
    seam_x = np.full(valid_src.shape[0], 0.5 * (x0 + x1 - 1))
    return transition_mad(warped_src, placed_tgt, valid_src & valid_tgt, seam_x, x1 - x0)


def shape_figures(views: list[tuple[np.ndarray, Forward]]) -> dict:
    """Shape figures over the views (image, forward map into the method's output) of one panorama."""
    anisotropy, bends = [], []
    for img, forward in views:
        height, width = img.shape[:2]
        grid = np.stack(np.meshgrid(np.linspace(2, width - 3, SHAPE_GRID), np.linspace(2, height - 3, SHAPE_GRID)),
                        axis=-1).reshape(-1, 2)
        anisotropy.append(forward_anisotropy(forward, grid))
        bends.append(line_bend_pct(forward, long_segments(img)))
    anisotropy, bends = np.concatenate(anisotropy), np.concatenate(bends)
    anisotropy, bends = anisotropy[np.isfinite(anisotropy)], bends[np.isfinite(bends)]
    return {"anisotropy": float(anisotropy.mean()) if anisotropy.size else math.nan,
            "line_bend_mean_pct": float(bends.mean()) if bends.size else math.nan,
            "line_bend_max_pct": float(bends.max()) if bends.size else math.nan, "lines": int(bends.size)}


def identity(pts: np.ndarray) -> np.ndarray:
    """The forward map of a view pasted unwarped (SENA's and the global models' target)."""
    return np.asarray(pts, np.float64)


def panorama_views(img_src: np.ndarray, img_tgt: np.ndarray, pano: Panorama, cfg: Config) -> CanvasViews:
    """Both working-frame views on the canvas as the panorama samples them (before their gains): the
    source by the seam maps, the target at its offset, each valid only where its seam map samples it
    (a thin strip left out is not shown)."""
    maps = pano.maps.seam.maps
    views = canvas_views(img_src, img_tgt, maps.map_src_canvas, pano.maps.warp.overlap.canvas, cfg)
    return replace(views, valid_tgt=views.valid_tgt & np.isfinite(maps.map_tgt_canvas[..., 0]))


def natural_figures(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config) -> dict:
    """The natural-appearance figures of a finished stitch (``naturalness``), in the working frame on the canvas.

    ``copies``: reliable matches whose target copy is in the overlap; ``dup_lost_pct``: of them, %
    duplicated or lost (copies > 2 px apart); ``dup_lost_over_4px`` how many by more than 4 px,
    ``dup_lost_worst_px`` the worst; ``seam_step``, ``border_step``: grey levels; ``visible_bend_max_pct``: largest bend
    of a segment its own view shows whole; ``continuity_px``: median offset of the segments the seam
    cuts, ``cut_lines`` how many. ``cfg.device`` resolved.
    """
    maps = pano.maps
    warp, seam = maps.warp, maps.seam
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    canvas = warp.overlap.canvas
    views = compensated_views(panorama_views(img_src, img_tgt, pano, cfg), seam.gains)
    weight_src, weight_tgt = naturalness.view_weights(seam.maps.alpha_canvas, views.valid_src, views.valid_tgt)

    def forward(pts: np.ndarray) -> np.ndarray:
        return forward_points(seam.maps.map_src_canvas, warp.glob.affine_src_to_tgt, canvas, pts, cfg)

    pts_src, pts_tgt = matches_to_working(maps.matches.pts_a, maps.matches.pts_b, maps.rig)
    reliable = naturalness.reliable_matches(pts_src, pts_tgt, warp.glob.affine_src_to_tgt)
    copies = naturalness.copy_figures(forward(pts_src[reliable]), canvas.tgt_to_canvas(pts_tgt[reliable]),
                                      weight_src, weight_tgt, views.both)
    grey = lambda img: cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32)  # noqa: E731
    pano_working = image_to_working(pano.image, maps.rig)[:, :, :3]
    step = naturalness.seam_step(grey(pano_working), grey(views.src), grey(views.tgt), views.valid_src, views.valid_tgt,
                                 seam.maps.seam_x_canvas)
    border = naturalness.border_step(grey(pano_working), grey(views.src), views.valid_src, weight_tgt, seam.border.lines)
    bends, continuity = naturalness.line_figures(naturalness.line_segments(img_src), forward, weight_src,
                                                 naturalness.line_segments(img_tgt), canvas.tgt_to_canvas, weight_tgt)
    return {
        "copies": copies.points,
        "dup_lost_pct": copies.share_pct,
        "dup_lost_over_4px": copies.over_strict,
        "dup_lost_worst_px": copies.worst_px,
        "seam_step": step,
        "border_step": border,
        "visible_bend_max_pct": float(bends.max()) if bends.size else math.nan,
        "continuity_px": float(np.median(continuity)) if continuity.size else math.nan,
        "cut_lines": int(continuity.size),
    }


def dense_figures(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config) -> dict:
    """Issue 35's dense figures of a finished stitch (``dense``), in the working frame on the canvas.

    ``seam_misalign_*_px``, ``border_misalign_*_px``: median and 95th percentile of the flow between the
    views as the panorama shows them, at the seam's textured band and at the borders' (NaN: no such
    pixel); ``doubled_pct``, ``lost_pct``: of the consistent textured overlap pixels, those shown twice
    or nowhere; ``dup_objects``, ``dup_object_px``: such regions of at least ``dense.OBJECT_MIN_PX``
    pixels, the largest; ``tone_spread_pct``, ``tone_colour_pct``: tone fidelity of the panorama
    against the views as the same compositor shows them (:func:`rendered`), ``*_plain_pct`` of the plain
    panorama (each view times its gains, nothing else); ``white_cast_grey`` and
    ``white_cast_plain_grey`` likewise. ``cfg.device`` resolved.
    """
    maps = pano.maps
    seam = maps.seam
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    raw = panorama_views(img_src, img_tgt, pano, cfg)
    views = compensated_views(raw, seam.gains)
    weight_src, weight_tgt = naturalness.view_weights(seam.maps.alpha_canvas, views.valid_src, views.valid_tgt)
    seam_px, border_px = switch_pixels(shown_labels(weight_src, weight_tgt), views.valid_src, views.valid_tgt)
    src8, tgt8, flow, flow_back = dense.flows(*views.grey(), views.valid_src, views.valid_tgt)
    texture_ok, across, ratio = dense.structure(src8, tgt8)
    shift = dense.visible_shift(flow, across, ratio)
    at_seam, at_border = dense.misalignment(shift, seam_px, border_px, views.both, texture_ok, seam.maps.seam_x_canvas,
                                            cfg.transition_px)
    shown = dense.copies(flow, flow_back, shift, weight_src, weight_tgt, views.both, texture_ok)
    pures = (weight_src >= dense.PURE_WEIGHT, weight_tgt >= dense.PURE_WEIGHT)
    view, plain = (rendered(img_a, img_b, pano, cfg, with_gains) for with_gains in (False, True))
    pano_working = image_to_working(pano.image, maps.rig)[:, :, :3]
    spread, colour = dense.tone_figures(pano_working, (view, view), pures)
    spread_plain, colour_plain = dense.tone_figures(plain, (view, view), pures)
    return {
        "seam_misalign_median_px": at_seam.median_px,
        "seam_misalign_p95_px": at_seam.p95_px,
        "border_misalign_median_px": at_border.median_px,
        "border_misalign_p95_px": at_border.p95_px,
        "doubled_pct": shown.doubled_pct,
        "lost_pct": shown.lost_pct,
        "dup_objects": shown.objects,
        "dup_object_px": shown.largest_px,
        "tone_spread_pct": spread,
        "tone_spread_plain_pct": spread_plain,
        "tone_colour_pct": colour,
        "tone_colour_plain_pct": colour_plain,
        "white_cast_grey": dense.white_cast(pano_working, view, pures[0] | pures[1]),
        "white_cast_plain_grey": dense.white_cast(plain, view, pures[0] | pures[1]),
    }


def rendered(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config, with_gains: bool) -> np.ndarray:
    """(H, W, 3) uint8 working-canvas panorama of a finished stitch composited again with no seam blend:
    each view as it is (``with_gains`` False) or times its gains alone (the plain panorama). The same
    compositor and sampling as the panorama's, so that comparing them sees tones, not resampling."""
    maps = pano.maps
    img_src, img_tgt = maps.rig.pick(img_a, img_b)
    plan = composite_plan(maps.map_src_input, maps.map_tgt_input, maps.seam_input, (img_src.shape, img_tgt.shape), cfg)
    gains = maps.seam.gains
    channels = len(gains.gain_src)
    ones, zeros = np.ones(channels), np.zeros(channels)
    values = (gains.gain_src, gains.bias_src, gains.gain_tgt, gains.bias_tgt) if with_gains else (ones, zeros, ones, zeros)
    image = composite_image(img_src, img_tgt, plan, FrameState(maps.seam_input.positions, values), cfg)
    return image_to_working(image, maps.rig)


def report_figures(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config) -> dict:
    """The ``metrics`` of ``sena-warp image --report``: :func:`overlap_figures` and :func:`seam_figures`."""
    psnr_db, ssim = overlap_figures(img_a, img_b, pano, cfg)
    seam = seam_figures(img_a, img_b, pano, cfg)
    return {
        "overlap_psnr_db": psnr_db,
        "overlap_ssim": ssim,
        "anchor_residual_median_px": seam["anchor_residual_px"],
        "anchor_residual_max_px": seam["anchor_residual_max_px"],
        "transition_mad_grey": seam["seam_mad"],
    }
