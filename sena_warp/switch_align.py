"""Step 9, ours: the source aligned to the target wherever the panorama switches from one to the other.

The step-6 warp aligns the overlap as a whole; where the seam crosses a near plane (paving, a kerb,
a lane line) or beyond the seam's ends, where the canvas switches from the target to the source
along the target's border (or from the source to the target along the warped source's own edge),
what is left of the parallax shows as a step in every line the switch crosses. The
anchors of step 9 correct the seam at keypoints only, and nothing corrects the borders.

Here the views are compared densely at every *switch* of a finished stitch (the pixels next to one
showing the other view: ``switch_pixels``): the optical flow from the target to the step-6 source
(DIS, OpenCV) in a band around them, kept where both views are textured and the flow back returns
to where it started; smoothed along the switches (a normalised Gaussian, ``cfg.switch_sigma_px``);
carried from the switches to the canvas around them by a harmonic extension (smooth between two
switches that disagree, never beyond them); fading to 0 (smootherstep) over ``cfg.switch_fade_px``
from the switches, or further where the correction is large (at most ``cfg.switch_max_slope`` px of
correction per px), and kept well below a fold everywhere (``FOLD_SLOPE``). The source map is
resampled by that field (``M_a(u) = M_s(u + C(u))``,
Warp kernel ``kernels/seam.py``'s ``displaced_map_kernel``): where the seam and the borders run, the
source now shows what the target shows, and far from them it keeps its step-6 shape. Steps 7-9
then run again on the aligned source, so the seam also chooses where the views agree after the
alignment (seam-guided local alignment, as Lin et al. ECCV 2016 iterate it).

A flow larger than ``cfg.switch_max_px`` is not followed: parallax that large is an occlusion or
a depth jump that a local warp would fold, which the seam must avoid instead.
"""

from __future__ import annotations

import cv2
import numpy as np
import warp as wp

from sena_warp.config import Config
from sena_warp.kernels import runtime, transfer
from sena_warp.kernels.seam import displaced_map_kernel

CONSISTENT_PX = 1.5  # the flow is followed where the flow back returns within this
EDGE_MARGIN_PX = 9  # ... at least half this far inside both views (DIS's patches are 8 px)
EDGE_GREY_PER_PX = 4.0  # ... and both views are textured: each view's gradient energy (7x7) at least this
TENSOR_BOX_PX = 7  # the structure tensor's window
MIN_SUPPORT, FULL_SUPPORT = 0.02, 0.08  # a switch's correction counts in full where this share of the flow
# near it (Gaussian-weighted) is followed, and not at all below MIN_SUPPORT
SPREAD_FULL_PX, SPREAD_NONE_PX = 1.0, 4.0  # ... and where the followed flow near it agrees within this (std):
# two depths, or wrong matches among right ones, leave the switch as it is
FIELD_SIGMA_PX = 3.0  # the carried field is blurred by this: no tear where two switches' reaches meet
KNOWN_SUPPORT = 0.2  # carried_out: a coarse cell is known in full where this share of it is trusted switch cells
HARMONIC_ROUNDS = 24  # carried_out: Jacobi rounds per pyramid level
FOLD_SLOPE = 0.5  # the field is scaled down where it changes by more than this per px (far from a fold at 1)
SLOPE_ROUNDS = 4  # slope_limited: rounds of scaling the field down where it is steep


def seam_side_alpha(seam_x_canvas: np.ndarray, width: int) -> np.ndarray:
    """(H, W) float32: 1 left of the seam and on it (x <= seam x), 0 right of it: the side of the seam
    each pixel takes, as the seam maps' alpha gives it (at least 0.5 on the source's side), without
    step 9. seam_x_canvas: (H,) the seam's x per canvas row."""
    cols = np.arange(width, dtype=np.float32)[None, :]
    return (cols <= np.asarray(seam_x_canvas, np.float32)[:, None]).astype(np.float32)


def view_weights(alpha_canvas: np.ndarray, valid_src: np.ndarray, valid_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(weight of the source, weight of the target) per canvas pixel, float32 (H, W): what each view
    contributes to the panorama, given the source alpha and where each view is defined."""
    alpha = np.where(valid_src, np.where(valid_tgt, alpha_canvas, 1.0), 0.0).astype(np.float32)
    return alpha, np.where(valid_tgt, 1.0 - alpha, 0.0).astype(np.float32)


def shown_labels(weight_src: np.ndarray, weight_tgt: np.ndarray) -> np.ndarray:
    """(H, W) uint8: 1 where the panorama shows the source (its weight at least 0.5), 2 the target, 0 neither."""
    return np.where(weight_src >= 0.5, 1, np.where(weight_tgt > 0.5, 2, 0)).astype(np.uint8)


def switch_pixels(label: np.ndarray, valid_src: np.ndarray, valid_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(seam, border): (H, W) bool pixels next to (4-neighbour) one showing the other view (``label``
    of :func:`shown_labels`), split by whether both views are defined at both pixels (a seam: the
    stitch chose to switch there) or not (a border: a view ends there)."""
    both = valid_src & valid_tgt
    seam, border = np.zeros(label.shape, bool), np.zeros(label.shape, bool)
    height, width = label.shape
    for dy, dx in ((0, 1), (1, 0)):
        here = (slice(0, height - dy), slice(0, width - dx))
        there = (slice(dy, height), slice(dx, width))
        switch = (label[here] != label[there]) & (label[here] > 0) & (label[there] > 0)
        chosen = switch & both[here] & both[there]
        for part in (here, there):
            seam[part] |= chosen
            border[part] |= switch & ~chosen
    return seam, border


def extended(grey: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W) uint8: ``grey`` where valid, elsewhere its nearest valid pixel (0 where none is): a line
    that crosses the view's edge goes on as a streak, so a flow across the edge is not pulled to 0."""
    out = np.clip(np.rint(np.nan_to_num(grey)), 0, 255).astype(np.uint8)
    if valid.all() or not valid.any():
        return out
    _, nearest = cv2.distanceTransformWithLabels((~valid).astype(np.uint8), cv2.DIST_L2, 5,
                                                 labelType=cv2.DIST_LABEL_PIXEL)
    ys, xs = np.nonzero(valid)
    lookup = np.zeros(int(nearest.max()) + 1, np.int64)
    lookup[nearest[ys, xs]] = ys * grey.shape[1] + xs
    return out.ravel()[lookup[nearest]].reshape(grey.shape)


def bounding_box(mask: np.ndarray, margin: int) -> tuple[slice, slice] | None:
    """The bounding box of ``mask`` (H, W) bool widened by ``margin``, clipped to it; None where it is empty."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not rows.size:
        return None
    return (slice(max(rows[0] - margin, 0), min(rows[-1] + margin + 1, mask.shape[0])),
            slice(max(cols[0] - margin, 0), min(cols[-1] + margin + 1, mask.shape[1])))


def view_flow(src8: np.ndarray, tgt8: np.ndarray, box: tuple[slice, slice] | None, preset: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """(flow target -> source, flow source -> target): (H, W, 2) float32 (dx, dy) canvas px: the target's
    content at p is in the source at p + flow(p). DIS optical flow (``cv2.DISOPTICAL_FLOW_PRESET_*``
    ``preset``) on the canvas box ``box`` (0 outside it; None: nowhere). src8, tgt8: (H, W) uint8 grey
    views, each continued past its own edge (:func:`extended`)."""
    height, width = src8.shape
    forward, backward = np.zeros((height, width, 2), np.float32), np.zeros((height, width, 2), np.float32)
    if box is None:
        return forward, backward
    src8, tgt8 = np.ascontiguousarray(src8[box]), np.ascontiguousarray(tgt8[box])
    dis = cv2.DISOpticalFlow_create(preset)
    forward[box] = dis.calc(tgt8, src8, None)
    backward[box] = dis.calc(src8, tgt8, None)
    return forward, backward


def edge_strength(grey: np.ndarray) -> np.ndarray:
    """(H, W) float32: the square root of the larger eigenvalue of the structure tensor (Sobel gradients in
    grey levels per px, summed over ``TENSOR_BOX_PX`` square) of a grey view continued past its edge
    (:func:`extended`): how strong an edge or corner is there."""
    grey = grey.astype(np.float32)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    box = (TENSOR_BOX_PX, TENSOR_BOX_PX)
    jxx, jyy, jxy = (cv2.blur(v, box) for v in (gx * gx, gy * gy, gx * gy))
    return np.sqrt(0.5 * (jxx + jyy) + np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy**2))


def consistent(flow: np.ndarray, flow_back: np.ndarray, tol_px: float) -> np.ndarray:
    """(H, W) bool: pixels p whose flow back from p + flow(p) returns within ``tol_px`` of p (on the canvas)."""
    height, width = flow.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    map_x, map_y = xs + flow[..., 0], ys + flow[..., 1]
    back = cv2.remap(flow_back, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    return np.hypot(*(flow + back).transpose(2, 0, 1)) <= tol_px


def switch_correction(flow: np.ndarray, followed: np.ndarray, switches: np.ndarray, cfg: Config) -> np.ndarray:
    """(H, W, 2) float32 canvas px: the correction field C of the module docstring.

    flow: (H, W, 2) target -> source; followed: (H, W) bool where the flow is trusted; switches: (H,
    W) bool switch pixels. Worked out on cells of ``cfg.switch_cell_px`` (the field is smooth) and
    upsampled bilinearly: at each switch cell, the normalised Gaussian average (``cfg.switch_sigma_px``)
    of the followed flow, trusted in part where little of it is near (``MIN_SUPPORT``, ``FULL_SUPPORT``)
    or where it disagrees with itself (``SPREAD_FULL_PX``, ``SPREAD_NONE_PX``); carried to every cell
    from the switch cells near it, as far as they are trusted (:func:`carried_out`), weighted by
    1 - smootherstep(distance to a trusted switch cell / L), L = max(
    ``cfg.switch_fade_px``, 1.875 |C| / ``cfg.switch_max_slope``) (smootherstep's steepest slope is
    1.875 / L), blurred by ``FIELD_SIGMA_PX`` and kept from changing faster than ``FOLD_SLOPE`` anywhere
    (:func:`slope_limited`: where two switches want very different corrections close together).
    """
    height, width = switches.shape
    if not switches.any() or not followed.any():
        return np.zeros((height, width, 2), np.float32)
    cell = max(1, int(cfg.switch_cell_px))
    small = (max(1, -(-width // cell)), max(1, -(-height // cell)))
    weight = cv2.resize(followed.astype(np.float32), small, interpolation=cv2.INTER_AREA)
    weighted = cv2.resize(flow * followed[..., None], small, interpolation=cv2.INTER_AREA)
    on_switch = cv2.resize(switches.astype(np.float32), small, interpolation=cv2.INTER_AREA) > 0
    squared = cv2.resize((flow * flow).sum(axis=2) * followed, small, interpolation=cv2.INTER_AREA)
    sigma = cfg.switch_sigma_px / cell
    support = cv2.GaussianBlur(weight, (0, 0), sigma)
    smooth = cv2.GaussianBlur(weighted, (0, 0), sigma) / np.maximum(support, 1e-6)[..., None]
    spread = np.sqrt(np.maximum(cv2.GaussianBlur(squared, (0, 0), sigma) / np.maximum(support, 1e-6)
                                - (smooth * smooth).sum(axis=2), 0.0))
    trust = np.clip((support - MIN_SUPPORT) / (FULL_SUPPORT - MIN_SUPPORT), 0.0, 1.0)
    trust *= np.clip((SPREAD_NONE_PX - spread) / (SPREAD_NONE_PX - SPREAD_FULL_PX), 0.0, 1.0)
    corrected = on_switch & (trust > 0)
    if not corrected.any():
        return np.zeros((height, width, 2), np.float32)
    distance = cv2.distanceTransform((~corrected).astype(np.uint8), cv2.DIST_L2, 5)
    carried = carried_out(smooth, np.where(on_switch, trust, 0.0).astype(np.float32))
    reach = np.maximum(cfg.switch_fade_px, 1.875 * np.hypot(carried[..., 0], carried[..., 1]) / cfg.switch_max_slope)
    t = np.clip(distance * cell / reach, 0.0, 1.0)
    fade = 1.0 - t * t * t * (t * (6.0 * t - 15.0) + 10.0)
    field = cv2.GaussianBlur((carried * fade[..., None]).astype(np.float32), (0, 0), FIELD_SIGMA_PX / cell)
    field = slope_limited(field, FOLD_SLOPE * cell)
    return cv2.resize(field, (small[0] * cell, small[1] * cell), interpolation=cv2.INTER_LINEAR)[:height, :width]


def carried_out(values: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(H, W, 2) float32: ``values`` (H, W, 2), known with confidence ``weight`` (H, W) in [0, 1], carried
    to every cell by a harmonic extension: each cell the weighted mix of its known value and the mean of
    its neighbours (free cells: the mean alone). On the switches the values themselves where they are
    trusted, their neighbours' where not, and between two switches that disagree a smooth blend of
    both, never beyond them: no tear where the nearest switch changes, no bump. Solved coarse to fine on
    a Gaussian pyramid, ``HARMONIC_ROUNDS`` Jacobi rounds a level from the coarser level's solution."""
    num, den = values * weight[..., None], weight
    levels = []
    while True:
        levels.append((num / np.maximum(den, 1e-12)[..., None], np.clip(den / KNOWN_SUPPORT, 0.0, 1.0)[..., None]))
        if min(den.shape) < 8:
            break
        num, den = cv2.pyrDown(num), cv2.pyrDown(den)
    known_values, known = levels[-1]
    field = np.zeros_like(known_values)
    total = known.sum()
    field[:] = (known_values * known).sum(axis=(0, 1)) / total if total > 0 else 0.0
    for known_values, known in levels[::-1]:
        field = cv2.resize(field, known.shape[1::-1], interpolation=cv2.INTER_LINEAR)
        for _ in range(HARMONIC_ROUNDS):
            field = known * known_values + (1.0 - known) * cv2.blur(field, (3, 3))
    return field.astype(np.float32)


def slope_limited(field: np.ndarray, max_slope: float) -> np.ndarray:
    """(H, W, 2) float32 ``field`` scaled down where it changes by more than ``max_slope`` per pixel in any
    direction (central differences, either component): where two switches close together want very
    different corrections, the source would otherwise be squeezed toward a fold between them.
    ``SLOPE_ROUNDS`` times, each scale the smallest within a pixel and blurred, so that the scaling
    makes no steep edge of its own."""
    for _ in range(SLOPE_ROUNDS):
        steepest = np.zeros(field.shape[:2], np.float32)
        for k in range(2):
            gy, gx = np.gradient(field[..., k])
            steepest = np.maximum(steepest, np.maximum(np.abs(gx), np.abs(gy)))
        if steepest.max() <= max_slope:
            break
        scale = np.minimum(1.0, max_slope / np.maximum(steepest, 1e-6)).astype(np.float32)
        scale = cv2.GaussianBlur(cv2.erode(scale, np.ones((3, 3), np.uint8)), (0, 0), 1.0)
        field = field * scale[..., None]
    return field


def displaced_map(map_src_canvas: np.ndarray, field_canvas: np.ndarray, cfg: Config) -> np.ndarray:
    """(H, W, 2) float32: the source map resampled at u + field(u) (bilinear, clamped to the canvas):
    ``M_a(u) = M_s(u + C(u))`` (Warp kernel ``displaced_map_kernel``). Runs on ``cfg.device`` (resolved)."""
    height, width = map_src_canvas.shape[:2]
    device = cfg.device
    out = wp.empty((height, width), dtype=wp.vec2, device=device)
    inputs = [transfer.to_device(np.ascontiguousarray(map_src_canvas, np.float32), wp.vec2, device, "switch_align"),
              transfer.to_device(np.ascontiguousarray(field_canvas, np.float32), wp.vec2, device, "switch_align"), out]
    runtime.launch_rows(displaced_map_kernel, height, width, inputs, device, cfg.cpu_threads)
    return transfer.download(out, "switch_align").reshape(height, width, 2)


def aligned_source_map(map_src_canvas: np.ndarray, grey_src: np.ndarray, grey_tgt: np.ndarray, valid_src: np.ndarray,
                       valid_tgt: np.ndarray, seam_x_canvas: np.ndarray, cfg: Config) -> np.ndarray:
    """A source map aligned to the target at every switch of a stitch (module docstring).

    map_src_canvas: (H, W, 2) float32 the map the stitch was cut on (step 6's, or one aligned before);
    grey_*: (H, W) float32 grey views it and the target give on the canvas, with their gains (NaN
    where undefined); valid_*: (H, W) bool;
    seam_x_canvas: (H,) the seam's x per canvas row (where the seam runs). Runs on
    ``cfg.device`` (resolved) with ``cfg.cpu_threads``.
    """
    weight_src, weight_tgt = view_weights(seam_side_alpha(seam_x_canvas, valid_src.shape[1]), valid_src, valid_tgt)
    seam, border = switch_pixels(shown_labels(weight_src, weight_tgt), valid_src, valid_tgt)
    switches = seam | border
    both = valid_src & valid_tgt
    near = cv2.distanceTransform((~switches).astype(np.uint8), cv2.DIST_L2, 3) <= cfg.switch_band_px
    # The flow's box reaches as far beyond the band as the flow followed may go: content that moved out
    # of the box cannot be found, and DIS would match something else.
    box = bounding_box(near & both, int(np.ceil(cfg.switch_band_px + cfg.switch_max_px)))
    flow = np.zeros((*switches.shape, 2), np.float32)
    followed = np.zeros(switches.shape, bool)
    if box is not None:
        src8, tgt8 = extended(grey_src[box], valid_src[box]), extended(grey_tgt[box], valid_tgt[box])
        whole = (slice(None), slice(None))
        flow[box], flow_back = view_flow(src8, tgt8, whole, cfg.switch_flow_preset)
        textured = (edge_strength(src8) >= EDGE_GREY_PER_PX) & (edge_strength(tgt8) >= EDGE_GREY_PER_PX)
        # Patches reaching past a view's edge see its continuation, not the scene: read the flow inside.
        inside = cv2.erode((valid_src & valid_tgt)[box].astype(np.uint8), np.ones((EDGE_MARGIN_PX, EDGE_MARGIN_PX), np.uint8))
        followed[box] = (near[box] & (inside > 0) & textured & consistent(flow[box], flow_back, CONSISTENT_PX)
                         & (np.hypot(flow[box][..., 0], flow[box][..., 1]) <= cfg.switch_max_px))
    return displaced_map(map_src_canvas, switch_correction(flow, followed, switches, cfg), cfg)
