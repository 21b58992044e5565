"""SENA canvas maps adapted to YUV 4:2:0 video planes, on a canvas fixed for the whole video.

A stitch estimate gives full-resolution maps over its canvas (``sena_warp.stitch.StitchMaps``). A
video composites the decoder's planes directly (no RGB on the hot path, docs/method.md "Maps, not images"):
Y with those maps, U and V with half-resolution maps derived from them once per estimate. The
output size is fixed by the first estimate; later estimates are expressed on that canvas.

Conventions: maps are float32 ``(H, W, 2)`` of (x, y) sample positions, NaN where nothing may be
sampled (the compositor treats NaN as outside); alpha is float32 ``(H, W)``, the source weight.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
import warp as wp

from ..composite import BorderBlend, SeamLayout
from ..config import Config
from ..rig import Rig
from ..stitch import StitchMaps
from sena_warp.kernels import map_change, runtime
from sena_warp.kernels.transfer import host_array

# Output pixels no input covers: black in limited-range BT.601, the range H.264 decoders assume.
BLACK_Y, BLACK_UV = 16, 128
WHITE_Y = 235  # limited-range white: where the gains' highlight knee runs to on the Y plane
Y_PER_GREY = 219 / 255  # limited-range Y levels per full-range grey level (a grey offset moves Y only)


@dataclass(frozen=True)
class PlaneMaps:
    """One estimate's maps on the fixed (even-sized) output canvas, for luma and for chroma.

    ``map_src_luma`` / ``map_tgt_luma``: (H, W, 2) float32 (x, y) in the source / target Y plane;
    ``alpha_luma`` (H, W) the source weight the seam gives; ``seam_luma`` the seam for the compositor.
    ``*_chroma``: the same at (H/2, W/2), positions in the U/V planes.
    ``seam_x_working``: (rows,) float32 seam x per row of the *working* frame (``rig.py``), NaN
    where the estimate's canvas does not reach. ``inliers``: global-affine inliers of the estimate.
    ``border_luma``: the estimate's border blend on the Y plane (``partition.border_offsets``): lines
    (2,), source offsets (2, P, 1), target offsets (2, P, 1) in the compositor's terms, or None.
    ``overlap_luma``: a static rig's overlap per seam line of the Y plane (:func:`overlap_lines`), over
    which its per-frame seam may go round what is in front; None for a moving rig.

    A value: its arrays are made read-only, so a plan may use them where they are (``composite_plan``)
    and anything that moves the maps makes new ones.
    """

    map_src_luma: np.ndarray
    map_tgt_luma: np.ndarray
    alpha_luma: np.ndarray
    map_src_chroma: np.ndarray
    map_tgt_chroma: np.ndarray
    alpha_chroma: np.ndarray
    seam_luma: SeamLayout
    seam_chroma: SeamLayout
    seam_x_working: np.ndarray
    inliers: int
    border_luma: BorderBlend | None
    overlap_luma: np.ndarray | None = None

    def __post_init__(self) -> None:
        border = () if self.border_luma is None else (self.border_luma.src, self.border_luma.tgt)
        overlap = () if self.overlap_luma is None else (self.overlap_luma,)
        for array in (*overlap, self.map_src_luma, self.map_tgt_luma, self.alpha_luma, self.map_src_chroma, self.map_tgt_chroma,
                      self.alpha_chroma, self.seam_luma.positions, self.seam_chroma.positions, self.seam_x_working,
                      *border):
            array.flags.writeable = False

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the output luma plane."""
        return self.alpha_luma.shape


def target_offset(map_tgt_canvas: np.ndarray) -> np.ndarray:
    """o = (ox, oy), the canvas position of target pixel (0, 0), read off the target map.

    The target is pasted unwarped (``map_tgt = u - o`` everywhere, docs/method.md step 2), so the map at
    canvas pixel (0, 0) is -o. Float64 (2,), whole pixels, in the frame the map is in.
    """
    return -np.asarray(map_tgt_canvas[0, 0], dtype=np.float64)


def shift_onto(field: np.ndarray, shift_xy: np.ndarray, shape: tuple[int, int], fill: float) -> np.ndarray:
    """``out[y, x] = field[y + dy, x + dx]`` on a grid of ``shape`` (H, W); ``fill`` outside ``field``.

    ``field`` is (h, w) or (h, w, C); ``shift_xy`` = (dx, dy) whole pixels. Used to express an
    estimate on the fixed canvas: u_new = u_fixed - o_fixed + o_new.
    """
    dx, dy = (int(round(v)) for v in shift_xy)
    out = np.full((*shape, *field.shape[2:]), fill, dtype=field.dtype)
    h, w = field.shape[:2]
    y0, y1 = max(0, -dy), min(shape[0], h - dy)
    x0, x1 = max(0, -dx), min(shape[1], w - dx)
    if y0 < y1 and x0 < x1:
        out[y0:y1, x0:x1] = field[y0 + dy:y1 + dy, x0 + dx:x1 + dx]
    return out


def target_map(shape: tuple[int, int], offset_tgt: np.ndarray) -> np.ndarray:
    """(H, W, 2) float32 target map ``u - o`` of a canvas of ``shape`` (H, W) with target offset o = (ox, oy)."""
    out = np.empty((*shape, 2), np.float32)
    out[:, :, 0] = np.arange(shape[1], dtype=np.float32)[None, :] - np.float32(offset_tgt[0])
    out[:, :, 1] = np.arange(shape[0], dtype=np.float32)[:, None] - np.float32(offset_tgt[1])
    return out


def chroma_positions(map_luma: np.ndarray) -> np.ndarray:
    """Half-resolution map for 4:2:0 planes from an even-sized luma map (H, W, 2) -> (H/2, W/2, 2).

    Chroma pixel (xc, yc) sits at luma (2xc + 0.5, 2yc + 0.5) (MPEG-2/H.264 centred chroma), the
    centre of its 2x2 luma block, so the bilinear sample of the luma map there is the block mean.
    That gives the source luma position (xs, ys), i.e. chroma position ((xs - 0.5)/2, (ys - 0.5)/2).
    NaN anywhere in the block stays NaN (nothing sampled).
    """
    pos_luma = block_mean(map_luma)
    return ((pos_luma - 0.5) * 0.5).astype(np.float32)


def block_mean(field: np.ndarray) -> np.ndarray:
    """Mean of each 2x2 block of an even-sized (H, W) or (H, W, C) float array: (H/2, W/2[, C])."""
    return 0.25 * (field[0::2, 0::2] + field[1::2, 0::2] + field[0::2, 1::2] + field[1::2, 1::2])


def plane_maps(maps: StitchMaps, shape: tuple[int, int], offset_fixed: np.ndarray) -> PlaneMaps:
    """An estimate's maps on the fixed canvas of ``shape`` (even H, W) whose target offset is ``offset_fixed``.

    Canvas pixels outside the estimate's own canvas get a NaN source map and alpha 0; the target
    map is the fixed canvas's own (the target is never warped, so it is the same for every estimate).
    Chroma maps are derived once here so frames only sample.
    """
    shift_xy = target_offset(maps.map_tgt_input) - offset_fixed
    map_src = shift_onto(maps.map_src_input.astype(np.float32), shift_xy, shape, np.nan)
    map_tgt = target_map(shape, offset_fixed)
    alpha = shift_onto(maps.alpha_input.astype(np.float32), shift_xy, shape, 0.0)
    seam_x = seam_on_canvas(maps.seam.maps.seam_x_canvas, maps.rig, shift_xy, shape)
    seam_luma = SeamLayout(positions=filled(seam_x), lines_are_rows=not maps.rig.vertical,
                           band_px=maps.seam_input.band_px, transition_px=maps.seam_input.transition_px,
                           smooth_sigma_px=maps.seam_input.smooth_sigma_px, lf_px=maps.seam_input.lf_px)
    return PlaneMaps(
        map_src_luma=map_src, map_tgt_luma=map_tgt, alpha_luma=alpha,
        map_src_chroma=chroma_positions(map_src), map_tgt_chroma=chroma_positions(map_tgt),
        alpha_chroma=block_mean(alpha).astype(np.float32),
        seam_luma=seam_luma, seam_chroma=chroma_seam(seam_luma),
        seam_x_working=seam_x,
        inliers=int(maps.warp.glob.n_inliers),
        border_luma=border_on_canvas(maps, shift_xy, shape),
    )


def maps_on_canvas(maps: StitchMaps, shape: tuple[int, int], offset_fixed: np.ndarray, band_px: int,
                   shape_out: tuple[int, int], shapes: tuple[tuple[int, int], tuple[int, int]], static: bool,
                   cfg: Config) -> PlaneMaps:
    """:func:`plane_maps` of an estimate on the fixed canvas of ``shape``, scaled to the output of
    ``shape_out`` (:func:`scaled_plane_maps`), with its seam's home for a rig of Y ``shapes`` (rows, cols
    of the source's and the target's planes; :func:`with_home`), its plan's band widened by ``band_px``,
    the reach of the per-frame seam (``frame_seam.band_half_width``, output pixels), so both views are kept
    wherever the frame's seam may go. ``static``: a static rig, whose seam may go round what is in front
    anywhere in the overlap: the overlap is kept (``overlap_luma``, output pixels) and the plan's band
    reaches over all of it from the home."""
    plane = with_home(scaled_plane_maps(plane_maps(maps, shape, offset_fixed), shape_out), shapes, cfg)
    reach = band_px + plane.seam_luma.band_px
    overlap = None
    if static:
        overlap = overlap_lines(plane, *shapes)
        home, inside = plane.seam_luma.positions, overlap[:, 1] >= overlap[:, 0]
        far = np.maximum(home - overlap[:, 0], overlap[:, 1] - home)[inside & np.isfinite(home)]
        reach += float(far.max()) if far.size else 0.0
    return replace(plane, seam_luma=replace(plane.seam_luma, band_px=reach),
                   seam_chroma=replace(plane.seam_chroma, band_px=0.5 * reach), overlap_luma=overlap)


def border_on_canvas(maps: StitchMaps, shift_xy: np.ndarray, shape: tuple[int, int]) -> BorderBlend | None:
    """The estimate's border blend (grey levels per working column at two working rows) on the fixed
    canvas's Y plane: lines ``L - dy``, offsets shifted by ``dx`` along them (0 beyond the estimate's
    canvas) and scaled to Y levels; None when the estimate has none. ``shift_xy`` and ``shape`` as
    :func:`seam_on_canvas`'s."""
    border = maps.seam.border
    if not border.on:
        return None
    dx, dy = shift_xy[::-1] if maps.rig.vertical else shift_xy
    positions = shape[0] if maps.rig.vertical else shape[1]

    def along(offsets: np.ndarray) -> np.ndarray:
        grey = offsets[:, :, :1].transpose(1, 0, 2)[:, :, 0]  # (W, 2): the offsets are grey, one channel says all
        shifted = shift_onto(grey.astype(np.float32)[:, :, None], np.array([0.0, dx]), (positions, 2), 0.0)[:, :, 0]
        return (Y_PER_GREY * shifted.T)[:, :, None].astype(np.float32)

    lines = tuple(float(line - round(dy)) for line in border.lines)
    return BorderBlend(lines, along(border.src), along(border.tgt))


def filled(positions: np.ndarray) -> np.ndarray:
    """(L,) float32 with NaN entries (lines the estimate's canvas does not reach) set to the nearest
    known one, so that every line of the fixed canvas has a seam."""
    known = np.isfinite(positions)
    if known.all() or not known.any():
        return np.nan_to_num(positions).astype(np.float32)
    lines = np.arange(len(positions))
    return np.interp(lines, lines[known], positions[known]).astype(np.float32)


def chroma_lines(positions: np.ndarray) -> np.ndarray:
    """Seam positions of the half-resolution U/V planes from the luma ones (L,) (L even): chroma line l
    holds luma lines 2l and 2l + 1, and chroma position p sits at luma position 2p + 0.5
    (``chroma_positions``)."""
    pairs = np.asarray(positions, np.float32)[: len(positions) // 2 * 2].reshape(-1, 2).mean(axis=1)
    return ((pairs - 0.5) * 0.5).astype(np.float32)


def chroma_seam(seam: SeamLayout) -> SeamLayout:
    """The seam of the half-resolution U/V planes (``chroma_lines``); widths halve."""
    return SeamLayout(positions=chroma_lines(seam.positions), lines_are_rows=seam.lines_are_rows,
                      band_px=0.5 * seam.band_px, transition_px=0.5 * seam.transition_px,
                      smooth_sigma_px=0.5 * seam.smooth_sigma_px, lf_px=0.5 * seam.lf_px)


def seam_on_canvas(seam_x_working: np.ndarray, rig: Rig, shift_xy: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Seam x per working-frame row of the fixed canvas: ``s_fixed[r] = s_new[r + dy] - dx`` (working frame).

    ``shift_xy`` and ``shape`` are in the input frame; a vertical rig works transposed, so both swap.
    """
    dx, dy = shift_xy[::-1] if rig.vertical else shift_xy
    rows = shape[1] if rig.vertical else shape[0]
    seam = shift_onto(seam_x_working.astype(np.float32)[:, None], np.array([0.0, dy]), (rows, 1), np.nan)
    return seam[:, 0] - np.float32(round(dx))


def seam_per_target_line(positions: np.ndarray, offset_working: np.ndarray) -> np.ndarray:
    """A canvas seam (L,) per working-frame canvas line as x per working-frame target row, in target
    pixels; ``offset_working`` (ox, oy): the target's canvas offset in the working frame. Target rows
    above the canvas (a cropped canvas starts inside the target) are NaN: no seam known there."""
    ox, oy = offset_working
    first = int(round(oy))
    seam = np.asarray(positions, np.float64)
    if first < 0:
        seam = np.concatenate([np.full(-first, np.nan), seam])
    return seam[max(first, 0):] - ox


def output_shape(canvas_shape: tuple[int, int], max_width: int) -> tuple[int, int]:
    """(H, W) of the output for a canvas of ``canvas_shape`` (H, W) at most ``max_width`` wide (0: no
    limit): the aspect kept, both sides even (yuv420p), at least 2."""
    height, width = canvas_shape
    if not max_width or width <= max_width:
        return canvas_shape
    out_w = max(2, max_width - max_width % 2)
    out_h = max(2, int(round(height * out_w / width / 2)) * 2)
    return out_h, out_w


def canvas_scale(canvas_shape: tuple[int, int], shape_out: tuple[int, int]) -> np.ndarray:
    """(sx, sy): output pixels per canvas pixel along x and y."""
    return np.array([shape_out[1] / canvas_shape[1], shape_out[0] / canvas_shape[0]], np.float64)


def canvas_positions(count_out: int, scale: float) -> np.ndarray:
    """Canvas position of each of ``count_out`` output pixels along an axis scaled by ``scale``
    (pixel centres at whole coordinates on both: output p is canvas ``(p + 0.5) / scale - 0.5``)."""
    return (np.arange(count_out, dtype=np.float64) + 0.5) / scale - 0.5


def on_output(field: np.ndarray, shape_out: tuple[int, int]) -> np.ndarray:
    """(H, W[, C]) float ``field`` on the canvas sampled bilinearly at each output pixel of ``shape_out``;
    NaN where a tap that counts is NaN (a map's "nothing to sample" stays so), float32."""
    scale = canvas_scale(field.shape[:2], shape_out)
    rows = at_positions(field, canvas_positions(shape_out[0], scale[1]), axis=0)
    return at_positions(rows, canvas_positions(shape_out[1], scale[0]), axis=1).astype(np.float32)


def at_positions(values: np.ndarray, positions: np.ndarray, axis: int = 0) -> np.ndarray:
    """``values`` sampled linearly along ``axis`` at fractional ``positions`` (clamped to its ends); NaN
    where a tap that counts is NaN."""
    last = values.shape[axis] - 1
    p = np.clip(np.asarray(positions, np.float64), 0, last)
    i0 = np.floor(p).astype(np.int64)
    i1 = np.minimum(i0 + 1, last)
    shape = [1] * values.ndim
    shape[axis] = len(p)
    f = (p - i0).reshape(shape)
    low, high = np.take(values, i0, axis=axis), np.take(values, i1, axis=axis)
    return np.where(f == 0.0, low, low * (1.0 - f) + high * f)


def scaled_plane_maps(maps: PlaneMaps, shape_out: tuple[int, int]) -> PlaneMaps:
    """``maps`` (on the fixed canvas) for an output of ``shape_out`` (even H, W), the canvas scaled to it:
    every output pixel samples the inputs where the canvas position it covers does (the maps are
    smooth: bilinear between canvas pixels), the seam, its widths and the border blend scaled along.
    ``seam_x_working`` and ``inliers`` stay the estimate's (canvas pixels: what the report measures)."""
    if shape_out == maps.shape:
        return maps
    sx, sy = canvas_scale(maps.shape, shape_out)
    rows = maps.seam_luma.lines_are_rows
    along, across = (sy, sx) if rows else (sx, sy)  # lines run along one axis, the seam's positions the other
    count = shape_out[0] if rows else shape_out[1]
    positions = (at_positions(maps.seam_luma.positions, canvas_positions(count, along)) + 0.5) * across - 0.5
    seam = SeamLayout(positions=positions.astype(np.float32), lines_are_rows=rows,
                      band_px=maps.seam_luma.band_px * across, transition_px=maps.seam_luma.transition_px * across,
                      smooth_sigma_px=maps.seam_luma.smooth_sigma_px * across, lf_px=maps.seam_luma.lf_px * across)
    border = maps.border_luma
    if border is not None:
        spots = canvas_positions(shape_out[1] if rows else shape_out[0], across)
        border = BorderBlend(tuple(float((line + 0.5) * along - 0.5) for line in border.lines),
                             at_positions(border.src, spots, axis=1).astype(np.float32),
                             at_positions(border.tgt, spots, axis=1).astype(np.float32))
    map_src, map_tgt, alpha = (on_output(field, shape_out)
                               for field in (maps.map_src_luma, maps.map_tgt_luma, maps.alpha_luma))
    return replace(maps, map_src_luma=map_src, map_tgt_luma=map_tgt, alpha_luma=alpha,
                   map_src_chroma=chroma_positions(map_src), map_tgt_chroma=chroma_positions(map_tgt),
                   alpha_chroma=block_mean(alpha).astype(np.float32), seam_luma=seam, seam_chroma=chroma_seam(seam),
                   border_luma=border)


def translated(field: np.ndarray, corner: np.ndarray, shape: tuple[int, int], fill: float) -> np.ndarray:
    """(H, W[, C]) float32 of ``shape``: ``field`` (h, w[, C]) float32 at (x, y) + ``corner`` (x, y),
    sub-pixel, bilinearly (a tap of weight 0 does not count; a NaN tap that counts makes NaN, so a
    map's "nothing to sample" stays so); ``fill`` where a counted tap lies off ``field``."""
    whole = np.floor(np.asarray(corner, np.float64))
    fx, fy = (float(v) for v in np.asarray(corner, np.float64) - whole)
    rows, cols = shape
    taps = shift_onto(field, whole, (rows + 1, cols + 1), fill)
    across = taps[:, :cols] if fx == 0.0 else cv2.addWeighted(taps[:, :cols], 1.0 - fx, taps[:, 1:], fx, 0.0)
    out = across[:rows] if fy == 0.0 else cv2.addWeighted(across[:rows], 1.0 - fy, across[1:], fy, 0.0)
    return np.ascontiguousarray(out, np.float32)


def windowed_lines(per_line: np.ndarray, corner: np.ndarray, lines_are_rows: bool, count: int) -> np.ndarray:
    """Per-line values (L[, C]) of the canvas, for ``count`` lines of a window whose pixel (0, 0) sits at
    canvas ``corner`` (x, y): window line l is canvas line l + the corner's along the lines (linear
    between lines, clamped at the ends), float64."""
    along = corner[1] if lines_are_rows else corner[0]
    return at_positions(np.asarray(per_line, np.float64), np.arange(count) + float(along), axis=0)


def windowed_seam(positions: np.ndarray, corner: np.ndarray, lines_are_rows: bool, count: int) -> np.ndarray:
    """A canvas seam (L,) (positions along its lines) as the seam of the window at ``corner`` (x, y) with
    ``count`` lines (:func:`windowed_lines`, less the corner across the lines), float32."""
    across = corner[0] if lines_are_rows else corner[1]
    return (windowed_lines(positions, corner, lines_are_rows, count) - float(across)).astype(np.float32)


def windowed_layouts(maps: PlaneMaps, corner: np.ndarray, shape_out: tuple[int, int]
                     ) -> tuple[SeamLayout, SeamLayout, BorderBlend | None]:
    """The seam (luma, chroma) and the border blend of ``maps`` (on the canvas) for an output of ``shape_out``
    (even H, W) whose pixel (x, y) shows the canvas at (x, y) + ``corner`` (x, y luma px, sub-pixel)."""
    corner = np.asarray(corner, np.float64)
    rows = maps.seam_luma.lines_are_rows
    lines = shape_out[0] if rows else shape_out[1]
    seam = replace(maps.seam_luma, positions=windowed_seam(maps.seam_luma.positions, corner, rows, lines))
    border = maps.border_luma
    if border is not None:
        along, across = (corner[1], corner[0]) if rows else (corner[0], corner[1])
        spots = np.arange(shape_out[1] if rows else shape_out[0]) + float(across)
        border = BorderBlend(tuple(float(line - along) for line in border.lines),
                             at_positions(border.src, spots, axis=1).astype(np.float32),
                             at_positions(border.tgt, spots, axis=1).astype(np.float32))
    return seam, chroma_seam(seam), border


def windowed_plane_maps(maps: PlaneMaps, corner: np.ndarray, shape_out: tuple[int, int],
                        offset_tgt: np.ndarray) -> PlaneMaps:
    """``maps`` (on the canvas, at its stitched size: the target map is ``u - offset_tgt``) for an output
    of ``shape_out`` (even H, W) whose pixel (x, y) shows the canvas at (x, y) + ``corner`` (x, y luma
    px, sub-pixel; may lie off the canvas, where nothing is sampled): every output pixel samples the
    inputs once, where the canvas position it shows does (the source maps are smooth: bilinear between
    canvas pixels; chroma pixels at half the corner; the target's exact, u - offset_tgt + corner: the
    canvas holds the whole target, or a crop the window never leaves); the seam, the border blend along
    (:func:`windowed_layouts`). A moving rig's steady canvas (``steady.py``) is composited by the plan of
    these maps, made without them (``composite.window_plan``); these are what it composites, for a
    reference. ``overlap_luma`` is left out (None): these maps are composited, the per-frame seam works
    on the canvas's."""
    corner = np.asarray(corner, np.float64)
    origin = np.asarray(offset_tgt, np.float64) - corner  # where target pixel (0, 0) sits on the window
    half = 0.5 * corner
    chroma_out = (shape_out[0] // 2, shape_out[1] // 2)
    seam, seam_chroma, border = windowed_layouts(maps, corner, shape_out)
    return replace(maps, map_src_luma=translated(maps.map_src_luma, corner, shape_out, np.nan),
                   map_tgt_luma=target_map(shape_out, origin),
                   alpha_luma=translated(maps.alpha_luma, corner, shape_out, 0.0),
                   map_src_chroma=translated(maps.map_src_chroma, half, chroma_out, np.nan),
                   map_tgt_chroma=target_map(chroma_out, 0.5 * origin),
                   alpha_chroma=translated(maps.alpha_chroma, half, chroma_out, 0.0),
                   seam_luma=seam, seam_chroma=seam_chroma, border_luma=border, overlap_luma=None)


def seam_on_canvas_lines(positions_out: np.ndarray, lines: int, scale: np.ndarray, lines_are_rows: bool) -> np.ndarray:
    """An output seam (L_out,) as canvas positions per canvas line (``lines`` of them): the inverse of
    :func:`scaled_plane_maps`' seam, for what works on the canvas (a re-estimate's prior seam)."""
    along, across = (scale[1], scale[0]) if lines_are_rows else (scale[0], scale[1])
    at_lines = at_positions(np.asarray(positions_out, np.float64), (np.arange(lines) + 0.5) * along - 0.5)
    return ((at_lines + 0.5) / across - 0.5).astype(np.float32)


def drifted_maps(maps: PlaneMaps, shift_src: np.ndarray, shift_tgt: np.ndarray,
                 scale: tuple[float, float] = (1.0, 1.0)) -> PlaneMaps:
    """``maps`` after the source camera's content moved by ``shift_src`` (x, y) in its Y plane and the
    target's by ``shift_tgt`` (``drift.py``): the target is never warped, so its content moves by
    ``shift_tgt`` on the canvas, and what canvas pixel q shows came from ``q - shift_tgt`` before, whose
    source position moved by ``shift_src``: ``map_src'(q) = map_src(q - shift_tgt) + shift_src``. The
    canvas shift is taken in whole pixels and its fraction added to the positions (the source map's
    scale is about 1 px per px). The seam stays where it is on the canvas (inside the overlap, which
    the fixed target frame bounds; the per-frame seam finds its way in its band), and so do the
    target map and the border blend. On an output scaled from the canvas (``scale``: output pixels per
    canvas pixel, x and y) the target's content moves ``shift_tgt * scale`` output pixels, and a
    position's fraction of an output pixel is ``1 / scale`` input pixels."""
    scale = np.asarray(scale, np.float64)
    moved = np.asarray(shift_tgt, np.float64) * scale
    whole = np.round(moved)
    map_src = (shift_onto(maps.map_src_luma, -whole, maps.shape, np.nan)
               + (np.asarray(shift_src) - (moved - whole) / scale).astype(np.float32)).astype(np.float32)
    return replace(maps, map_src_luma=map_src, map_src_chroma=chroma_positions(map_src))


class ArrayLerp:
    """``a + weight * (b - a)`` for any weight, computed as before: the difference, scaled by the float32
    weight, then added; ``b``'s value where either is NaN (the maps hold no infinities), cast to float32.
    The difference and where ``a`` alone is NaN are worked out once, so a step of a blend makes two
    passes over the array instead of four. An array ``a`` and ``b`` share is kept as it is."""

    def __init__(self, a: np.ndarray, b: np.ndarray):
        self._a, self._shared = a, a is b
        if not self._shared:
            self._difference = np.ascontiguousarray(b - a)  # each step's array C-ordered: its flat view below
            self._goal_only = np.flatnonzero(np.isnan(a) & ~np.isnan(b))
            self._goal_values = np.ravel(b)[self._goal_only]

    def at(self, weight: float) -> np.ndarray:
        if self._shared:
            return self._a
        mixed = self._difference * np.float32(weight)  # a new array: the compositor keeps the last one
        mixed += self._a
        mixed.reshape(-1)[self._goal_only] = self._goal_values
        return mixed.astype(np.float32, copy=False)


class MapsBlend:
    """Maps between ``start`` and ``goal``: :meth:`at` ``weight`` gives every array of the two as
    :class:`ArrayLerp` does, and the rest (inliers, the border blend, the seams' layouts) as ``goal`` has it."""

    ARRAYS = ("map_src_luma", "map_tgt_luma", "alpha_luma", "map_src_chroma", "map_tgt_chroma", "alpha_chroma",
              "seam_x_working")

    def __init__(self, start: PlaneMaps, goal: PlaneMaps):
        self._goal = goal
        self._arrays = {name: ArrayLerp(getattr(start, name), getattr(goal, name)) for name in self.ARRAYS}
        self._seams = (ArrayLerp(start.seam_luma.positions, goal.seam_luma.positions),
                       ArrayLerp(start.seam_chroma.positions, goal.seam_chroma.positions))

    def at(self, weight: float) -> PlaneMaps:
        luma, chroma = (lerp.at(weight) for lerp in self._seams)
        return replace(self._goal, **{name: lerp.at(weight) for name, lerp in self._arrays.items()},
                       seam_luma=replace(self._goal.seam_luma, positions=luma),
                       seam_chroma=replace(self._goal.seam_chroma, positions=chroma))



def sampled_mask(map_canvas: np.ndarray, plane_shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: where the map's (x, y) has its bilinear footprint inside a plane of ``plane_shape`` (rows, cols)."""
    x, y = map_canvas[:, :, 0], map_canvas[:, :, 1]
    return (x >= 0) & (y >= 0) & (x <= plane_shape[1] - 1) & (y <= plane_shape[0] - 1)


def overlap_lines(maps: PlaneMaps, shape_src: tuple[int, int], shape_tgt: tuple[int, int]) -> np.ndarray:
    """(L, 2) int32: per seam line of the luma plane (a canvas row, or a column for a vertical rig) the
    first and the last position where ``maps`` sample both views, planes of (rows, cols) ``shape_src``
    / ``shape_tgt``; (0, -1) on a line where they sample both nowhere."""
    both = sampled_mask(maps.map_src_luma, shape_src) & sampled_mask(maps.map_tgt_luma, shape_tgt)
    if not maps.seam_luma.lines_are_rows:
        both = both.T
    has = both.any(axis=1)
    first = np.argmax(both, axis=1)
    last = both.shape[1] - 1 - np.argmax(both[:, ::-1], axis=1)
    return np.stack([np.where(has, first, 0), np.where(has, last, -1)], axis=1).astype(np.int32)


def edge_home(overlap: np.ndarray, home: np.ndarray, edge_px: float, most_px: float) -> np.ndarray:
    """(L,) float32 a seam home ``edge_px`` inside the target's side of the ``overlap`` (L, 2) (first, last
    position holding both views per line; the target lies above the seam), changing by at most
    ``most_px`` from one line to the next and nowhere nearer the edge than that (raised where the
    overlap's edge steps). Lines whose overlap is less than half the median's wide (where a view's slanted
    top or bottom border cuts it) do not count: there the home runs on from the lines that do (off the
    overlap the seam picks no view: each pixel shows the view that has it, the target first); ``home``
    where no line has an overlap."""
    width = overlap[:, 1] - overlap[:, 0] + 1
    has = width > 0
    if not has.any():
        return np.asarray(home, np.float32)
    full = width >= 0.5 * np.median(width[has])
    lines = np.arange(len(overlap))
    goal = np.interp(lines, lines[full], (overlap[full, 0] + np.minimum(edge_px, width[full] - 1)).astype(np.float64))
    for k in range(1, len(goal)):  # the lowest home within the bound of its neighbours: raised, never lowered
        goal[k] = max(goal[k], goal[k - 1] - most_px)
    for k in range(len(goal) - 2, -1, -1):
        goal[k] = max(goal[k], goal[k + 1] - most_px)
    return goal.astype(np.float32)


def with_home(key: PlaneMaps, shapes: tuple[tuple[int, int], tuple[int, int]], cfg: Config) -> PlaneMaps:
    """``key`` with its seam's home for a rig of Y ``shapes`` (source, target): where its overlap spans
    ``video_edge_home_share`` or more of the target across the seam (a mostly shared view: a stereo rig,
    two webcams side by side, whose views differ most where things are near), the home is
    ``video_seam_edge_px`` inside the overlap's target-side edge (:func:`edge_home`): the output is the
    target, the source only beyond it, and a near object (a person close to both cameras) is not cut
    between two views whose parallax differs; else the estimate's seam (the paper's)."""
    overlap = overlap_lines(key, *shapes)
    has = overlap[:, 1] >= overlap[:, 0]
    rows = key.seam_luma.lines_are_rows
    across = shapes[1][1] if rows else shapes[1][0]  # the target's extent across the seam
    if not has.any() or np.median(overlap[has, 1] - overlap[has, 0] + 1) < cfg.video_edge_home_share * across:
        return key
    home = edge_home(overlap, key.seam_luma.positions, cfg.video_seam_edge_px, cfg.seam_max_step_px)
    return replace(key, seam_luma=replace(key.seam_luma, positions=home),
                   seam_chroma=replace(key.seam_chroma, positions=chroma_lines(home)))


def seam_change_px(before: PlaneMaps, after: PlaneMaps) -> float:
    """Mean over rows of |seam x after - seam x before| (working frame, px); rows either lacks are skipped."""
    change = np.abs(after.seam_x_working - before.seam_x_working)
    return float(np.nanmean(change)) if np.isfinite(change).any() else 0.0


def map_change_px(before: PlaneMaps, after: PlaneMaps, shape_src: tuple[int, int], percentile: float,
                  shape_tgt: tuple[int, int] | None = None, stride: int = 1) -> float:
    """``percentile`` of |M_s after - M_s before| (source px) over pixels both sample in the source; 0 if none.

    With ``shape_tgt`` (rows, cols of the target Y plane) only the overlap counts: pixels that also
    sample the target. ``stride``: every this-th canvas row and column only (a per-frame figure).
    Per pixel by ``kernels/map_change.py`` on Warp's CPU device, where the maps are; the maps are float32
    (as ``PlaneMaps`` holds them) of one canvas.
    """
    if before.map_src_luma.shape != after.map_src_luma.shape or after.map_tgt_luma.shape != after.map_src_luma.shape:
        raise ValueError("map_change_px: the maps are not of one canvas")
    height, width = before.map_src_luma.shape[:2]
    rows, cols = -(-height // stride), -(-width // stride)
    change = np.empty((rows, cols), np.float32)
    arrays = [host_array(np.ascontiguousarray(m), wp.vec2)
              for m in (before.map_src_luma, after.map_src_luma, after.map_tgt_luma)]
    inputs = [stride, arrays[0], arrays[1], wp.vec3i(*shape_src, 1), arrays[2],
              wp.vec3i(*(shape_tgt or (0, 0)), 1), int(shape_tgt is not None),
              host_array(change, float)]
    runtime.launch_rows(map_change.map_change_kernel, rows, cols, inputs, map_change.DEVICE, runtime.BAND_THREADS)
    counted = change[~np.isnan(change)]
    return float(np.percentile(counted, percentile)) if counted.size else 0.0
