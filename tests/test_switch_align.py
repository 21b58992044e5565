"""switch_align: the source aligned to the target where the panorama switches views, on a real image
whose misalignment is known."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.switch_align import aligned_source_map, seam_side_alpha, shown_labels, switch_pixels, view_weights

CFG = Config(device="cpu")


def canvas_case(img: np.ndarray, shift_x: float, rows_tgt: slice):
    """The image as the target in ``rows_tgt`` (the whole width) and as a source whose step-6 map is off
    by ``shift_x`` (the map samples u + shift: the source shows each point shift_x left of the target);
    a straight seam down x = 256. (map, grey_src, grey_tgt, valid_src, valid_tgt, seam x per row)."""
    height, width = img.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    map_src = np.stack([xs + shift_x, ys], axis=-1)
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32)
    valid_src = (map_src[..., 0] >= 0) & (map_src[..., 0] <= width - 1)
    grey_src = np.where(valid_src, cv2.remap(grey, map_src, None, cv2.INTER_LINEAR), np.nan).astype(np.float32)
    valid_tgt = np.zeros((height, width), bool)
    valid_tgt[rows_tgt] = True
    grey_tgt = np.where(valid_tgt, grey, np.nan).astype(np.float32)
    return map_src, grey_src, grey_tgt, valid_src, valid_tgt, np.full(height, 256.0, np.float32)


def test_a_shifted_source_is_aligned_at_the_seam_and_the_borders_and_kept_far_from_them(udisd_pair):
    """The source off by 4 px: at the seam and next to the target's borders (where the source goes on
    beyond them) the aligned map samples where the target shows (to 0.3 px at the seam, 0.75 px beyond the
    borders, where the target is continued by its edge for the flow); far from every switch it
    is the map as it was."""
    img = udisd_pair[0]
    map_src, *views = canvas_case(img, 4.0, slice(100, 400))
    aligned = aligned_source_map(map_src, *views, CFG)
    ys, xs = np.mgrid[0:512, 0:512].astype(np.float32)
    error = np.hypot(aligned[..., 0] - xs, aligned[..., 1] - ys)
    weight_src, weight_tgt = view_weights(seam_side_alpha(views[4], 512), views[2], views[3])
    seam, border = switch_pixels(shown_labels(weight_src, weight_tgt), views[2], views[3])
    assert seam[150:350].any(axis=1).all() and border[99, 300:500].all() and border[400, 300:500].all()
    assert np.median(error[150:350, 250:263]) < 0.3  # at the seam
    assert np.median(error[95:100, 300:440]) < 0.75 and np.median(error[400:405, 300:440]) < 0.75  # beyond the borders
    far = np.hypot(aligned[..., 0] - map_src[..., 0], aligned[..., 1] - map_src[..., 1])
    assert far[200:300, :100].max() < 1e-3  # the source's own side, far from the seam
    assert far[:20, 300:].max() < 1e-3 and far[480:, 300:].max() < 1e-3  # far beyond the borders


def test_the_correction_fades_no_faster_than_its_slope_allows(udisd_pair):
    """A 20 px misalignment fades out over at least 1.875 x 20 / max_slope px: the aligned map never
    stretches the source by more than the slope (and a bit of interpolation)."""
    img = udisd_pair[0]
    map_src, *views = canvas_case(img, 20.0, slice(0, 512))
    aligned = aligned_source_map(map_src, *views, CFG)
    stretch = np.abs(np.diff(aligned[150:350, :, 0] - map_src[150:350, :, 0], axis=1))
    assert np.abs(aligned[250, 256, 0] - 256.0) < 1.0
    assert stretch.max() <= CFG.switch_max_slope + 0.05


def test_misalignment_beyond_the_limit_is_not_followed(udisd_pair):
    """A 100 px misalignment is more than ``switch_max_px``: a local warp that large would fold the
    source, and the map stays as it was."""
    img = udisd_pair[0]
    map_src, *views = canvas_case(img, 100.0, slice(0, 512))
    aligned = aligned_source_map(map_src, *views, CFG)
    assert np.hypot(*(aligned - map_src).transpose(2, 0, 1)).max() < 0.5


@pytest.mark.parametrize("setting", [dict(switch_sigma_px=12.0), dict(switch_fade_px=96.0)])
def test_settings_reach_the_alignment(udisd_pair, setting):
    """A wider smoothing or fade changes the aligned map (both settings are read)."""
    img = udisd_pair[0]
    map_src, *views = canvas_case(img, 4.0, slice(100, 400))
    base = aligned_source_map(map_src, *views, CFG)
    changed = aligned_source_map(map_src, *views, CFG.replace(**setting))
    assert np.abs(changed - base).max() > 0.05
