"""Dense figures of a panorama: misalignment wherever the views switch, what is shown twice
or nowhere, and how faithfully each view's tones come through.

The sparse figures of ``naturalness`` judge the panorama at reliable keypoints, and the seam step at
the rows where the views agree; a kerb stepped by the seam, a pole lost at a view's border or orange
blotches on a brick wall pass between them. These are measured at every pixel. All functions take
plain arrays in the pipeline's working frame on the canvas (``naturalness``'s conventions), so SENA's
variants are measured alike.

* *Shown view* (``switch_align.shown_labels``): per canvas pixel, the view the panorama shows there (the one
  weighing at least a half; none where neither view covers it). A *switch* is a pixel next to one
  showing the other view. It lies on the *seam* where both views are defined on both sides (the
  pipeline chose to switch there), else on a *border*: one view ends (the target's top or bottom
  edge beyond the seam's ends, the warped source's edge inside the target).
* *Flow*: DIS optical flow (OpenCV, medium preset) from the target to the source, on the grey views
  as they enter the panorama (warped, with their gains), over the overlap's bounding box
  (``switch_align.view_flow``); outside its own valid area each view is continued by its nearest
  valid pixel (a line crossing the border continues as a streak, so the flow across it is not pulled
  toward 0 as a fill with the other view would pull it). The target's content at canvas pixel p is
  in the source at p + flow(p). The switches are ``switch_align.switch_pixels``.
* *Misalignment* (px): the part of the flow the image structure shows (:func:`visible_shift`: all
  of it at a corner, the part across the edge on a straight edge, where a shift along the edge
  changes nothing and the flow cannot see it) at the switch's band, where both views are defined
  and both are textured (an edge or corner: :func:`structure`): within T/2 of the seam (T =
  transition width: where the views mix) and within :data:`BORDER_BAND_PX` of a border. Median and
  95th percentile, for the seam and the borders apart (none where fewer than :data:`MIN_BAND_PIXELS`
  band pixels count: a border that is a corner of a few pixels). A misalignment there is a step in
  every line the switch crosses (nothing is blended across a border).
* *Shown twice / nowhere*: the flow gives every textured target pixel of the overlap its source
  copy at p + flow(p), where the flow back from there returns within :data:`CONSISTENT_PX` (the
  views see the same thing: not an occlusion). Copies whose visible shift is more than
  ``naturalness.COINCIDE_PX`` are
  *doubled* when the panorama shows both (each view weighing at least ``naturalness.VISIBLE_WEIGHT``
  at its copy) and *lost* when it shows neither. Per pixel share of the consistent ones, and the
  *objects*: connected regions of such pixels (closed by :data:`OBJECT_CLOSE_PX`) of at least
  :data:`OBJECT_MIN_PX` pixels, the largest of them.
* *Tone fidelity* (%): a panorama made of each view times a gain that varies smoothly over the
  canvas has log(panorama / view) nearly constant within a small block, and the same colour
  everywhere; offsets added to dark pixels, a knee that bends one channel and not another, or gains
  that vary fast make it spread or change colour. Per block of :data:`TONE_BLOCK_PX` square over the
  pixels shown by one view alone (weight at least :data:`PURE_WEIGHT`), with every channel of the
  view and the panorama inside [:data:`TONE_DARK`, :data:`TONE_BRIGHT`] (blocks with at least half
  their pixels so), 100 x the natural log of the ratio per channel: its *spread* (10th to 90th
  percentile) within the block, and the *colour* the block's median gives less the view's usual
  colour (:func:`tone_figures`); the 99th percentile over the blocks of each (a blotch of 1 % of the
  panorama shows). The same figures of the *plain* panorama (each view times its per-channel gains,
  rounded, nothing else) are what a plain gain gives: the floor rounding leaves.
* *White cast* (grey levels): over the pixels whose view is clipped white (every channel at least
  :data:`WHITE_INPUT`) and shown alone, the mean spread between the panorama's largest and smallest
  channel there: a clipped highlight carries no colour, and the panorama must not give it one.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sena_warp.switch_align import bounding_box, extended, view_flow

from . import naturalness

EDGE_GREY_PER_PX = 4.0  # a pixel is textured where each view's gradient energy (7x7) is at least this
TENSOR_BOX_PX = 7  # the structure tensor's window
BORDER_BAND_PX = 6  # misalignment at a border is read this far inside the overlap from it
MIN_BAND_PIXELS = 100  # a switch with fewer textured band pixels than this (a corner) has no figure
FLOW_MARGIN_PX = 16  # the flow runs on the overlap's bounding box widened by this
CONSISTENT_PX = 1.0  # a target pixel's copy is trusted where the flow back returns within this
OBJECT_CLOSE_PX = 3  # doubled / lost pixels this close join one object
OBJECT_MIN_PX = 60  # an object has at least this many doubled (or lost) pixels
PURE_WEIGHT = 0.99  # tone fidelity: pixels where one view weighs at least this
TONE_BLOCK_PX = 12  # tone fidelity: side of the blocks
TONE_DARK, TONE_BRIGHT = 16, 250  # tone fidelity: channel values counted (rounding and clipping aside)
WHITE_INPUT = 250  # white cast: a view pixel with every channel at least this is clipped white


@dataclass(frozen=True)
class Misalignment:
    """|flow| at a switch's band (px): median, 95th percentile, how many band pixels (NaN: none)."""

    median_px: float
    p95_px: float
    pixels: int

    @staticmethod
    def of(values: np.ndarray) -> "Misalignment":
        values = np.asarray(values, np.float64)
        if values.size < MIN_BAND_PIXELS:
            return Misalignment(float("nan"), float("nan"), int(values.size))
        return Misalignment(float(np.median(values)), float(np.percentile(values, 95)), int(values.size))


@dataclass(frozen=True)
class Copies:
    """Dense shown twice / nowhere: shares of the consistent target pixels (%), and the objects."""

    pixels: int  # consistent textured target pixels of the overlap
    doubled_pct: float
    lost_pct: float
    objects: int  # doubled or lost regions of at least OBJECT_MIN_PX pixels
    largest_px: int  # pixels of the largest doubled or lost region (0: none)


def flows(grey_src: np.ndarray, grey_tgt: np.ndarray, valid_src: np.ndarray, valid_tgt: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(src8, tgt8, flow target -> source, flow source -> target) of two grey canvas views (NaN where
    undefined): the views continued past their edges (``switch_align.extended``) and the flows on the
    overlap's bounding box widened by ``FLOW_MARGIN_PX``, DIS medium preset (module docstring)."""
    src8, tgt8 = extended(grey_src, valid_src), extended(grey_tgt, valid_tgt)
    flow, back = view_flow(src8, tgt8, bounding_box(valid_src & valid_tgt, FLOW_MARGIN_PX),
                           cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return src8, tgt8, flow, back


def structure(grey_src: np.ndarray, grey_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(textured (H, W) bool, across (H, W, 2) unit vector, ratio (H, W)) of two grey views on the
    canvas, each continued past its edge (:func:`flows`' src8, tgt8: no edge where a view ends).

    Per view the structure tensor J (Sobel gradients in grey levels per px, summed over
    ``TENSOR_BOX_PX`` square); textured where the square root of each view's larger eigenvalue is at
    least ``EDGE_GREY_PER_PX`` (an edge or a corner with contrast). ``across`` is the larger
    eigenvector of the two views' summed tensor (across the edge) and ``ratio`` its smaller eigenvalue
    over its larger (0 on a straight edge, 1 at a corner)."""
    box = (TENSOR_BOX_PX, TENSOR_BOX_PX)
    tensors, strong = [], []
    for grey in (grey_src, grey_tgt):
        grey = grey.astype(np.float32)
        gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        jxx, jyy, jxy = (cv2.blur(v, box) for v in (gx * gx, gy * gy, gx * gy))
        larger = 0.5 * (jxx + jyy) + np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy ** 2)
        strong.append(larger >= EDGE_GREY_PER_PX**2)
        tensors.append((jxx, jyy, jxy))
    jxx, jyy, jxy = (tensors[0][k] + tensors[1][k] for k in range(3))
    spread = np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy ** 2)
    larger, smaller = 0.5 * (jxx + jyy) + spread, 0.5 * (jxx + jyy) - spread
    angle = 0.5 * np.arctan2(2.0 * jxy, jxx - jyy)
    across = np.stack([np.cos(angle), np.sin(angle)], axis=-1).astype(np.float32)
    return strong[0] & strong[1], across, np.clip(smaller / np.maximum(larger, 1e-6), 0.0, 1.0).astype(np.float32)


def visible_shift(flow: np.ndarray, across: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """(H, W) px: the part of a shift (H, W, 2) the image structure shows, sqrt((f . across)^2 + ratio
    (f . along)^2): all of it at a corner, the part across the edge on a straight edge (a shift along
    an edge changes nothing there, and the flow cannot see it)."""
    normal = flow[..., 0] * across[..., 0] + flow[..., 1] * across[..., 1]
    along = flow[..., 1] * across[..., 0] - flow[..., 0] * across[..., 1]
    return np.sqrt(normal**2 + ratio * along**2)


def misalignment(shift: np.ndarray, seam: np.ndarray, border: np.ndarray, both: np.ndarray, texture_ok: np.ndarray,
                 seam_x: np.ndarray, transition_px: float) -> tuple[Misalignment, Misalignment]:
    """(at the seam, at the borders) from the visible shift (H, W) px (:func:`visible_shift` of the flow)
    at the textured overlap pixels within T/2 of the seam (seam_x (H,) per row, where a row holds a
    seam switch) and within ``BORDER_BAND_PX`` of a border switch (module docstring)."""
    magnitude = shift
    counted = both & texture_ok
    height, width = both.shape
    cols = np.arange(width)[None, :]
    near_seam = (np.abs(cols - np.nan_to_num(np.asarray(seam_x, np.float64), nan=-1e9)[:, None]) <= 0.5 * transition_px)
    near_seam &= seam.any(axis=1)[:, None]
    size = 2 * BORDER_BAND_PX + 1
    near_border = cv2.dilate(border.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))) > 0
    return Misalignment.of(magnitude[near_seam & counted]), Misalignment.of(magnitude[near_border & counted])


def copies(flow: np.ndarray, flow_back: np.ndarray, shift: np.ndarray, weight_src: np.ndarray, weight_tgt: np.ndarray,
           both: np.ndarray, texture_ok: np.ndarray) -> Copies:
    """Shown twice / nowhere from the flows (H, W, 2), the visible shift (H, W) between each target
    pixel's copies (:func:`visible_shift`) and each view's weight in the panorama (module docstring)."""
    height, width = both.shape
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    map_x, map_y = xs + flow[..., 0], ys + flow[..., 1]
    back = cv2.remap(flow_back, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    on_canvas = (map_x >= 0) & (map_x <= width - 1) & (map_y >= 0) & (map_y <= height - 1)
    consistent = both & texture_ok & on_canvas & (np.hypot(*(flow + back).transpose(2, 0, 1)) <= CONSISTENT_PX)
    seen_src = cv2.remap(weight_src.astype(np.float32), map_x, map_y, cv2.INTER_LINEAR) >= naturalness.VISIBLE_WEIGHT
    seen_tgt = weight_tgt >= naturalness.VISIBLE_WEIGHT
    apart = consistent & (shift > naturalness.COINCIDE_PX)
    doubled, lost = apart & seen_src & seen_tgt, apart & ~seen_src & ~seen_tgt
    pixels = int(consistent.sum())
    size = 2 * OBJECT_CLOSE_PX + 1
    joined = cv2.morphologyEx((doubled | lost).astype(np.uint8), cv2.MORPH_CLOSE,
                              cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    count, regions = cv2.connectedComponents(joined, connectivity=8)
    bad_per_region = np.bincount(regions[doubled | lost], minlength=count)[1:]
    objects = bad_per_region[bad_per_region >= OBJECT_MIN_PX]
    return Copies(pixels, 100.0 * doubled.sum() / max(pixels, 1), 100.0 * lost.sum() / max(pixels, 1), int(objects.size),
                  int(objects.max()) if objects.size else 0)


def tone_blocks(pano: np.ndarray, view: np.ndarray, pure: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per counted block (module docstring) of the ``TONE_BLOCK_PX`` grid: (K, C) the 10th-90th
    percentile spread and (K, C) the median of 100 x log(panorama / view) per channel.

    pano, view: (H, W, C) uint8 canvas images (the panorama, the view it shows, before its gains); pure:
    (H, W) bool pixels that view alone is shown at."""
    usable = pure & np.all((view >= TONE_DARK) & (view <= TONE_BRIGHT) & (pano >= TONE_DARK) & (pano <= TONE_BRIGHT),
                           axis=2)
    block = TONE_BLOCK_PX
    height, width = (s - s % block for s in usable.shape)
    channels = view.shape[2]
    if not height or not width:
        return np.zeros((0, channels)), np.zeros((0, channels))
    ratio = 100.0 * (np.log(np.maximum(pano[:height, :width], 1).astype(np.float32))
                     - np.log(np.maximum(view[:height, :width], 1).astype(np.float32)))
    ratio = ratio.reshape(height // block, block, width // block, block, channels).transpose(0, 2, 4, 1, 3)
    ratio = ratio.reshape(height // block, width // block, channels, block * block)
    keep = usable[:height, :width].reshape(height // block, block, width // block, block).transpose(0, 2, 1, 3)
    keep = keep.reshape(height // block, width // block, 1, block * block)
    counted = keep.sum(axis=3)[..., 0] >= block * block / 2
    if not counted.any():
        return np.zeros((0, channels)), np.zeros((0, channels))
    values = np.where(keep, ratio, np.nan)[counted]
    low, mid, high = np.nanpercentile(values, [10, 50, 90], axis=2)
    return high - low, mid


def tone_figures(pano: np.ndarray, views: tuple[np.ndarray, ...], pures: tuple[np.ndarray, ...]) -> tuple[float, float]:
    """(spread, colour) in %, the tone fidelity of a panorama (module docstring; NaN: no block counted).

    pano: (H, W, C) uint8 canvas panorama; views: each view on the canvas (H, W, C) uint8 before its
    gains; pures: per view, (H, W) bool the pixels it alone is shown at. Spread: the 99th percentile
    over every view's blocks of the largest channel's spread within the block. Colour: per view, each
    block's median log ratio less its mean over the channels (the colour it gives), less the view's
    median of that over its blocks (a gain's own tint); the 99th percentile over the blocks of the
    largest channel's |.|."""
    spreads, colours = [], []
    for view, pure in zip(views, pures):
        spread, mid = tone_blocks(pano, view, pure)
        if not len(spread):
            continue
        tint = mid - mid.mean(axis=1, keepdims=True)
        spreads.append(spread.max(axis=1))
        colours.append(np.abs(tint - np.median(tint, axis=0)).max(axis=1))
    if not spreads:
        return float("nan"), float("nan")
    return float(np.percentile(np.concatenate(spreads), 99)), float(np.percentile(np.concatenate(colours), 99))


def white_cast(pano: np.ndarray, view: np.ndarray, pure: np.ndarray) -> float:
    """The white cast (module docstring): mean (max - min channel) of the panorama, grey levels, over the
    pixels shown alone whose view is clipped white; NaN where there are none."""
    white = pure & np.all(view >= WHITE_INPUT, axis=2)
    if not white.any():
        return float("nan")
    values = pano[white].astype(np.float32)
    return float(np.mean(values.max(axis=1) - values.min(axis=1)))
