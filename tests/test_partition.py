"""Step 9, partition and reconstruction: seam per row, alpha, anchors meeting, on synthetic and real canvases."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.canvas import Canvas
from sena_warp.config import Config
from sena_warp.evaluation.metrics import anchor_residuals_px, transition_mad
from sena_warp.imageio import read_image
from sena_warp.partition import (BLEND_COLOUR_MAX, SeamOffsets, border_offsets, past_target_src, seam_maps, seam_offsets,
                                 seam_rows, smooth_curve,
                                 thin_strips)
from sena_warp.seam_path import straight_path
from sena_warp.warp_map import CanvasViews

DEVICE = "cpu"  # the host modules below run their kernels on Config(device=DEVICE)
PAPER = dict(seam_model="paper")  # straight seam, linear anchor correction


def _affine_map(height, width):
    """A smooth step-6-like map: source (x, y) = a mild affine of the canvas pixel."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    return np.stack([0.95 * xs + 0.05 * ys + 4.0, -0.03 * xs + 1.02 * ys - 2.0], -1).astype(np.float32)


def test_seam_rows_interpolate_anchors():
    tgt = np.array([[30.0, 0.0], [40.0, 50.0], [20.0, 99.0]])
    src = tgt + np.array([[1.0, 2.0], [3.0, 6.0], [1.0, 2.0]])
    rows = seam_rows(straight_path(src, tgt, 120), 120, Config(device=DEVICE, **PAPER))
    assert rows.seam_x[25] == pytest.approx(35.0)
    assert rows.seam_x[50] == pytest.approx(40.0)
    assert rows.seam_x[110] == pytest.approx(20.0)  # constant below the last anchor
    assert rows.src_row_y[25] == pytest.approx(25.0 + 4.0)
    assert rows.shift_x[25] == pytest.approx(2.0)


def test_smooth_correction_follows_the_anchors_without_kinks():
    """Ours: a smoothing spline through the anchor residuals, not a polyline with a kink at each anchor.

    Residuals that swing by 4 px between anchors 40 rows apart (far more than real anchors do) are
    followed loosely by the default smoothing, tightly by a light one; both bend far less than the polyline.
    """
    y = np.array([20.0, 60.0, 100.0, 140.0])
    values = np.array([1.0, 3.0, -1.0, 2.0])
    linear = np.interp(np.arange(200), y, values)
    tight = smooth_curve(y, values, 200, 0.3)
    curve = smooth_curve(y, values, 200, Config().correction_smooth)
    assert np.abs(tight[y.astype(int)] - values).max() < 0.15  # measured 0.09 px
    assert np.abs(np.diff(tight, 2)).max() < 0.6 * np.abs(np.diff(linear, 2)).max()  # measured 0.54
    assert np.abs(np.diff(curve, 2)).max() < 0.1 * np.abs(np.diff(linear, 2)).max()  # measured 0.08
    assert np.abs(curve[y.astype(int)] - values).max() < 2.0  # measured 1.84 px at this swing
    assert curve[0] == curve[19] and curve[199] == curve[141]  # constant beyond the ends
    np.testing.assert_array_equal(smooth_curve(np.zeros(0), np.zeros(0), 50, 10.0), np.zeros(50))


def test_seam_offsets_meet_halfway_and_vanish_when_off():
    """Views 110 and 100 by the seam meet halfway: in grey levels with ``seam_blend_gain`` off, in ratio
    with it on, where rows whose views differ by a ratio no exposure explains follow their neighbours."""
    height, width = 60, 100
    src = np.full((height, width, 3), 110, np.uint8)
    tgt = np.full((height, width, 3), 100, np.uint8)
    valid = np.ones((height, width), bool)
    views = CanvasViews(src, tgt, valid, valid)
    offsets = seam_offsets(views, np.full(height, 50.0), 500.0, Config(seam_blend_gain=False))
    np.testing.assert_allclose(offsets.src, -5.0, atol=1e-5)
    np.testing.assert_allclose(offsets.tgt, 5.0, atol=1e-5)
    assert offsets.fade_px == pytest.approx(Config().seam_blend_ratio * 500.0)
    relative_src, relative_tgt = seam_offsets(views, np.full(height, 50.0), 500.0, Config()).relative()
    met = np.sqrt(111.0 * 101.0) - 1.0  # as gains the two meet at their geometric mean
    np.testing.assert_allclose(110.0 * (1.0 + relative_src), met, atol=0.05)
    np.testing.assert_allclose(100.0 * (1.0 + relative_tgt), met, atol=0.05)
    src[30:], tgt[30:] = 40, 120  # other content in the lower half: a ratio of 3 is not an exposure
    relative_src, _ = seam_offsets(CanvasViews(src, tgt, valid, valid), np.full(height, 50.0), 500.0, Config()).relative()
    np.testing.assert_allclose(relative_src[45:], relative_src[:15], atol=1e-6)
    off = seam_offsets(views, np.full(height, 50.0), 500.0, Config(seam_blend_ratio=0.0))
    assert np.all(off.src == 0) and np.all(off.tgt == 0) and off.fade_px == 0


def test_seam_offsets_as_a_gain_are_relative_to_the_level_they_were_measured_at_per_channel_or_grey():
    """A source brighter than the target by (20, 10, 0) levels per channel at levels 120 / 110 / 100:
    with ``seam_blend_gain`` each side moves half way in ratio; per channel with ``seam_blend_colour``
    (each channel meets the other view's at the geometric mean), else the same gain in every channel
    (the grey levels 110 and 100 meet near 105); without ``seam_blend_gain``, per channel in grey levels."""
    height, width = 60, 100
    src = np.tile(np.uint8([120, 110, 100]), (height, width, 1))
    tgt = np.tile(np.uint8([100, 100, 100]), (height, width, 1))
    valid = np.ones((height, width), bool)
    views = CanvasViews(src, tgt, valid, valid)
    relative_src, relative_tgt = seam_offsets(views, np.full(height, 50.0), 500.0, Config()).relative()
    met = np.sqrt(np.float32([121.0, 111.0, 101.0]) * 101.0) - 1.0
    np.testing.assert_allclose(np.float32([120, 110, 100]) * (1.0 + relative_src), met[None, :].repeat(height, 0), atol=0.1)
    np.testing.assert_allclose(100.0 * (1.0 + relative_tgt), met[None, :].repeat(height, 0), atol=0.1)
    offsets = seam_offsets(views, np.full(height, 50.0), 500.0, Config(seam_blend_colour=False))
    np.testing.assert_allclose(offsets.src, -5.0, atol=0.1)
    np.testing.assert_allclose(offsets.tgt, 5.0, atol=0.2)
    relative_src, relative_tgt = offsets.relative()
    assert np.ptp(relative_src) < 1e-6 and np.ptp(relative_tgt) < 1e-6  # one gain for all channels
    np.testing.assert_allclose(110.0 * (1.0 + relative_src), 100.0 * (1.0 + relative_tgt), atol=0.1)
    per_channel = seam_offsets(views, np.full(height, 50.0), 500.0, Config(seam_blend_gain=False))
    np.testing.assert_allclose(per_channel.src[0], [-10.0, -5.0, 0.0], atol=1e-4)


def test_a_colour_difference_at_the_seam_is_blended_only_up_to_its_limit():
    """Blue 60 % stronger in the source than in the target while green and red agree: the seam blend
    takes the grey ratio and each channel at most ``BLEND_COLOUR_MAX`` (in log) away from it, so a
    colour the views disagree about that much (other content) is not spread over the panorama."""
    height, width = 60, 100
    src = np.tile(np.uint8([160, 100, 100]), (height, width, 1))
    tgt = np.full((height, width, 3), 100, np.uint8)
    valid = np.ones((height, width), bool)
    relative_src, relative_tgt = seam_offsets(CanvasViews(src, tgt, valid, valid), np.full(height, 50.0), 500.0,
                                              Config()).relative()
    grey = np.log(121.0 / 101.0)
    blended = np.log((1.0 + relative_tgt) / (1.0 + relative_src))  # the log ratio the blend takes off
    np.testing.assert_allclose(blended[:, 0], grey + BLEND_COLOUR_MAX, atol=1e-3)
    np.testing.assert_allclose(blended[:, 1:], grey - BLEND_COLOUR_MAX, atol=1e-3)


def test_seam_maps_alpha_and_target_map():
    canvas = Canvas(width=120, height=100, offset_tgt=(30.0, 4.0))
    tgt = np.array([[50.0, 0.0], [70.0, 60.0], [60.0, 99.0]])
    cfg = Config(device=DEVICE, transition_px=20, seam_smooth_sigma_px=0.0, **PAPER)
    maps = seam_maps(_affine_map(100, 120), canvas, straight_path(tgt, tgt, 100), cfg)
    np.testing.assert_allclose(maps.seam_x_canvas, np.interp(np.arange(100), tgt[:, 1], tgt[:, 0]), atol=1e-4)
    xs = np.arange(120)
    for y in (0, 30, 60, 80):
        s = maps.seam_x_canvas[y]
        alpha = maps.alpha_canvas[y]
        assert np.all(alpha[xs <= s - 10] == 1.0) and np.all(alpha[xs >= s + 10] == 0.0)
        ramp = np.abs(xs - s) < 10
        np.testing.assert_allclose(alpha[ramp], 0.5 - (xs[ramp] - s) / 20, atol=1e-6)
    ys, xs2 = np.mgrid[0:100, 0:120]
    np.testing.assert_allclose(maps.map_tgt_canvas, np.stack([xs2 - 30.0, ys - 4.0], -1))
    # no residual between anchors: the source map is the step-6 map untouched
    np.testing.assert_allclose(maps.map_src_canvas, _affine_map(100, 120), atol=1e-4)


def test_smoothing_only_near_the_ramp_ends():
    canvas = Canvas(width=120, height=10, offset_tgt=(0.0, 0.0))
    tgt = np.array([[60.0, 0.0], [60.0, 9.0]])
    cfg = Config(device=DEVICE, transition_px=20, seam_smooth_sigma_px=1.5, **PAPER)
    alpha = seam_maps(_affine_map(10, 120), canvas, straight_path(tgt, tgt, 10), cfg).alpha_canvas[5]
    plain = np.clip(0.5 - (np.arange(120) - 60.0) / 20, 0, 1)
    assert np.abs(alpha - plain).max() > 0.01  # the corners are rounded
    far = np.abs(np.abs(np.arange(120) - 60.0) - 10) > 6  # > 4 sigma from both ramp ends
    np.testing.assert_allclose(alpha[far], plain[far], atol=1e-5)
    k = np.arange(60)
    np.testing.assert_allclose(alpha[60 + k] + alpha[60 - k], 1.0, atol=1e-5)  # odd about the seam
    assert np.all(np.diff(alpha) <= 1e-7)


def test_vertical_offset_anchors_meet_and_far_source_keeps_its_shape():
    height, width = 160, 200
    canvas = Canvas(width=width, height=height, offset_tgt=(60.0, 0.0))
    map_before = _affine_map(height, width)
    tgt = np.array([[120.0, 5.0], [126.3, 40.2], [118.7, 90.6], [123.0, 150.0]])
    src = tgt + np.array([[0.5, 3.0], [0.8, 4.5], [-1.2, 2.5], [0.0, 3.5]])
    cfg = Config(device=DEVICE, transition_px=24, seam_fade_px=40.0, **PAPER)
    maps = seam_maps(map_before, canvas, straight_path(src, tgt, height), cfg)
    residual_before = anchor_residuals_px(map_before, map_before, src, tgt)
    residual_after = anchor_residuals_px(map_before, maps.map_src_canvas, src, tgt)
    assert residual_before.min() > 2.0
    assert residual_after.max() < 0.1
    # source at least T/2 + fade from the seam keeps its step-6 map exactly
    far = np.arange(width)[None, :] < maps.seam_x_canvas[:, None] - 12 - 40
    np.testing.assert_array_equal(maps.map_src_canvas[far], map_before[far])


def test_real_image_shifted_source_meets_target_in_the_transition(bundled_dir):
    """Target = a real image on the canvas; source = the same image moved 3 px down, step-6 map = identity.

    Anchors say the scene point at target (x, y) sits at (x, y + 3) in the warped source; after the
    reconstruction the source equals the target inside the transition band (integer shift: exact).
    """
    grey = cv2.cvtColor(read_image(bundled_dir / "udisd_test_000001" / "a.jpg"), cv2.COLOR_BGR2GRAY)
    height, width = grey.shape
    grey_src = np.zeros_like(grey)
    grey_src[3:] = grey[:-3]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    map_identity = np.stack([xs, ys], -1)
    tgt = np.array([[250.0, 0.0], [262.0, 200.0], [245.0, 511.0]])
    src = tgt + [0.0, 3.0]
    cfg = Config(device=DEVICE, transition_px=24, **PAPER)
    maps = seam_maps(map_identity, Canvas(width, height, (0.0, 0.0)), straight_path(src, tgt, height), cfg)

    def remap(img, m):
        return cv2.remap(img, m[..., 0], m[..., 1], cv2.INTER_LINEAR)

    valid = np.zeros((height, width), bool)
    valid[4 : height - 4] = True
    out_tgt = remap(grey, maps.map_tgt_canvas)
    mad_before = transition_mad(remap(grey_src, map_identity), out_tgt, valid, maps.seam_x_canvas, 24)
    mad_after = transition_mad(remap(grey_src, maps.map_src_canvas), out_tgt, valid, maps.seam_x_canvas, 24)
    assert mad_before > 3.0
    assert mad_after < 0.05
    residual = anchor_residuals_px(map_identity, maps.map_src_canvas, src[1:2], tgt[1:2])
    assert residual[0] < 0.1


def _border_views(img: np.ndarray, oy: int, height_tgt: int, x0: int, tgt: np.ndarray) -> CanvasViews:
    """The source: ``img`` on the whole canvas; the target: ``tgt`` in rows [oy, oy + height_tgt), x >= x0."""
    valid_tgt = np.zeros(img.shape[:2], bool)
    valid_tgt[oy:oy + height_tgt, x0:] = True
    return CanvasViews(img, np.where(valid_tgt[:, :, None], tgt, 0).astype(np.uint8), np.ones(img.shape[:2], bool),
                       valid_tgt)


def test_border_offsets_meet_halfway_across_the_targets_borders_and_leave_other_content_alone(bundled_dir):
    """A real image as both views, the target 10 levels darker inside rows 100-399 right of x 150 and a
    seam at x 120: both borders get half the difference on each side where the source goes on beyond
    them; a target that shows other content there (the image upside down) gets nothing."""
    img = read_image(bundled_dir / "udisd_test_000001" / "a.jpg")
    height, width = img.shape[:2]
    cfg = Config(device=DEVICE)
    seam_x = np.full(height, 120.0, np.float32)
    zero = np.zeros((height, 3), np.float32)
    none = SeamOffsets(zero, zero.copy(), 60.0)
    darker = np.clip(img.astype(np.int16) - 10, 0, 255).astype(np.uint8)
    border = border_offsets(_border_views(img, 100, 300, 150, darker), seam_x, none, (150.0, 100.0), 300, cfg)
    assert border.on and border.lines == (99.5, 399.5)
    inside = slice(200, width - 20)
    for k in range(2):
        np.testing.assert_allclose(border.src[k, inside], -5.0, atol=1.0)
        np.testing.assert_allclose(border.tgt[k, inside], 5.0, atol=1.0)
    grey = img.astype(np.float32).mean(axis=2)
    for k, rows in enumerate((slice(100, 112), slice(388, 400))):  # the level each side was measured at
        assert border.level_src[k, inside].mean() == pytest.approx(grey[rows, inside].mean(), abs=2.0)
        assert border.level_tgt[k, inside].mean() == pytest.approx(grey[rows, inside].mean() - 10.0, abs=2.0)
    other = border_offsets(_border_views(img, 100, 300, 150, img[::-1]), seam_x, none, (150.0, 100.0), 300, cfg)
    assert np.abs(other.src).max() == 0 and np.abs(other.tgt).max() == 0
    off = border_offsets(_border_views(img, 100, 300, 150, darker), seam_x, none, (150.0, 100.0), 300,
                         cfg.replace(border_blend=False))
    assert not off.on and np.abs(off.tgt).max() == 0


def test_border_offsets_take_a_colour_difference_per_channel_or_as_grey(bundled_dir):
    """The target's blue 8 levels lower inside rows 100-399 right of x 150: with ``seam_blend_colour`` the
    border blend takes half of it off the source's blue alone; without it, a third of that in every
    channel (the grey difference)."""
    img = read_image(bundled_dir / "udisd_test_000001" / "a.jpg")
    height, width = img.shape[:2]
    seam_x = np.full(height, 120.0, np.float32)
    zero = np.zeros((height, 3), np.float32)
    none = SeamOffsets(zero, zero.copy(), 60.0)
    bluer = img.astype(np.int16)
    bluer[:, :, 0] -= 8
    bluer = np.clip(bluer, 0, 255).astype(np.uint8)
    views = _border_views(img, 100, 300, 150, bluer)
    inside = slice(200, width - 20)
    colour = border_offsets(views, seam_x, none, (150.0, 100.0), 300, Config(device=DEVICE))
    grey = border_offsets(views, seam_x, none, (150.0, 100.0), 300, Config(device=DEVICE, seam_blend_colour=False))
    for k in range(2):
        np.testing.assert_allclose(colour.src[k, inside, 0], -4.0, atol=1.0)
        np.testing.assert_allclose(colour.src[k, inside, 1:], 0.0, atol=0.5)
        np.testing.assert_allclose(grey.src[k, inside], -4.0 / 3.0, atol=0.5)


def test_thin_strips_of_either_view_where_the_other_takes_over_are_found():
    """A 100 x 160 canvas: the target shown at rows 20-79, columns 61-139 (right of a seam down x 60), the
    source elsewhere where it goes: left of the seam from row 3 (so the target's 2 rows above it, columns
    40-60, are a thin strip of the target), 5 rows above the target up to column 99 and 20 rows from
    there, 3 rows below it, 4 columns right of it. With 12 px as the limit the 2-row target strip, the
    5-row, 3-row and 4-column source strips are thin; the 20-row part and the source left of the target
    (where nothing takes over) are not."""
    label = np.zeros((100, 160), np.uint8)
    label[15:83, :144] = 1
    label[0:20, 100:144] = 1
    label[20:80, 61:140] = 2
    label[3:15, :61] = 1  # left of the seam the source starts at row 3 ...
    label[0:3, 40:61] = 2  # ... with the target above its top edge there
    thin_src, thin_tgt = thin_strips(label, 12.0)
    assert thin_src[15:20, 61:100].all() and not thin_src[:20, 100:140].any()
    assert thin_src[80:83, 61:140].all() and thin_src[20:80, 140:144].all()
    assert not thin_src[:, :61].any()
    assert thin_src.sum() == 5 * 39 + 3 * 79 + 60 * 4
    assert thin_tgt[0:3, 40:61].all() and thin_tgt.sum() == 3 * 21


def test_the_source_past_the_target_is_kept_along_a_border_only_as_far_as_the_views_agree():
    """A 70 x 200 canvas, the target at rows 20-49, columns 40-179, a seam down x 60.5, the source everywhere
    left of x 190 above the target and, below it, at columns 0-100 and 140-170. Just inside the top border
    the two views show the same texture up to column 122 and other content from 123 (a block start): above
    the target the source is kept up to there; below, the views agree all along but the source stops at
    column 101, so the piece beyond the gap is left out; past the target's far edge it is left out too;
    left of the seam nothing is. With the same texture all along, or a limit no difference exceeds, the
    source above the target is kept up to the far edge; with the texture a pixel off (a fine texture's
    difference spreads, not once smoothed) the same as with it exact, and without the smoothing it all
    goes from the seam on."""
    rng = np.random.default_rng(5)
    texture = rng.integers(40, 216, (70, 200)).astype(np.uint8)
    other = rng.integers(40, 216, (70, 200)).astype(np.uint8)
    valid_tgt = np.zeros((70, 200), bool)
    valid_tgt[20:50, 40:180] = True
    valid_src = np.zeros((70, 200), bool)
    valid_src[:50, :190] = True
    valid_src[50:, :101] = valid_src[50:, 140:171] = True
    grey_src = np.where(np.arange(200)[None, :] < 123, texture, other)
    views = CanvasViews(np.repeat(np.where(valid_src, grey_src, 0)[:, :, None], 3, axis=2),
                        np.repeat(np.where(valid_tgt, texture, 0)[:, :, None], 3, axis=2), valid_src, valid_tgt)
    seam_x = np.full(70, 60.5, np.float32)
    cfg = Config(device=DEVICE)
    left_out = past_target_src(views, seam_x, (40.0, 20.0), (30, 140, 3), cfg)
    expected = np.zeros((70, 200), bool)
    expected[:20, 123:] = True
    expected[20:50, 180:] = True
    expected[50:, 101:] = True
    np.testing.assert_array_equal(left_out, expected)
    agreeing = CanvasViews(np.repeat(np.where(valid_src, texture, 0)[:, :, None], 3, axis=2), views.tgt, valid_src,
                           valid_tgt)  # the same texture all along the top border: kept up to the target's far edge
    left_out = past_target_src(agreeing, seam_x, (40.0, 20.0), (30, 140, 3), cfg)
    assert not left_out[:20, :180].any() and left_out[:20, 180:].all()
    assert not past_target_src(views, seam_x, (40.0, 20.0), (30, 140, 3), cfg.replace(past_target_mad_grey=255.0))[:20, :180].any()
    shifted = np.where(np.arange(200)[None, :] < 123, np.roll(texture, 1, axis=1), other)  # the texture a pixel off
    views = CanvasViews(np.repeat(np.where(valid_src, shifted, 0)[:, :, None], 3, axis=2), views.tgt, valid_src, valid_tgt)
    np.testing.assert_array_equal(past_target_src(views, seam_x, (40.0, 20.0), (30, 140, 3), cfg), expected)
    assert past_target_src(views, seam_x, (40.0, 20.0), (30, 140, 3), cfg.replace(past_target_sigma_px=0.0))[:20, 61:].all()
