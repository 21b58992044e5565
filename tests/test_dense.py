"""evaluation.dense: the dense figures on crafted panoramas of a real image whose answers are known."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.evaluation import dense, naturalness
from sena_warp.switch_align import shown_labels, switch_pixels


def shifted(img: np.ndarray, dx: float) -> np.ndarray:
    """``img`` moved right by dx px (bilinear, edge replicated): its content at x is at x + dx."""
    affine = np.float32([[1, 0, dx], [0, 1, 0]])
    return cv2.warpAffine(img, affine, img.shape[1::-1], flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def panorama(src: np.ndarray, tgt: np.ndarray, seam_x: float, rows_tgt: slice, transition_px: float = 8.0):
    """A stitch of two canvas views: the source everywhere, the target inside ``rows_tgt`` right of a
    straight seam, a linear ramp across it; (pano, weight_src, weight_tgt, valid_src, valid_tgt, seam_x per row)."""
    height, width = src.shape[:2]
    valid_src = np.ones((height, width), bool)
    valid_tgt = np.zeros((height, width), bool)
    valid_tgt[rows_tgt] = True
    alpha = np.clip(0.5 - (np.arange(width)[None, :] - seam_x) / transition_px, 0, 1) * np.ones((height, 1))
    weight_src, weight_tgt = naturalness.view_weights(alpha, valid_src, valid_tgt)
    pano = weight_src[:, :, None] * src + weight_tgt[:, :, None] * tgt.astype(np.float32)
    return pano, weight_src, weight_tgt, valid_src, valid_tgt, np.full(height, seam_x)


def figures(src: np.ndarray, tgt: np.ndarray, rows_tgt: slice = slice(100, 400), true_shift=(0.0, 0.0)):
    """(seam, border, misalignment at the seam, at the borders, copies, the misalignments the true
    shift of tgt against src gives at the same pixels)."""
    grey_src, grey_tgt = (cv2.cvtColor(v, cv2.COLOR_BGR2GRAY).astype(np.float32) for v in (src, tgt))
    _, weight_src, weight_tgt, valid_src, valid_tgt, seam_x = panorama(src, tgt, 256.0, rows_tgt)
    grey_tgt = np.where(valid_tgt, grey_tgt, np.nan)
    seam, border = switch_pixels(shown_labels(weight_src, weight_tgt), valid_src, valid_tgt)
    src8, tgt8, flow, back = dense.flows(grey_src, grey_tgt, valid_src, valid_tgt)
    texture_ok, across, ratio = dense.structure(src8, tgt8)
    shift = dense.visible_shift(flow, across, ratio)
    both = valid_src & valid_tgt
    at_seam, at_border = dense.misalignment(shift, seam, border, both, texture_ok, seam_x, 8.0)
    truth = dense.visible_shift(np.broadcast_to(np.float32(true_shift), flow.shape), across, ratio)
    return (seam, border, at_seam, at_border, dense.copies(flow, back, shift, weight_src, weight_tgt, both, texture_ok),
            dense.misalignment(truth, seam, border, both, texture_ok, seam_x, 8.0))


def test_switches_split_the_seam_from_the_targets_borders(udisd_pair):
    """The seam runs down x = 256 between rows 100 and 399; the target's borders at rows 99.5 and 399.5
    switch to the source right of it; nothing switches where the source is shown on both sides."""
    seam, border, *_ = figures(udisd_pair[0], udisd_pair[0])
    rows, cols = np.nonzero(seam)
    assert rows.min() >= 100 and rows.max() <= 399 and set(cols) == {256, 257}
    rows, cols = np.nonzero(border)
    assert set(rows) == {99, 100, 399, 400} and cols.min() >= 255


@pytest.mark.parametrize("dx", [0.0, 3.0])
def test_misalignment_is_the_shift_between_the_views(udisd_pair, dx):
    """The target is the source moved right by dx: at the seam's band and at the borders the figure
    reads what that shift shows (dx at a corner, dx times the cosine across an edge) to 0.3 px."""
    src = udisd_pair[0]
    _, _, at_seam, at_border, _, (true_seam, true_border) = figures(src, shifted(src, dx), true_shift=(-dx, 0.0))
    assert at_seam.pixels > 500 and at_border.pixels > 500
    for found, truth in ((at_seam, true_seam), (at_border, true_border)):
        assert found.pixels == truth.pixels
        assert found.median_px == pytest.approx(truth.median_px, abs=0.3)
        assert found.p95_px == pytest.approx(truth.p95_px, abs=0.5)
    assert true_seam.p95_px == pytest.approx(dx, abs=0.01)


def test_a_shift_across_the_seam_is_doubled_one_way_and_lost_the_other(udisd_pair):
    """The source's copy of every point 12 px right of its target copy: the points just left of the seam
    are shown by neither view (a strip lost all down the seam: 12 px less the 4 px where the transition
    shows both at a quarter or more); 12 px left of it, those just right are shown by both (doubled).
    Aligned views show each point once."""
    src = udisd_pair[0]
    lost, doubled, aligned = (figures(src, shifted(src, dx))[4] for dx in (-12.0, 12.0, 0.0))
    for found, share, other in ((lost, lost.lost_pct, lost.doubled_pct), (doubled, doubled.doubled_pct, doubled.lost_pct)):
        assert share > 1.0 and other < 0.2 and found.objects >= 1 and found.largest_px > 1000
    assert aligned.doubled_pct + aligned.lost_pct < 0.1 and aligned.objects == 0


def test_tone_fidelity_sees_offsets_and_not_gains(udisd_pair):
    """A per-channel gain far from 1 keeps log(panorama / view) flat in every block and of one colour: as
    flat as rounding leaves it. A grey offset of 5 levels on top of the same gain over a third of the
    view spreads it on dark texture and tints that third."""
    view = udisd_pair[0]
    pures = (np.ones(view.shape[:2], bool),)
    gain = np.float32([0.9, 0.65, 0.6])
    plain = np.clip(np.rint(view * gain), 0, 255).astype(np.uint8)
    offset = plain.copy()
    offset[:, :170] = np.clip(np.rint(view[:, :170] * gain + 5.0), 0, 255).astype(np.uint8)
    (spread_plain, colour_plain), (spread, colour) = (dense.tone_figures(p, (view,), pures) for p in (plain, offset))
    assert spread_plain < 6.0 and colour_plain < 3.0
    assert spread > spread_plain + 5.0 and colour > colour_plain + 3.0


def test_white_cast_of_a_clipped_highlight():
    """A clipped white region through per-channel gains: a plain gain tints it; kept white, no cast."""
    view = np.full((40, 40, 3), 255, np.uint8)
    pure = np.ones(view.shape[:2], bool)
    tinted = np.clip(np.rint(view * np.float32([0.9, 0.8, 1.1])), 0, 255).astype(np.uint8)
    assert dense.white_cast(tinted, view, pure) == pytest.approx(255 - 204, abs=0.5)
    assert dense.white_cast(view, view, pure) == 0.0
    assert np.isnan(dense.white_cast(view, view // 2, pure))
