"""A video's estimates at a working resolution: the frames made small, the maps scaled up.

An estimate's dear stages work per canvas pixel (the warp map, the views, the gains, the seam). Above
``video_estimate_max_side`` the frames are made that small for it (XFeat sees them at ``xfeat_max_side``
anyway), and what the video composites with is scaled up to the full frames: the source map by
bilinear interpolation (it is smooth), the seam, its anchors and offsets and the border blend along
their lines; the alpha is made anew from the scaled seam by the seam's rule. The target stays
unwarped: its map on the full canvas is exact, at a whole-pixel offset.

The default side, 1920 px, leaves frames up to 1080p as they were: the estimate's settings are in
pixels, and a smaller working side lands on another model and seam, better on some recordings and
worse on others (``docs/evaluation.md``, "Working resolution of a video's estimate"); a 4K video is estimated as a
1080p one is.

Conventions: pixel centres at whole coordinates at both resolutions, so a position p of a frame made
(sx, sy) times smaller is at ``(p + 0.5) * s - 0.5`` in the full frame. The canvas follows the target
(pasted unwarped): working canvas position u is at ``(u - o + 0.5) * s_tgt - 0.5 + O`` on the full canvas,
o the working canvas's target offset, O = round(o * s_tgt) the full one's. The positions of a vertical
rig's working frame are transposed (``rig.py``), so its scales swap there.
"""

from __future__ import annotations

import time
from dataclasses import replace

import cv2
import numpy as np

from ..composite import SeamLayout, seam_weights
from ..config import Config
from ..features import Matches
from ..partition import BorderOffsets, SeamMaps, SeamOffsets
from ..rig import map_from_working
from ..stitch import StitchMaps
from .maps import at_positions, target_map


def working_scale(shapes: tuple[tuple[int, ...], ...], max_side: int) -> float:
    """Full pixels per working pixel for frames of ``shapes`` (rows, cols, ...): their long side down to
    ``max_side``, 1.0 where they are no larger."""
    return max(1.0, max(max(shape[:2]) for shape in shapes) / max_side)


def shrunk(img: np.ndarray, scale: float) -> np.ndarray:
    """``img`` made ``scale`` times smaller (area interpolation), each side rounded; itself at 1.0."""
    if scale == 1.0:
        return img
    rows, cols = img.shape[:2]
    return cv2.resize(img, (max(1, round(cols / scale)), max(1, round(rows / scale))), interpolation=cv2.INTER_AREA)


def axis_scales(full: tuple[int, ...], small: tuple[int, ...]) -> np.ndarray:
    """(sx, sy) float64: full pixels per working pixel of a frame of shape ``full`` made ``small``."""
    return np.array([full[1] / small[1], full[0] / small[0]], np.float64)


def shrunk_pair(images: tuple[np.ndarray, np.ndarray], scale: float
                ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """Both images made ``scale`` times smaller (:func:`shrunk`), and each one's (sx, sy) (:func:`axis_scales`)."""
    small = tuple(shrunk(img, scale) for img in images)
    return small, tuple(axis_scales(full.shape, img.shape) for full, img in zip(images, small))


def to_small(pts: np.ndarray, scale) -> np.ndarray:
    """Full-frame positions (..., 2), or values along one axis, as positions in the frame made ``scale``
    ((sx, sy) or one factor) times smaller."""
    return (np.asarray(pts, np.float64) + 0.5) / scale - 0.5


def to_full(pts: np.ndarray, scale) -> np.ndarray:
    """Working-frame positions to the full frame (the inverse of :func:`to_small`)."""
    return (np.asarray(pts, np.float64) + 0.5) * scale - 0.5


def small_matches(matches: Matches | None, scale_a: np.ndarray, scale_b: np.ndarray) -> Matches | None:
    """Matches of the full frames a, b on the frames made (sx, sy) ``scale_a`` / ``scale_b`` smaller."""
    if matches is None:
        return None
    return replace(matches, pts_a=to_small(matches.pts_a, scale_a), pts_b=to_small(matches.pts_b, scale_b))


def prior_to_small(prior_seam_tgt: np.ndarray | None, scale: float) -> np.ndarray | None:
    """A seam to stay near (x per working-frame target row, target pixels; ``stitch.estimate_seam``) on the
    target made ``scale`` times smaller (its rows as many fewer): the nominal scale for both axes, within
    0.05 % of each axis's own, close enough for a seam to stay near."""
    if prior_seam_tgt is None:
        return None
    rows_full = to_full(np.arange(max(1, round(len(prior_seam_tgt) / scale))), scale)
    return to_small(at_positions(np.asarray(prior_seam_tgt, np.float64), rows_full), scale)


def seam_alpha(seam_x: np.ndarray, shape: tuple[int, int], layout: SeamLayout, cfg: Config) -> np.ndarray:
    """(H, W) float32 source weight of a seam at ``seam_x`` (H,) per row, across ``layout``'s transition
    (``kernels/composite.py``'s ``seam_weights_kernel``: the rule ``partition.seam_maps`` gives its alpha)."""
    return seam_weights(seam_x, replace(layout, lines_are_rows=True, lf_px=0.0), shape, cfg)[0]


def scaled_up(maps: StitchMaps, scale_src: np.ndarray, scale_tgt: np.ndarray, shape_tgt: tuple[int, int],
              cfg: Config) -> StitchMaps:
    """``maps`` estimated on frames made (sx, sy) ``scale_src`` / ``scale_tgt`` smaller (input frame) as
    the full frames' maps; ``shape_tgt`` (rows, cols) of the full target (input frame); ``cfg.device``
    resolved.

    At full resolution: the input-frame maps, the seam's layout (its lf fade scaled with the canvas;
    transition and band stay the settings', in full pixels, as the frames are composited) and the
    alpha it gives, and the seam's path, maps, offsets and border blend. ``warp``, ``matches`` and the
    seam's zone stay at the working resolution; ``seconds`` gains ``scale_up``.
    """
    t0 = time.perf_counter()
    rig, seam = maps.rig, maps.seam
    s_src, s_tgt = (s[::-1] if rig.vertical else s for s in (scale_src, scale_tgt))
    rows_tgt, cols_tgt = shape_tgt[::-1] if rig.vertical else shape_tgt
    small_canvas = maps.warp.overlap.canvas
    o = np.asarray(small_canvas.offset_tgt, np.float64)
    big_o = np.round(o * s_tgt)
    height = int(max(round(small_canvas.height * s_tgt[1]), big_o[1] + rows_tgt))
    width = int(max(round(small_canvas.width * s_tgt[0]), big_o[0] + cols_tgt))
    u_x = to_small(np.arange(width) - big_o[0], s_tgt[0]) + o[0]  # working canvas column of each full one
    u_y = to_small(np.arange(height) - big_o[1], s_tgt[1]) + o[1]
    # Full canvas pixel (x, y) -> working canvas position (u_x[x], u_y[y]), as the matrix warpAffine inverts with.
    full_to_small = np.array([[1 / s_tgt[0], 0.0, u_x[0]], [0.0, 1 / s_tgt[1], u_y[0]]])

    def canvas_x(x_small: np.ndarray) -> np.ndarray:
        return to_full(x_small - o[0], s_tgt[0]) + big_o[0]

    def canvas_y(y_small: np.ndarray) -> np.ndarray:
        return to_full(y_small - o[1], s_tgt[1]) + big_o[1]

    def along_rows(x_small: np.ndarray) -> np.ndarray:
        """A position x per working canvas row as one per full canvas row (float32)."""
        return canvas_x(at_positions(np.asarray(x_small, np.float64), u_y)).astype(np.float32)

    def anchors(pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, np.float64).reshape(-1, 2)
        return np.stack([canvas_x(pts[:, 0]), canvas_y(pts[:, 1])], axis=1)

    # Each channel alone: OpenCV's 2-channel warp rounds positions to 1/32 px, its 1-channel one does not.
    map_src = np.stack([cv2.warpAffine(np.ascontiguousarray(seam.maps.map_src_canvas[:, :, k]), full_to_small,
                                       (width, height), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                       borderMode=cv2.BORDER_REPLICATE) for k in range(2)], axis=-1)
    map_src += np.float32(0.5)  # to_full in place, in float32: the map is the largest array here
    map_src *= s_src.astype(np.float32)
    map_src -= np.float32(0.5)
    seam_x = along_rows(seam.path.seam_x_canvas)
    seam_input = replace(maps.seam_input, positions=seam_x, lf_px=float(maps.seam_input.lf_px * s_tgt[0]))
    alpha = seam_alpha(seam_x, (height, width), seam_input, cfg)
    path = replace(seam.path, seam_x_canvas=seam_x, coarse_x_canvas=along_rows(seam.path.coarse_x_canvas),
                   rows=tuple(int(np.clip(round(canvas_y(r)), 0, height - 1)) for r in seam.path.rows),
                   anchors_src_canvas=anchors(seam.path.anchors_src_canvas),
                   anchors_tgt_canvas=anchors(seam.path.anchors_tgt_canvas))
    seam_maps = SeamMaps(map_src, target_map((height, width), big_o), alpha, seam_x, path.anchors_src_canvas,
                         path.anchors_tgt_canvas)  # partition.seam_maps takes its anchors from the path too
    offsets = SeamOffsets(at_positions(seam.offsets.src, u_y).astype(np.float32),
                          at_positions(seam.offsets.tgt, u_y).astype(np.float32), seam_input.lf_px)
    border = seam.border
    if border.on:
        lines = tuple(float(canvas_y(line)) for line in border.lines)
        border = BorderOffsets(lines, at_positions(border.src, u_x, axis=1).astype(np.float32),
                               at_positions(border.tgt, u_x, axis=1).astype(np.float32), True)
    return replace(maps, map_src_input=map_from_working(map_src, rig),
                   map_tgt_input=map_from_working(seam_maps.map_tgt_canvas, rig),
                   alpha_input=map_from_working(alpha, rig), seam_input=seam_input,
                   seam=replace(seam, path=path, maps=seam_maps, offsets=offsets, border=border),
                   seconds={**maps.seconds, "scale_up": time.perf_counter() - t0})
