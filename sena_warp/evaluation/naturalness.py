"""Figures of a natural panorama: what a viewer sees twice, not at all, stepped or bent.

All functions work in the pipeline's working frame on the canvas (source left of a seam that runs
top to bottom, ``seam_x[y]`` per row) on plain arrays, so that SENA's variants are measured alike.

* *Duplicated / lost points*: every reliable match (below) whose target copy lies in the overlap has
  a source copy and a target copy on the canvas; a copy is *visible* where its view's weight in the
  panorama is at least ``VISIBLE_WEIGHT``. Copies more than ``COINCIDE_PX`` apart are *duplicated*
  when both are visible (the point shows twice, or as a ghost inside the transition) and *lost* when
  neither is.
* *Seam step*: per row, the panorama's mean luma just left of the seam (``STEP_NEAR_PX`` to
  ``STEP_FAR_PX``) minus just right of it, less the scene's own change across those pixels (the mean
  of the same difference in either view alone); averaged over ``STEP_ROWS`` rows (a step is a
  low-frequency thing), its absolute value's mean over the rows. Rows where the two views disagree
  about that change by more than ``STEP_AGREE_GREY`` show different things there (parallax, something
  that moved): a brightness step cannot be told from the content on them, and they are left out (the
  duplicated / lost points and the continuity measure them).
* *Border step*: beyond the seam's ends the panorama switches from the target to the source across
  the target's top or bottom border, where the source goes on beyond it. Per canvas column there, the
  panorama's mean luma ``STEP_NEAR_PX`` to ``STEP_FAR_PX`` rows outside the border minus inside it,
  less the source's own change across those rows (the source is defined on both sides), averaged
  over ``STEP_ROWS`` columns; its absolute value's mean over the columns of both borders.
* *Line bend / continuity*: long straight segments of each input (LSD, at least ``MIN_LINE_PX``)
  mapped to the canvas; a segment the panorama shows from its own view all along gets its bend
  (largest distance from the chord, % of its length); a segment the seam cuts gets its continuity:
  the distance at the cut between it and the other view's copy of the line (the nearly parallel
  segment of the other view that reaches the cut), px. Segments hidden by the other view do not count.

Reliable matches are the pipeline's matches that satisfy the epipolar geometry (a fundamental
matrix by seeded USAC RANSAC, ``EPIPOLAR_PX``), lie within ``MAX_DISPARITY_PX`` of the global affine
and are supported by neighbours that move alike (``features.neighbour_supported``: a wrong match on a
periodic pattern lies on its epipolar line too, a period away): correct correspondences whatever
their depth, which the warp may or may not align.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sena_warp.bilinear import sample_bilinear
from sena_warp.features import neighbour_supported
from sena_warp.switch_align import view_weights  # noqa: F401 - the figures' weights are the stitch's

VISIBLE_WEIGHT = 0.25  # a copy shown at a quarter or more is seen (a ghost in a blend counts)
COINCIDE_PX = 2.0  # copies closer than this are one point
STRICT_PX = 4.0  # the strict threshold: no point duplicated or lost by more than this
EPIPOLAR_PX = 1.0  # fundamental-matrix RANSAC threshold of the reliable matches
EPIPOLAR_SEED = 1  # USAC's random state: the same matches every run
MAX_DISPARITY_PX = 60.0  # reliable matches lie within this of the global affine (wrong ones can sit on an epipolar line)
SUPPORT_NEIGHBOURS, SUPPORT_TOL_PX, SUPPORT_MIN = 8, 3.0, 2  # and at least 2 of their 8 neighbours move alike
STEP_NEAR_PX, STEP_FAR_PX = 3, 10  # the strips either side of the seam that the seam step compares
STEP_ROWS = 16  # rows averaged before the step's absolute value
STEP_AGREE_GREY = 10.0  # rows whose views' own change across the strips differs by more are left out
MIN_LINE_PX = 60.0  # shortest segment of the line figures
MAX_LINES = 80  # the longest this many segments per view are measured
LINE_SAMPLES = 33  # points per segment mapped to the canvas
LINE_VISIBLE = 0.5  # a segment point is shown by its view where that view weighs at least this
PARTNER_ANGLE_DEG = 4.0  # the other view's copy of a cut line is within this angle ...
PARTNER_GAP_PX = 12.0  # ... and this distance of the cut


@dataclass(frozen=True)
class CopyFigures:
    """Duplicated / lost points of one panorama: counts over the reliable matches in the overlap."""

    points: int
    duplicated: int  # both copies visible, more than COINCIDE_PX apart
    lost: int  # neither copy visible, more than COINCIDE_PX apart
    over_strict: int  # duplicated or lost by more than STRICT_PX
    worst_px: float  # largest distance between the copies of a duplicated or lost point (0: none)

    @property
    def share_pct(self) -> float:
        """Duplicated or lost points, % of the overlap's reliable points."""
        return 100.0 * (self.duplicated + self.lost) / max(self.points, 1)


def reliable_matches(pts_src: np.ndarray, pts_tgt: np.ndarray, affine_src_to_tgt: np.ndarray) -> np.ndarray:
    """(N,) bool over matched (N, 2) source / target points: epipolar inliers near the global affine."""
    pts_src = np.asarray(pts_src, np.float64)
    pts_tgt = np.asarray(pts_tgt, np.float64)
    keep = np.zeros(len(pts_src), bool)
    if len(pts_src) < 8:
        return keep
    params = cv2.UsacParams()
    params.threshold, params.confidence, params.maxIterations = EPIPOLAR_PX, 0.999, 5000
    params.randomGeneratorState = EPIPOLAR_SEED
    _, mask = cv2.findFundamentalMat(pts_src, pts_tgt, params)
    if mask is None:
        return keep
    predicted = pts_src @ np.asarray(affine_src_to_tgt)[:, :2].T + np.asarray(affine_src_to_tgt)[:, 2]
    supported = neighbour_supported(pts_src, pts_tgt, SUPPORT_NEIGHBOURS, SUPPORT_TOL_PX, SUPPORT_MIN)
    return mask.ravel().astype(bool) & (np.hypot(*(predicted - pts_tgt).T) <= MAX_DISPARITY_PX) & supported


def copy_figures(copies_src_canvas: np.ndarray, copies_tgt_canvas: np.ndarray, weight_src: np.ndarray,
                 weight_tgt: np.ndarray, overlap_canvas: np.ndarray) -> CopyFigures:
    """Duplicated / lost points from each match's two copies (N, 2) canvas (x, y) (NaN: undefined)."""
    distance = np.hypot(*(np.asarray(copies_src_canvas) - np.asarray(copies_tgt_canvas)).T)
    in_overlap = sample_bilinear(overlap_canvas.astype(np.float32), copies_tgt_canvas) > 0.5
    counted = np.isfinite(distance) & in_overlap
    seen_src = sample_bilinear(weight_src, copies_src_canvas) >= VISIBLE_WEIGHT
    seen_tgt = sample_bilinear(weight_tgt, copies_tgt_canvas) >= VISIBLE_WEIGHT
    apart = counted & (distance > COINCIDE_PX)
    duplicated, lost = apart & seen_src & seen_tgt, apart & ~seen_src & ~seen_tgt
    bad = duplicated | lost
    return CopyFigures(points=int(counted.sum()), duplicated=int(duplicated.sum()), lost=int(lost.sum()),
                       over_strict=int((bad & (distance > STRICT_PX)).sum()),
                       worst_px=float(distance[bad].max()) if bad.any() else 0.0)


def seam_steps(pano_grey: np.ndarray, src_grey: np.ndarray, tgt_grey: np.ndarray, valid_src: np.ndarray,
               valid_tgt: np.ndarray, seam_x: np.ndarray, one_view: bool = False) -> np.ndarray:
    """The signed seam step of each row, averaged over ``STEP_ROWS`` rows (module docstring): (H,) float64
    grey levels, NaN where a row or too many of its neighbours lack both views on both strips or have
    views that disagree about the scene's own change there (``STEP_AGREE_GREY``).

    Arguments as :func:`seam_step`. A positive step: the panorama is brighter just left of the seam
    than the views' own change explains. ``one_view``: a row where only one view covers both strips
    counts too, with that view's own change (a seam at the overlap's edge, where the view beyond it
    goes on alone: as the border step reads a view's border).
    """
    height, width = pano_grey.shape
    offsets = np.arange(STEP_NEAR_PX, STEP_FAR_PX + 1)
    seam_x = np.asarray(seam_x, np.float64)
    finite = np.isfinite(seam_x)
    at = np.where(finite, seam_x, 0.0)[:, None]
    left, right = np.floor(at - offsets).astype(int), np.ceil(at + offsets).astype(int)
    known = finite & (left.min(axis=1) >= 0) & (right.max(axis=1) < width)
    left, right = np.clip(left, 0, width - 1), np.clip(right, 0, width - 1)
    rows = np.arange(height)[:, None]
    on_src, on_tgt = (np.asarray(v)[rows, left].all(axis=1) & np.asarray(v)[rows, right].all(axis=1)
                      for v in (valid_src, valid_tgt))

    def across(img: np.ndarray) -> np.ndarray:
        return img[rows, left].mean(axis=1) - img[rows, right].mean(axis=1)

    change_src, change_tgt = across(src_grey), across(tgt_grey)
    both = on_src & on_tgt
    agree = both & (np.abs(change_src - change_tgt) <= STEP_AGREE_GREY)
    known &= (agree | (on_src ^ on_tgt)) if one_view else agree
    change = np.where(both, 0.5 * (change_src + change_tgt), np.where(on_src, change_src, change_tgt))
    steps = np.where(known, across(pano_grey) - change, 0.0)
    window = np.ones(STEP_ROWS)
    total = np.convolve(steps, window, "same")
    count = np.convolve(known.astype(np.float64), window, "same")
    kept = known & (count >= STEP_ROWS / 2)
    return np.where(kept, total / np.maximum(count, 1.0), np.nan)


def seam_step(pano_grey: np.ndarray, src_grey: np.ndarray, tgt_grey: np.ndarray, valid_src: np.ndarray,
              valid_tgt: np.ndarray, seam_x: np.ndarray) -> float:
    """The seam step in grey levels (module docstring): the mean of |:func:`seam_steps`| over the rows
    where it is defined; NaN when no row has both views on both strips.

    pano_grey, src_grey, tgt_grey: (H, W) float canvas images (the panorama, each view as it enters the
    panorama: warped, gain-compensated); valid_*: (H, W) bool; seam_x: (H,) seam x per row.
    """
    steps = seam_steps(pano_grey, src_grey, tgt_grey, valid_src, valid_tgt, seam_x)
    known = np.isfinite(steps)
    return float(np.mean(np.abs(steps[known]))) if known.any() else float("nan")


def _across(img: np.ndarray, outside: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Per column, the mean of ``img`` over the rows ``outside`` a border minus that over the rows ``inside``."""
    return img[outside].mean(axis=0) - img[inside].mean(axis=0)


def border_step(pano_grey: np.ndarray, src_grey: np.ndarray, valid_src: np.ndarray, weight_tgt: np.ndarray,
                borders: tuple[float, float]) -> float:
    """The border step in grey levels (module docstring); NaN where no column switches views across a border.

    pano_grey, src_grey: (H, W) float canvas images (the panorama, the source as it enters it);
    valid_src: (H, W) bool; weight_tgt: (H, W) the target's weight in the panorama; borders: the y of
    the target's top and bottom borders (half-integers between its edge rows and the rows beyond).
    """
    height, width = pano_grey.shape
    offsets = np.arange(STEP_NEAR_PX, STEP_FAR_PX + 1) - 0.5
    steps = []
    for border, outward in zip(borders, (-1.0, 1.0)):
        outside = np.rint(border + outward * offsets).astype(int)
        inside = np.rint(border - outward * offsets).astype(int)
        if min(outside.min(), inside.min()) < 0 or max(outside.max(), inside.max()) >= height:
            continue
        switch = (valid_src[outside].all(axis=0) & valid_src[inside].all(axis=0)
                  & (weight_tgt[inside] >= 0.5).all(axis=0) & (weight_tgt[outside] == 0).all(axis=0))

        step = np.where(switch, _across(pano_grey, outside, inside) - _across(src_grey, outside, inside), 0.0)
        window = np.ones(STEP_ROWS)
        count = np.convolve(switch.astype(np.float64), window, "same")
        kept = switch & (count >= STEP_ROWS / 2)
        steps.append((np.convolve(step, window, "same") / np.maximum(count, 1.0))[kept])
    steps = np.concatenate(steps) if steps else np.zeros(0)
    return float(np.mean(np.abs(steps))) if steps.size else float("nan")


def line_segments(img: np.ndarray) -> np.ndarray:
    """(K, 2, 2) float64 LSD segments of a BGR or grey uint8 image at least MIN_LINE_PX long, longest first."""
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
    found = cv2.createLineSegmentDetector().detect(grey)[0]
    if found is None:
        return np.zeros((0, 2, 2))
    segments = found.reshape(-1, 2, 2).astype(np.float64)
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    order = np.argsort(-length)
    return segments[order][length[order] >= MIN_LINE_PX][:MAX_LINES]


def _mapped(segments: np.ndarray, forward, weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment points on the canvas (K, LINE_SAMPLES, 2) and whether their own view shows them (K, LINE_SAMPLES)."""
    t = np.linspace(0.0, 1.0, LINE_SAMPLES)[None, :, None]
    pts = segments[:, :1] + t * (segments[:, 1:] - segments[:, :1])
    mapped = forward(pts.reshape(-1, 2)).reshape(pts.shape)
    shown = (sample_bilinear(weight, mapped.reshape(-1, 2)) >= LINE_VISIBLE).reshape(pts.shape[:2])
    return mapped, shown & np.isfinite(mapped).all(axis=2)


def _direction(points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    finite = points[np.isfinite(points).all(axis=1)]
    if len(finite) < 2:
        return None
    d = finite[-1] - finite[0]
    return finite[0], d / max(np.linalg.norm(d), 1e-12)


def line_figures(segments_src: np.ndarray, forward_src, weight_src: np.ndarray,
                 segments_tgt: np.ndarray, forward_tgt, weight_tgt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(bend % of every segment shown whole by its view, continuity px of every cut segment with a partner).

    segments_*: (K, 2, 2) input-frame segments of each view; forward_*: (N, 2) view pixels -> canvas
    (x, y) (NaN where undefined); weight_*: (H, W) each view's weight in the panorama.
    """
    views = [_mapped(segments_src, forward_src, weight_src), _mapped(segments_tgt, forward_tgt, weight_tgt)]
    bends, continuity = [], []
    for own, other in ((0, 1), (1, 0)):
        mapped, shown = views[own]
        other_mapped, other_shown = views[other]
        other_lines = [_direction(m) for m in other_mapped]
        for points, seen in zip(mapped, shown):
            if seen.all():
                chord = points[-1] - points[0]
                length = np.linalg.norm(chord)
                rel = points - points[0]
                bends.append(100.0 * np.max(np.abs(rel[:, 0] * chord[1] - rel[:, 1] * chord[0])) / length**2)
                continue
            if not seen.any() or (line := _direction(points)) is None:
                continue
            switch = int(np.flatnonzero(seen[1:] != seen[:-1])[0])
            cut = points[switch] if seen[switch] else points[switch + 1]
            best = None
            for partner, partner_pts, partner_seen in zip(other_lines, other_mapped, other_shown):
                if partner is None or not partner_seen.any() or abs(line[1] @ partner[1]) < np.cos(np.radians(PARTNER_ANGLE_DEG)):
                    continue
                normal = np.array([-partner[1][1], partner[1][0]])
                gap = abs((cut - partner[0]) @ normal)
                reach = np.min(np.linalg.norm(partner_pts[partner_seen] - cut, axis=1))
                if gap <= PARTNER_GAP_PX and reach <= 3 * PARTNER_GAP_PX and (best is None or gap < best):
                    best = gap
            if best is not None:
                continuity.append(best)
    return np.asarray(bends), np.asarray(continuity)
