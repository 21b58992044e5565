"""Every setting given at the top of a run reaches the stage that uses it.

A stage that fell back to ``Config()`` would run on the defaults whatever the caller asked for: with
``forward_max_iters=0`` the step-7 inputs would come out as with the default 30 iterations, and the
grey canvas, the source map and the compositor would launch on the default thread count.
"""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp import stitch
from sena_warp.config import Config
from sena_warp.kernels import runtime
from sena_warp.video.loop import VideoOptions
from sena_warp.video.stitch import stitch_videos

THREADS = 3  # not the default (0 = one per core), so a stage running on Config() shows


class ZoneInputs(Exception):
    """Raised by the spy in place of step 7: the stitch stops once its inputs are seen."""


def zone_inputs(monkeypatch, img_a, img_b, cfg):
    """(warped-source inlier points on the canvas, warped-source grey canvas) handed to step 7."""
    def spy(pts_src_canvas, pts_tgt_canvas, overlap_mask_canvas, grey_src_canvas, grey_tgt_canvas, zone_cfg):
        raise ZoneInputs(pts_src_canvas, grey_src_canvas)

    monkeypatch.setattr(stitch, "adequate_zone", spy)
    with pytest.raises(ZoneInputs) as seen:
        stitch.estimate_maps(img_a, img_b, cfg)
    return seen.value.args


def launches(monkeypatch) -> list[tuple[str, str, int]]:
    """Every row-band launch from now on, as (kernel key, device, threads)."""
    seen = []
    for name in ("launch_rows", "launch_row_loops"):
        real = getattr(runtime, name)

        def spy(kernel, height, width, inputs, device, threads, real=real):
            seen.append((kernel.key, device, threads))
            real(kernel, height, width, inputs, device, threads)

        monkeypatch.setattr(runtime, name, spy)
    return seen


def test_forward_settings_reach_the_step_7_inputs(udisd_pair, monkeypatch):
    cfg = Config(device="cpu")
    pts_default, grey_default = zone_inputs(monkeypatch, *udisd_pair, cfg)
    # Measured on this pair: all 606 inlier points converge with the default 30 iterations ...
    assert np.isfinite(pts_default).all()
    # ... and 605 of them without any iteration: u = A s + o does not solve M_s(u) = s to 0.01 px.
    pts_none, grey_none = zone_inputs(monkeypatch, *udisd_pair, cfg.replace(forward_max_iters=0))
    assert np.isnan(pts_none[:, 0]).mean() > 0.99
    # A loose tolerance stops the iterations early: the points move (measured: up to 0.43 px, median
    # 0.03 px), and by less than the tolerance itself.
    pts_loose, _ = zone_inputs(monkeypatch, *udisd_pair, cfg.replace(forward_tol_px=2.0))
    moved = np.linalg.norm(pts_loose - pts_default, axis=1)
    assert 0.2 < moved.max() < 2.0
    # The grey canvas follows M_s alone, which those settings do not touch.
    np.testing.assert_array_equal(grey_none, grey_default)


def test_device_and_threads_reach_every_launch_of_an_image_stitch(udisd_pair, monkeypatch):
    resolved = []
    real_resolve = runtime.resolve_device
    monkeypatch.setattr(runtime, "resolve_device", lambda name: resolved.append(name) or real_resolve(name))
    seen = launches(monkeypatch)
    stitch.stitch_images(*udisd_pair, Config(device="auto", cpu_threads=THREADS))
    assert resolved == ["auto"]  # the device is chosen once per run
    kernels = {key for key, _, _ in seen}
    # Source map, the views' remap, the seam's path, seam maps, the compositor's plan and frame kernels.
    assert len(kernels) >= 6 and {"remap", "seam_dp", "seam_maps", "composite"} <= {
        part for key in kernels for part in ("remap", "seam_dp", "seam_maps", "composite") if part in key}
    assert {(device, threads) for _, device, threads in seen} == {(real_resolve("auto"), THREADS)}


def test_threads_reach_every_launch_of_a_video_stitch(bundled_dir, tmp_path, monkeypatch):
    seen = launches(monkeypatch)
    cfg = Config(device="cpu", cpu_threads=THREADS, video_estimate_pairs=1)
    clips = bundled_dir / "video"
    stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "o.mp4", cfg,
                  VideoOptions.from_config(cfg, audio="none"))
    assert len(seen) > 60  # the estimate's launches and two per frame (Y, then U and V)
    # The per-frame seam's band kernels, the frame's runs and the report's map change (a moving rig's maps
    # change every frame) run on BAND_THREADS (a second thread costs more than it saves); every other
    # launch uses the threads set.
    band = {"band_words_kernel", "band_difference_kernel", "view_background_kernel", "coarse_masks_kernel",
            "band_cost_kernel", "strip_mean_kernel", "frame_runs_kernel", "map_change_kernel"}
    assert {(device, threads) for key, device, threads in seen if key not in band} == {("cpu", THREADS)}
    assert {(device, threads) for key, device, threads in seen if key in band} == {("cpu", runtime.BAND_THREADS)}


@pytest.mark.parametrize("changes, aligned", [(dict(), 0), (dict(switch_align=True, switch_rounds=1), 1),
                                              (dict(switch_align=True), 2)])
def test_switch_settings_reach_the_seam_stage(udisd_pair, monkeypatch, changes, aligned):
    """``switch_align`` and ``switch_rounds`` decide how often the source is aligned at the switches (the
    aligned map's kernel launches) and the seam cut again; the cut uses the aligned map."""
    seen = launches(monkeypatch)
    maps = stitch.estimate_maps(*udisd_pair, Config(device="cpu", **changes))
    assert sum("displaced_map" in key for key, _, _ in seen) == aligned
    moved = np.abs(maps.seam.map_cut_canvas - maps.warp.map_src_canvas).max()
    assert (moved > 0.1) == (aligned > 0)


@pytest.fixture
def composited(monkeypatch) -> list:
    """The (plan, state) of every panorama ``stitch.composite_image`` composites."""
    calls = []
    real = stitch.composite_image

    def spy(img_src, img_tgt, plan, state, cfg, *args):
        calls.append((plan, state))
        return real(img_src, img_tgt, plan, state, cfg, *args)

    monkeypatch.setattr(stitch, "composite_image", spy)
    return calls


@pytest.mark.parametrize("gain", [True, False])
def test_seam_blend_gain_reaches_the_compositor(udisd_pair, composited, gain):
    """``seam_blend_gain``: the panorama is composited with the seam blend as relative gains (or grey
    levels), and the offsets it is given are those (a few % against a few levels)."""
    pano = stitch.stitch_images(*udisd_pair, Config(device="cpu", seam_blend_gain=gain))
    state = composited[-1][1]
    assert state.relative_offsets is gain
    applied = np.abs(state.offsets[0]).max()
    assert applied == pytest.approx(np.abs(pano.maps.seam.offsets.relative()[0] if gain else pano.maps.seam.offsets.src).max(),
                                    rel=1e-3, abs=1e-5)


@pytest.mark.parametrize("peak", [True, False])
def test_gain_knee_peak_reaches_the_views_and_the_compositor(udisd_pair, composited, peak):
    """``gain_knee_peak``: the views the seam is cut on and the panorama's plan both take the knee as
    set (a pixel's channels sharing it, or each its own), the kernels through the plan's tone."""
    pano = stitch.stitch_images(*udisd_pair, Config(device="cpu", gain_knee_peak=peak))
    assert pano.maps.seam.gains.knee_peak is peak
    assert composited[-1][0].knee_peak is peak and composited[-1][0].tone[2] == int(peak)
