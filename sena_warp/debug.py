"""Debug pictures of intermediate results (the ``stitch_verbose`` idea of STYLE.md).

Pictures are BGR uint8 ``(H, W, 3)`` images meant for people; nothing in the pipeline reads them.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .config import Config
from .features import Matches
from .imageio import encode_image
from .rig import image_to_working

# Drawing style only (not pipeline tunables): line and marker sizes in output pixels.
LINE_THICKNESS = 1
POINT_RADIUS = 3
HUE_STEPS = 180  # OpenCV's 8-bit hue range


def _match_colours(n: int) -> np.ndarray:
    """n distinct saturated BGR colours (uint8 (n, 3)), hue cycling with the golden ratio."""
    if n == 0:
        return np.zeros((0, 3), np.uint8)  # cvtColor refuses an empty image
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    hues = (np.arange(n) * golden % 1.0 * HUE_STEPS).astype(np.uint8)
    hsv = np.stack([hues, np.full(n, 255, np.uint8), np.full(n, 255, np.uint8)], axis=1)
    return cv2.cvtColor(hsv[None], cv2.COLOR_HSV2BGR)[0]


def draw_matches(img_a: np.ndarray, img_b: np.ndarray, matches: Matches) -> np.ndarray:
    """Image a and image b side by side (a left, b right, tops aligned), one coloured line per match.

    ``img_a``/``img_b``: BGR uint8 (H, W, 3), sizes may differ (the shorter one is padded with
    black below). ``matches.pts_a``/``pts_b`` are ``(x, y)`` pixels of a and b. Returns BGR uint8
    (max(H_a, H_b), W_a + W_b, 3).
    """
    height = max(img_a.shape[0], img_b.shape[0])
    canvas = np.zeros((height, img_a.shape[1] + img_b.shape[1], 3), np.uint8)
    canvas[: img_a.shape[0], : img_a.shape[1]] = img_a
    canvas[: img_b.shape[0], img_a.shape[1]:] = img_b
    pts_b_canvas = matches.pts_b + np.array([img_a.shape[1], 0.0])
    for pa, pb, colour in zip(matches.pts_a, pts_b_canvas, _match_colours(len(matches))):
        colour = tuple(int(c) for c in colour)
        pa, pb = tuple(int(round(v)) for v in pa), tuple(int(round(v)) for v in pb)
        cv2.line(canvas, pa, pb, colour, LINE_THICKNESS, cv2.LINE_AA)
        cv2.circle(canvas, pa, POINT_RADIUS, colour, LINE_THICKNESS, cv2.LINE_AA)
        cv2.circle(canvas, pb, POINT_RADIUS, colour, LINE_THICKNESS, cv2.LINE_AA)
    return canvas


def _heatmap(values: np.ndarray, vmax: float) -> np.ndarray:
    """(H, W) float values in [0, vmax] as a BGR colour map (turbo)."""
    scaled = np.clip(np.nan_to_num(values) / max(vmax, 1e-9) * 255.0, 0, 255).astype(np.uint8)
    return cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)


def _placed_target(img_tgt: np.ndarray, canvas) -> np.ndarray:
    """The target pasted on a black canvas at its integer offset."""
    out = np.zeros((*canvas.shape, 3), np.uint8)
    ox, oy = (int(round(v)) for v in canvas.offset_tgt)
    out[oy:oy + img_tgt.shape[0], ox:ox + img_tgt.shape[1]] = img_tgt
    return out


def draw_overlap_cells(img_tgt: np.ndarray, warp) -> np.ndarray:
    """Target on the canvas with the overlap polygon (yellow) and each cell's box and confidence."""
    canvas = warp.overlap.canvas
    pic = _placed_target(img_tgt, canvas)
    poly = np.round(warp.overlap.polygon_canvas).astype(np.int32)
    cv2.polylines(pic, [poly], True, (0, 255, 255), 2, cv2.LINE_AA)
    offset = np.asarray(canvas.offset_tgt)
    cells = () if warp.local is None else zip(warp.local.centres_tgt, warp.local.conf, warp.local.affines_src_to_tgt)
    for centre, conf, _ in cells:
        c = tuple(int(round(v)) for v in centre + offset)
        cv2.circle(pic, c, 6, (0, 0, 255), -1, cv2.LINE_AA)
        cv2.putText(pic, f"conf {conf:.2f}", (c[0] + 8, c[1]), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1,
                    cv2.LINE_AA)
    for pt in np.round(canvas.tgt_to_canvas(warp.inliers_tgt)).astype(int):
        cv2.circle(pic, tuple(pt), 2, (0, 255, 0), -1)
    return pic


def draw_field(field_canvas: np.ndarray) -> np.ndarray:
    """Magnitude of an (H, W, 2) displacement field (px) as a colour map, with arrows every 40 px."""
    magnitude = np.hypot(field_canvas[:, :, 0], field_canvas[:, :, 1])
    pic = _heatmap(magnitude, float(np.nanmax(magnitude)) if magnitude.size else 1.0)
    step = 40
    for y in range(step // 2, field_canvas.shape[0], step):
        for x in range(step // 2, field_canvas.shape[1], step):
            dx, dy = field_canvas[y, x]
            tip = (int(round(x + 4 * dx)), int(round(y + 4 * dy)))
            cv2.arrowedLine(pic, (x, y), tip, (255, 255, 255), 1, cv2.LINE_AA, tipLength=0.3)
    cv2.putText(pic, f"max |D| {np.nanmax(magnitude):.1f} px (arrows x4)", (10, 24), cv2.FONT_HERSHEY_SIMPLEX,
                0.6, (255, 255, 255), 1, cv2.LINE_AA)
    return pic


def draw_warped_over_target(img_src: np.ndarray, img_tgt: np.ndarray, warp, cfg: Config) -> np.ndarray:
    """50/50 mix of the warped source and the placed target: misalignment shows as ghosting."""
    from .warp_map import remap_image  # here, not at the top: ``sena-warp match`` draws without Warp

    warped, valid = remap_image(img_src, warp.map_src_canvas, cfg)
    placed = _placed_target(img_tgt, warp.overlap.canvas)
    mix = np.where(valid[:, :, None], warped, placed)
    both = valid & placed.any(axis=2)
    mix[both] = (warped[both].astype(np.uint16) + placed[both]) // 2
    return mix


def draw_seam(pano_working: np.ndarray, seam) -> np.ndarray:
    """The panorama with the adequate zone (blue band), the anchors (red), the seam (green) and the
    reduced-canvas path it was refined from (yellow)."""
    pic = pano_working[:, :, :3].copy()
    x0, x1 = int(round(seam.zone.x0)), int(round(seam.zone.x1))
    band = pic[:, x0:x1 + 1].astype(np.uint16)
    band[:, :, 0] = np.minimum(band[:, :, 0] + 80, 255)
    pic[:, x0:x1 + 1] = band.astype(np.uint8)
    for seam_x, colour in ((seam.path.coarse_x_canvas, (0, 255, 255)), (seam.maps.seam_x_canvas, (0, 255, 0))):
        pts = np.stack([seam_x, np.arange(len(seam_x))], axis=1)
        cv2.polylines(pic, [np.round(pts).astype(np.int32)], False, colour, 1, cv2.LINE_AA)
    for a in np.round(seam.anchors_tgt_canvas).astype(int):
        cv2.circle(pic, tuple(a), 4, (0, 0, 255), -1, cv2.LINE_AA)
    return pic


def dump_stages(folder, img_a: np.ndarray, img_b: np.ndarray, pano, cfg: Config) -> list:
    """Write one picture per stage into the existing ``folder``; returns the paths written.

    The folder is an output's temporary (``outputs.OutputPlan``), so the pictures are written into
    it directly. Pictures after the features are in the working frame (source left; transposed for
    a vertical rig). ``cfg``: the stitch's settings (the warped source is remapped on its device).
    """
    maps = pano.maps
    folder = Path(folder)
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    pano_working = image_to_working(pano.image, maps.rig)
    pictures = {
        "01_matches.jpg": draw_matches(img_a, img_b, maps.matches),
        "02_overlap_cells.jpg": draw_overlap_cells(img_tgt, maps.warp),
        "03_ffd_field.jpg": draw_field(maps.warp.field_canvas),
        **({} if maps.warp.gate_canvas is None else {"04_gate.jpg": _heatmap(maps.warp.gate_canvas, 1.0)}),
        "05_warped_over_target.jpg": draw_warped_over_target(img_src, img_tgt, maps.warp, cfg),
        "06_zone_chain_seam.jpg": draw_seam(pano_working, maps.seam),
        "07_alpha.jpg": _heatmap(maps.seam.maps.alpha_canvas, 1.0),
    }
    paths = []
    for name, pic in pictures.items():
        (folder / name).write_bytes(memoryview(encode_image(folder / name, pic)))
        paths.append(folder / name)
    return paths
