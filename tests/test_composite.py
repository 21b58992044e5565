"""The compositing step: plans, frame states, both frame kernels, against a numpy reference.

The reference takes the seam's weights from ``composite.seam_weights`` (the kernels' one rule, itself
checked against its closed form below), samples both views with the host's bilinear rule and applies
each side's gains (with their highlight knee) and offsets in float64.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import warp as wp

from sena_warp.composite import (LEVEL, BorderBlend, FrameArrays, FrameState, SeamLayout, band_difference, band_words,
                                 clipped_seam, composite_image, composite_plan, coverage, kernel_gains, applied_gains,
                                 row_runs, seam_weights, with_runs)
from sena_warp.config import Config
from sena_warp.gains import tone_curve
from sena_warp.kernels import transfer
from sena_warp.kernels.composite import ALPHA_TAIL_SIGMAS, NOT_BOTH, BandCells, BandWord, BandWords
from sena_warp.kernels.seam import source_alpha
from test_kernels_maps import DEVICES
from test_kernels_remap import remap_reference, scene  # noqa: F401  (scene is a fixture)

GAINS = ([1.1, 0.9, 1.0], [-3.0, 2.0, 0.0], [0.95, 1.05, 1.0], [1.0, -1.0, 4.0])
STRONG_GAINS = ([1.1, 0.9, 1.0], [-3.0, 2.0, 0.0], [1.3, 0.8, 1.0], [6.0, -5.0, 4.0])


def layout(scene_arrays, lines_are_rows=True, band_px=12.0, lf_px=40.0, wobble=15.0) -> SeamLayout:
    """A wavy seam down the middle of the scene's canvas (per row, or per column)."""
    _, _, map_src, _, _ = scene_arrays
    height, width = map_src.shape[:2]
    lines, across = (height, width) if lines_are_rows else (width, height)
    positions = 0.5 * across + wobble * np.sin(np.arange(lines) / 17.0)
    return SeamLayout(positions.astype(np.float32), lines_are_rows, band_px, 8.0, 1.5, lf_px)


def plan_for(scene, seam: SeamLayout, cfg: Config, channels: int = 3, **options):  # noqa: F811
    """The scene's plan for images of ``channels`` channels."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    shapes = ((*img_src.shape[:2], channels), (*img_tgt.shape[:2], channels))
    return composite_plan(map_src, map_tgt, seam, shapes, cfg, **options)


def ramp_offsets(lines: int, channels: int = 3) -> tuple[np.ndarray, np.ndarray]:
    ramp = np.linspace(-6, 6, lines, dtype=np.float32)[:, None]
    src, tgt = np.hstack([ramp, -ramp, ramp * 0]), np.hstack([-ramp, ramp, ramp * 0 + 2])
    return src[:, :channels], tgt[:, :channels]


def reference(plan, state: FrameState, img_src, img_tgt, map_src, map_tgt, cfg: Config):
    """(values (Hc, Wc, C) float64, covered (Hc, Wc) bool) of the compositing rule for ``state`` on
    ``plan`` (its border blend included), the gains and offsets as the kernels hold them."""
    img_src = img_src if img_src.ndim == 3 else img_src[:, :, None]
    img_tgt = img_tgt if img_tgt.ndim == 3 else img_tgt[:, :, None]
    channels = img_src.shape[2]
    v_src, ok_src = remap_reference(img_src, map_src)
    v_tgt, ok_tgt = remap_reference(img_tgt, map_tgt)
    alpha, lf = seam_weights(state.seam, plan.layout, plan.canvas_shape, cfg)
    gain_src, bias_src, gain_tgt, bias_tgt = applied_gains(
        kernel_gains(state.gains, channels, plan.tone, wp.empty(1, dtype=wp.uint8, device="cpu")), channels)
    offsets = state.offsets if state.offsets is not None else (np.zeros((plan.lines, channels)),) * 2
    off_src, off_tgt = (np.rint(np.asarray(v, np.float64) * LEVEL) / LEVEL for v in offsets)
    rows = plan.layout.lines_are_rows
    off_src, off_tgt = (o[:, None, :] if rows else o[None, :, :] for o in (off_src, off_tgt))
    knee, white = plan.knee or (math.inf, math.inf)
    total_src, total_tgt = lf[..., None] * off_src, lf[..., None] * off_tgt
    border = plan.border_source
    if border is not None:
        height, width = alpha.shape
        line = np.arange(height)[:, None] if rows else np.arange(width)[None, :]
        for k in range(2):
            weight = np.clip(1 - np.abs(line - border.lines[k]) / plan.layout.lf_px, 0, None)[..., None]
            along_src, along_tgt = (b[k][None, :, :] if rows else b[k][:, None, :] for b in (border.src, border.tgt))
            total_src, total_tgt = total_src + weight * along_src, total_tgt + weight * along_tgt
    shared = plan.knee_peak
    if state.relative_offsets:  # a relative change of the gain, before the knee
        src = tone_curve(v_src, gain_src * (1 + total_src), bias_src, knee, white, shared)
        tgt = tone_curve(v_tgt, gain_tgt * (1 + total_tgt), bias_tgt, knee, white, shared)
    else:
        src = tone_curve(v_src, gain_src, bias_src, knee, white, shared) + total_src
        tgt = tone_curve(v_tgt, gain_tgt, bias_tgt, knee, white, shared) + total_tgt
    a = np.where(ok_src, np.where(ok_tgt, alpha, 1.0), 0.0)[..., None]
    covered = ok_src | ok_tgt
    return np.where(covered[..., None], np.clip(a * src + (1 - a) * tgt, 0, 255), 0.0), covered


def test_seam_weights_follow_the_smoothed_ramp(scene, warp_device):  # noqa: F811
    """The source weight is the linear ramp across T convolved with a Gaussian of sigma (closed form)."""
    _, _, map_src, _, _ = scene
    seam = layout(scene)
    alpha, lf = seam_weights(seam.positions, seam, map_src.shape[:2], Config(device=warp_device))
    y = 40
    d = np.arange(map_src.shape[1]) - seam.positions[y]
    t, s, half = seam.transition_px, seam.smooth_sigma_px, 0.5 * seam.transition_px
    phi = lambda z: 0.5 * (1 + np.vectorize(math.erf)(z / (s * math.sqrt(2))))  # noqa: E731
    pdf = lambda z: np.exp(-0.5 * (z / s) ** 2) / math.sqrt(2 * math.pi)  # noqa: E731
    part = lambda z: z * phi(z) + s * pdf(z)  # noqa: E731
    expected = np.clip((part(half - d) - part(-half - d)) / t, 0, 1)
    np.testing.assert_allclose(alpha[y], expected, atol=1e-5)
    np.testing.assert_allclose(lf[y], np.clip(1 - np.abs(d) / seam.lf_px, 0, None), atol=1e-6)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("lines_are_rows", [True, False])
def test_composite_matches_reference_with_gains_and_offsets(scene, device, lines_are_rows, warp_device):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=device, cpu_threads=2)
    seam = layout(scene, lines_are_rows)
    plan = plan_for(scene, seam, cfg)
    state = FrameState(seam.positions, GAINS, ramp_offsets(plan.lines))
    out = composite_image(img_src, img_tgt, plan, state, cfg)
    expected, covered = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
    assert out.shape == (*map_src.shape[:2], 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(coverage(plan), np.where(covered, 255, 0))
    assert np.abs(out.astype(np.float64) - expected).max() <= 1.0
    assert 0.3 < covered.mean() < 1.0


@pytest.mark.parametrize("lines_are_rows", [True, False])
@pytest.mark.parametrize("channels", [1, 2, 3])
def test_both_frame_kernels_give_the_same_planes(scene, lines_are_rows, channels, warp_device):  # noqa: F811
    """The per-pixel kernel (CUDA's) and the row-run kernel (the CPU's, with its runs) give the same
    pixels, with gains, knee, seam and border offsets all in play."""
    img_src, img_tgt, map_src, _, _ = scene
    cfg = Config(device=warp_device, cpu_threads=2)
    seam = layout(scene, lines_are_rows, band_px=20.0)
    positions = map_src.shape[1] if lines_are_rows else map_src.shape[0]
    along = np.linspace(-9, 9, positions, dtype=np.float32)[:, None] * np.array([1.0, -0.5, 0.25], np.float32)
    border = BorderBlend((10.5, len(seam.positions) - 20.5), np.stack([along, -along])[:, :, :channels],
                         np.stack([-along, 2 * along + 3])[:, :, :channels])
    plan = with_runs(plan_for(scene, seam, cfg, channels, border=border), cfg)
    state = FrameState(clipped_seam(seam.positions + 5.0, seam), tuple(np.asarray(g)[:channels] for g in STRONG_GAINS),
                       ramp_offsets(plan.lines, channels))
    pair = [np.ascontiguousarray(img[:, :, :channels]) for img in (img_src, img_tgt)]
    rows = composite_image(*pair, plan, state, cfg, per_pixel=False)
    pixels = composite_image(*pair, plan, state, cfg, per_pixel=True)
    np.testing.assert_array_equal(rows, pixels)
    assert (row_runs(plan, state.seam, cfg)[:, [1, 4]] > 0).mean() > 0.5  # the runs were there to take


def test_border_offsets_fade_from_both_borders_on_each_side(scene, warp_device):  # noqa: F811
    """The border blend adds each side's offsets per position along the two borders, fading over lf_px
    across them, on top of the seam's offsets (the reference adds them in float64)."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device, cpu_threads=2)
    for lines_are_rows in (True, False):
        seam = layout(scene, lines_are_rows)
        lines = len(seam.positions)
        state = FrameState(seam.positions, GAINS, ramp_offsets(lines))
        positions = map_src.shape[1] if lines_are_rows else map_src.shape[0]
        along = np.linspace(-9, 9, positions, dtype=np.float32)[:, None] * np.array([1.0, -0.5, 0.25], np.float32)
        border = BorderBlend((10.5, lines - 20.5), np.stack([along, -along]), np.stack([-along, 2 * along + 3]))
        plain = composite_image(img_src, img_tgt, plan_for(scene, seam, cfg), state, cfg)
        plan = plan_for(scene, seam, cfg, border=border)
        out = composite_image(img_src, img_tgt, plan, state, cfg)
        expected, _ = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
        assert np.abs(out.astype(np.float64) - expected).max() <= 1.0
        near = np.abs(np.arange(lines) - 10.5) < 0.5 * seam.lf_px
        changed = np.abs(out.astype(int) - plain.astype(int)).max(axis=2)
        assert (changed[near] if lines_are_rows else changed[:, near]).max() >= 4  # the offsets are there to see


@pytest.mark.parametrize("lines_are_rows", [True, False])
def test_relative_offsets_are_a_gain_that_keeps_white_white(scene, lines_are_rows, warp_device):  # noqa: F811
    """With ``relative_offsets`` the seam's and borders' offsets scale each side's gain (before its knee):
    the kernel matches the reference, white squares stay white where the offsets darken their side by
    20 %, and the mid-tones between them come out about 20 % darker than without the offsets."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    rows, cols = np.indices(img_src.shape[:2])
    img_src = np.where((((rows // 24) + (cols // 24)) % 2 == 0)[..., None], np.uint8(255), img_src)  # white squares
    seam = layout(scene, lines_are_rows)
    cfg = Config(device=warp_device, cpu_threads=2)
    gains = ([1.1, 0.9, 1.0], [0.0, 0.0, 0.0], [0.95, 1.05, 1.0], [0.0, 0.0, 0.0])
    lines = len(seam.positions)
    offsets = (np.full((lines, 3), -0.2, np.float32), np.full((lines, 3), 0.1, np.float32))
    state = FrameState(seam.positions, gains, offsets, relative_offsets=True)
    positions = map_src.shape[1] if lines_are_rows else map_src.shape[0]
    along = np.linspace(-0.1, 0.1, positions, dtype=np.float32)[:, None] * np.ones(3, np.float32)
    border = BorderBlend((10.5, lines - 20.5), np.stack([along, -along]), np.stack([-along, along]))
    plan = plan_for(scene, seam, cfg, border=border)
    out = composite_image(img_src, img_tgt, plan, state, cfg)
    expected, covered = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
    assert np.abs(out.astype(np.float64) - expected).max() <= 1.0
    white_src, _ = remap_reference(img_src, map_src)
    alpha, lf = seam_weights(state.seam, plan.layout, plan.canvas_shape, cfg)
    shown_white = (white_src.min(axis=2) >= 254.5) & (alpha > 0.999) & (lf > 0.3) & covered
    assert shown_white.sum() > 50 and out[shown_white].min() >= 254  # fixed point: within a level
    darkened = (white_src.max(axis=2) < 150) & (white_src.min(axis=2) > 40) & (alpha > 0.999) & (lf > 0.8) & covered
    plain = composite_image(img_src, img_tgt, plan_for(scene, seam, cfg), FrameState(seam.positions, gains), cfg)
    ratio = (out[darkened].astype(np.float64) + 0.5) / (plain[darkened] + 0.5)
    assert darkened.sum() > 50 and 0.7 < np.median(ratio) < 0.9


@pytest.mark.parametrize("device", DEVICES)
def test_the_frame_seam_moves_within_its_band_on_one_plan(scene, device, warp_device):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=device)
    plane_src, plane_tgt = np.ascontiguousarray(img_src[:, :, 1]), np.ascontiguousarray(img_tgt[:, :, 1])
    seam = layout(scene, band_px=20.0, lf_px=0.0)
    plan = plan_for(scene, seam, cfg, channels=1)
    gains = ([1.0], [0.0], [1.0], [0.0])
    first = composite_image(plane_src, plane_tgt, plan, FrameState(seam.positions, gains), cfg)
    moved_state = FrameState(clipped_seam(seam.positions + 10.0, seam), gains)  # inside the band: moves
    moved = composite_image(plane_src, plane_tgt, plan, moved_state, cfg)
    expected, _ = reference(plan, moved_state, plane_src, plane_tgt, map_src, map_tgt, cfg)
    assert np.abs(moved.astype(np.float64) - expected[:, :, 0]).max() <= 1.0
    assert not np.array_equal(first, moved)
    held = clipped_seam(seam.positions + 100.0, seam)  # beyond the band: held at its edge
    alpha, _ = seam_weights(held, seam, plan.canvas_shape, cfg)
    rows = np.arange(len(seam.positions))
    edge = np.rint(seam.positions + seam.band_px - 0.5 * seam.transition_px).astype(int)
    assert np.all(alpha[rows, edge - 12] > 0.99) and np.all(alpha[rows, edge + 12] < 0.01)


def test_a_plan_does_not_follow_its_callers_maps(scene, warp_device):  # noqa: F811
    """A plan is made of the maps as they were: a caller that changes its (writeable) map array after
    changes nothing, on the CPU as on a GPU; a read-only map (a video's) is used where it is."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device)
    seam = layout(scene)
    state = FrameState(seam.positions, GAINS, ramp_offsets(len(seam.positions)))
    mine = map_src.copy()
    plan = composite_plan(mine, map_tgt, seam, (img_src.shape, img_tgt.shape), cfg)
    before = composite_image(img_src, img_tgt, plan, state, cfg)
    mine += np.float32(7.0)
    np.testing.assert_array_equal(composite_image(img_src, img_tgt, plan, state, cfg), before)
    frozen = map_src.copy()
    frozen.flags.writeable = False
    counted = transfer.tally()
    composite_plan(frozen, map_tgt, seam, (img_src.shape, img_tgt.shape), cfg)
    assert (transfer.tally() - counted)[("upload", "plan")] == 3  # the static seam and both maps


def run_masks(plan, seam: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((Hc, Wc) bool the pixels in their row's copy run, the same of its sample run, (Hc, 5) the runs)."""
    runs = row_runs(plan, seam, cfg)
    cols = np.arange(plan.canvas_shape[1])[None, :]
    return ((cols >= runs[:, :1]) & (cols < runs[:, 1:2]), (cols >= runs[:, 3:4]) & (cols < runs[:, 4:5]), runs)


def with_runs_checked(img_src, img_tgt, plan, state: FrameState, cfg: Config) -> np.ndarray:
    """The pair composited with the plan's runs, checked to be the same as the pair composited by the
    full rule everywhere (the plan without its runs)."""
    out = composite_image(img_src, img_tgt, plan, state, cfg)
    assert (row_runs(plan, state.seam, cfg)[:, [1, 4]] > 0).any()
    full_rule = composite_image(img_src, img_tgt, replace(plan, runs=None), state, cfg)
    np.testing.assert_array_equal(out, full_rule)
    return out


@pytest.mark.parametrize("lines_are_rows", [True, False])
def test_runs_hold_one_side_alone_beyond_the_seams_reach(scene, lines_are_rows, warp_device):  # noqa: F811
    """Each row's copy run is target pixels at whole positions, consecutive, and its sample run source
    pixels, where neither the frame's seam nor a border's offsets reach; most such pixels are in one."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device, cpu_threads=2)
    seam = layout(scene, lines_are_rows)
    plan = with_runs(plan_for(scene, seam, cfg), cfg)
    frame_seam = clipped_seam(seam.positions + 7.0, seam)
    copied, sampled, runs = run_masks(plan, frame_seam, cfg)
    height, width = plan.canvas_shape
    line, position = np.mgrid[:height, :width] if lines_are_rows else np.mgrid[:height, :width][::-1]
    distance = position - seam.positions[line]
    distance_frame = position - frame_seam[line]
    _, ok_src = remap_reference(img_src, map_src)
    _, ok_tgt = remap_reference(img_tgt, map_tgt)
    shown_tgt = ok_tgt & (~ok_src | (distance > seam.band_px))  # the target alone, whatever the frame's seam
    exact = shown_tgt & np.all(map_tgt == np.round(map_tgt), axis=2)
    clear = np.abs(distance_frame) >= seam.lf_px  # the frame's seam offsets do not reach
    assert copied.any() and np.all((exact & clear)[copied])
    cols = np.arange(width)[None, :]
    element = (map_tgt[..., 1] * img_tgt.shape[1] + map_tgt[..., 0]) * 3 - cols * 3  # the runs' element at column 0
    np.testing.assert_array_equal(np.broadcast_to(runs[:, 2:3], copied.shape)[copied], element[copied])
    # Where the lines are rows each frame's runs come up to its seam's offsets; else they keep clear of
    # where any frame's might reach.
    reach = seam.lf_px + 1.0 if lines_are_rows else seam.band_px - 0.5 * seam.transition_px + seam.lf_px + 1.0
    within = (np.abs(distance_frame) if lines_are_rows else np.abs(distance)) > reach
    assert copied.sum() >= 0.9 * (exact & within).sum()
    shown_src = ok_src & (~ok_tgt | (distance < -seam.band_px))
    assert sampled.any() and np.all((shown_src & clear)[sampled])
    assert sampled.sum() >= 0.9 * (shown_src & within).sum()


def test_runs_leave_the_borders_offsets_and_a_resampled_target_to_the_full_rule(scene, warp_device):  # noqa: F811
    """Where a border's nonzero offsets reach, rows copy and sample nothing; a target map off whole pixels
    copies nothing."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device, cpu_threads=2)
    seam = layout(scene)
    lines = len(seam.positions)
    before = np.stack(run_masks(with_runs(plan_for(scene, seam, cfg), cfg), seam.positions, cfg)[:2])
    along = np.zeros((2, map_src.shape[1], 3), np.float32)
    along[0, : map_src.shape[1] * 3 // 4] = 5.0  # border 0 has offsets on the left three quarters
    plan = with_runs(plan_for(scene, seam, cfg, border=BorderBlend((10.5, lines - 20.5), along, along)), cfg)
    after = np.stack(run_masks(plan, seam.positions, cfg)[:2])
    near = np.abs(np.arange(lines) - 10.5) < seam.lf_px
    offset_cols = np.arange(map_src.shape[1]) < map_src.shape[1] * 3 // 4
    assert before[0][near][:, offset_cols].any() and before[1][near][:, offset_cols].any()
    assert not after[:, near][:, :, offset_cols].any()
    assert np.array_equal(after[:, ~near], before[:, ~near])
    shifted = composite_plan(map_src, map_tgt + np.float32(0.25), seam, (img_src.shape, img_tgt.shape), cfg)
    assert not run_masks(with_runs(shifted, cfg), seam.positions, cfg)[0].any()


@pytest.mark.parametrize("device", DEVICES)
def test_run_pixels_take_the_gains_and_knee_as_the_full_rule_does(scene, device, warp_device):  # noqa: F811
    """With the frame's seam at the edge of its band on either side and strong offsets, the runs still
    match the reference (copies to its rounding): the offsets never reach them, the gains and knee do."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=device, cpu_threads=2)
    seam = layout(scene, band_px=20.0)
    plan = with_runs(plan_for(scene, seam, cfg), cfg)
    lines = len(seam.positions)
    offsets = (np.full((lines, 3), 30.0, np.float32), np.full((lines, 3), -30.0, np.float32))
    state = FrameState(clipped_seam(seam.positions + 100.0, seam), STRONG_GAINS, offsets)
    out = with_runs_checked(img_src, img_tgt, plan, state, cfg)
    expected, _ = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
    copied, sampled, _ = run_masks(plan, state.seam, cfg)
    assert copied.mean() > 0.2 and sampled.mean() > 0.2
    assert np.abs(out[copied].astype(np.float64) - expected[copied]).max() <= 0.5 + 1e-6
    assert (out[copied] == 255).any()  # the knee is met: the gain of 1.3 would clip
    state = FrameState(clipped_seam(seam.positions - 100.0, seam), STRONG_GAINS, offsets)  # the source's side
    out = with_runs_checked(img_src, img_tgt, plan, state, cfg)
    expected, _ = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
    _, sampled, _ = run_masks(plan, state.seam, cfg)
    assert np.abs(out[sampled].astype(np.float64) - expected[sampled]).max() <= 1.0


def test_runs_reach_the_band_where_frames_carry_no_seam_offsets(scene, warp_device):  # noqa: F811
    """A pass whose frames carry no seam offsets (a chroma pass) has nothing of the seam reaching beyond
    the band, so its runs go up to it; a pass with offsets keeps their reach; both composite as the
    reference does."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device, cpu_threads=2)
    seam = layout(scene, band_px=20.0)
    lines = len(seam.positions)
    frame_seam = clipped_seam(seam.positions + 100.0, seam)
    plan = with_runs(plan_for(scene, seam, cfg, offsets=False), cfg)
    state = FrameState(frame_seam, STRONG_GAINS)
    out = with_runs_checked(img_src, img_tgt, plan, state, cfg)
    expected, _ = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
    copied, sampled, _ = run_masks(plan, frame_seam, cfg)
    distance = np.arange(map_src.shape[1])[None, :] - frame_seam[:, None]
    near = np.abs(distance) < seam.lf_px
    assert copied[near].any() and sampled[near].any()  # within the offsets' reach, had there been any
    # Beyond the band the plan shows one side where the reference's smoothed ramp has a tail left.
    alpha, _ = seam_weights(frame_seam, seam, plan.canvas_shape, cfg)
    both = (copied | sampled) & ((alpha < 1e-4) | (alpha > 1 - 1e-4))
    assert both.mean() > 0.5
    assert np.abs(out[both].astype(np.float64) - expected[both]).max() <= 1.0
    plan = with_runs(plan_for(scene, seam, cfg), cfg)
    offsets = (np.full((lines, 3), 30.0, np.float32), np.full((lines, 3), -30.0, np.float32))
    state = FrameState(frame_seam, STRONG_GAINS, offsets)
    out = with_runs_checked(img_src, img_tgt, plan, state, cfg)
    expected, _ = reference(plan, state, img_src, img_tgt, map_src, map_tgt, cfg)
    copied, sampled, _ = run_masks(plan, frame_seam, cfg)
    assert not (copied | sampled)[near].any()
    both = copied | sampled
    assert np.abs(out[both].astype(np.float64) - expected[both]).max() <= 1.0


@pytest.mark.parametrize("cell", [1, 2])
def test_band_difference_is_source_minus_target_where_both_are_kept(scene, warp_device, cell):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device)
    plane_src, plane_tgt = np.ascontiguousarray(img_src[:, :, 0]), np.ascontiguousarray(img_tgt[:, :, 0])
    seam = layout(scene, band_px=10.0)
    plan = plan_for(scene, seam, cfg, channels=1)
    frame = FrameArrays.on(transfer.to_device(plane_src.ravel(), wp.uint8, cfg.device, "planes"),
                           transfer.to_device(plane_tgt.ravel(), wp.uint8, cfg.device, "planes"),
                           wp.empty(plane_src.size, dtype=wp.uint8, device=cfg.device), plan)
    gains = kernel_gains(([1.2], [-5.0], [1.0], [0.0]), 1, plan.tone, frame.table)
    lines = np.arange(1, len(seam.positions), 3, dtype=np.int32)  # every third line, as the frame seam solves
    count = 2 * (8 // cell) + 1  # cells of ``cell`` px 8 px each side of the seam, inside the plan's band
    band_x0 = (np.rint(seam.positions[lines]) - 8).astype(np.int32)
    cells = (len(lines), count)
    last = np.full(cells, 3.0, np.float32)
    last[:, 0] = NOT_BOTH  # the last frame lacked a view there
    band = BandCells()
    band.lines, band.x0, band.cell = (wp.array(lines, dtype=int, device=cfg.device),
                                      wp.array(band_x0, dtype=int, device=cfg.device), cell)
    words = BandWords()  # the plan's words copied two cells further each side than the band reads
    words.first = wp.empty(len(lines), dtype=int, device=cfg.device)
    words.words = wp.empty((len(lines), count + 4), dtype=BandWord, device=cfg.device)
    band_words(frame, plan, band, 2, words)
    np.testing.assert_array_equal(words.first.numpy(), band_x0 - 2 * cell)
    out = (wp.array(last, dtype=float, device=cfg.device), *(wp.zeros(cells, dtype=float, device=cfg.device)
                                                             for _ in range(2)))
    band_difference(frame, plan, words, band, gains, count, out)
    diff, total, delta = (array.numpy() for array in out)
    v_src, ok_src = remap_reference(plane_src[:, :, None], map_src)
    v_tgt, ok_tgt = remap_reference(plane_tgt[:, :, None], map_tgt)
    rows = lines[:, None]
    cols = band_x0[:, None] + cell * np.arange(count)[None, :]
    both = ok_src[rows, cols] & ok_tgt[rows, cols]
    knee, white = plan.knee
    adjusted_src = tone_curve(v_src[rows, cols, 0], 1.2, -5.0, knee, white)
    adjusted_tgt = tone_curve(v_tgt[rows, cols, 0], 1.0, 0.0, knee, white)
    np.testing.assert_array_equal(diff < 0.5 * NOT_BOTH, both)
    assert both.mean() > 0.5
    assert np.abs(diff[both] - (adjusted_src - adjusted_tgt)[both]).max() < 0.25  # taps in 1/1024 px
    assert np.abs(total[both] - (adjusted_src + adjusted_tgt)[both]).max() < 0.25
    assert np.all(total[~both] == 0.0)
    changed = both & (last < 0.5 * NOT_BOTH)
    np.testing.assert_allclose(delta[changed], np.abs(diff - 3.0)[changed], atol=1e-5)
    assert np.all(delta[~changed] == 0.0)


def test_a_plan_refuses_inputs_it_cannot_serve(scene, warp_device):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, _ = scene
    cfg = Config(device=warp_device)
    seam = layout(scene)
    shapes = (img_src.shape, img_tgt.shape)
    with pytest.raises(ValueError, match="share one"):
        composite_plan(map_src[:-1], map_tgt, seam, shapes, cfg)
    with pytest.raises(ValueError, match="one position per line"):
        composite_plan(map_src, map_tgt, SeamLayout(seam.positions[:-1], True, 12.0, 8.0, 1.5, 0.0), shapes, cfg)
    with pytest.raises(ValueError, match="channels"):
        composite_plan(map_src, map_tgt, seam, (img_src.shape, (*img_tgt.shape[:2], 1)), cfg)
    plan = composite_plan(map_src, map_tgt, seam, shapes, cfg)
    with pytest.raises(ValueError, match="plan of"):
        composite_image(img_src, np.ascontiguousarray(img_tgt[:, :, 0]), plan,
                        FrameState(seam.positions, GAINS), cfg)


@wp.kernel
def alpha_at_kernel(t: wp.array(dtype=float), transition_px: wp.array(dtype=float), sigma_px: wp.array(dtype=float),
                    alpha: wp.array(dtype=float)):
    i = wp.tid()
    alpha[i] = source_alpha(t[i], transition_px[i], sigma_px[i])


def test_the_frame_kernel_may_skip_the_smoothed_ramp_beyond_its_tails(warp_device):  # noqa: F811
    # The frame kernel shows one side alone where the smoothed ramp is within 1e-4 of 0 or 1 and takes
    # that to hold from ALPHA_TAIL_SIGMAS past the ramp's ends without computing it there: check it does,
    # on both sides, for transitions of 1-64 px and sigmas of 0-16 px.
    grid = np.meshgrid([-1.0, 1.0], [1.0, 2.0, 8.0, 24.0, 64.0], [0.0, 0.5, 1.5, 4.0, 16.0], [0.0, 0.5, 3.0, 100.0],
                       indexing="ij")
    side, transition, sigma, beyond = (np.ravel(v).astype(np.float32) for v in grid)
    at = side * (0.5 * transition + float(ALPHA_TAIL_SIGMAS) * sigma + beyond)
    alpha = wp.zeros(len(at), dtype=float, device=warp_device)
    wp.launch(alpha_at_kernel, dim=len(at), inputs=[wp.array(at, dtype=float, device=warp_device),
                                                    wp.array(transition, dtype=float, device=warp_device),
                                                    wp.array(sigma, dtype=float, device=warp_device), alpha],
              device=warp_device)
    values = alpha.numpy()
    assert np.all(values[at > 0] < 0.0001) and np.all(values[at < 0] > 0.9999)  # the target's side, the source's
