"""``kernels/frame_objects.py`` against numpy references of the same rules, on a band of cells cut
from a real pair's luma."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from sena_warp.kernels import runtime
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.kernels.frame_objects import CellGrid, ViewModels, coarse_masks_kernel, view_background_kernel
from test_kernels_frame_seam import LINES, WIDTH, band, on  # noqa: F401 (band: the fixture)
from test_kernels_maps import DEVICES


@pytest.mark.parametrize("device", DEVICES)
def test_each_view_s_model_flags_what_its_spread_and_its_gain_do_not_explain(band, device, warp_device):  # noqa: F811
    diff, total = band
    both = diff < 0.5 * NOT_BOTH
    views = np.stack([0.5 * (total + diff), 0.5 * (total - diff)])
    rng = np.random.default_rng(5)
    background = (views + rng.normal(0.0, 3.0, views.shape)).astype(np.float32) * both  # cells that vary ...
    spread = rng.uniform(1.0, 5.0, views.shape).astype(np.float32)  # ... by about what they learnt, or less
    last = (views + rng.normal(0.0, 3.0, views.shape)).astype(np.float32)
    now = np.stack([1.05 * views[0] + 4.0, 0.97 * views[1] - 2.0]).astype(np.float32)  # each its exposure step ...
    now[0, 30:40, 12:20] += 90.0  # ... and something in front of the source
    explained = np.float32([0.05, 4.0, -0.03, -2.0])
    noise, factor, learn, learn_off = np.float32(12.0), np.float32(3.0), np.float32(1 / 60), np.float32(1 / 600)
    spread_off = np.float32(1 / 240)
    models = ViewModels()
    models.background, models.spread, models.last = on(device, background), on(device, spread), on(device, last)
    models.off = wp.zeros(views.shape, dtype=wp.uint8, device=device)
    models.noise, models.spread_factor, models.learn, models.learn_off = (float(v) for v in (noise, factor, learn,
                                                                                            learn_off))
    models.spread_off = float(spread_off)
    now_diff = np.where(both, now[0] - now[1], NOT_BOTH).astype(np.float32)
    now_total = np.where(both, now[0] + now[1], 0.0).astype(np.float32)
    runtime.launch_row_loops(view_background_kernel, LINES, WIDTH, [
        on(device, now_diff), on(device, now_total), wp.vec4(*explained), models], device, runtime.BAND_THREADS)

    luma = np.stack([0.5 * (now_total + now_diff), 0.5 * (now_total - now_diff)])
    change = luma - background
    gains = explained.reshape(2, 2)
    deviation = np.abs(change - (gains[:, :1, None] * background + gains[:, 1:, None]))
    off = both & (deviation > np.maximum(noise, factor * spread))
    rate = np.where(off, learn_off, learn)
    np.testing.assert_array_equal(models.off.numpy(), off)
    np.testing.assert_allclose(models.background.numpy(), np.where(both, background + rate * change, background),
                               rtol=0, atol=1e-3)
    spread_rate = np.where(off, spread_off, learn)  # an object's own texture is not the background's usual change
    np.testing.assert_allclose(models.spread.numpy(),
                               np.where(both, spread + spread_rate * (np.abs(luma - last) - spread), spread),
                               rtol=0, atol=1e-3)
    np.testing.assert_allclose(models.last.numpy(), np.where(both, luma, last), rtol=0, atol=1e-3)
    assert off[0, 30:40, 12:20].all() and not off[1, 30:40, 12:20].any()  # the source's object only


@pytest.mark.parametrize("device", DEVICES)
def test_a_finer_band_takes_the_coarse_cell_it_lies_in(device, warp_device):
    coarse_lines, coarse_width, step = 10, 12, 8  # every 8th line, cells of 8 px
    rng = np.random.default_rng(3)
    moving_c = (rng.random((coarse_lines, coarse_width)) < 0.3).astype(np.uint8)
    kept_c = (rng.random((coarse_lines, coarse_width)) < 0.3).astype(np.uint8)
    coarse = CellGrid()
    coarse_x0 = np.full(coarse_lines, 96, np.int32)
    coarse.x0, coarse.cell, coarse.step = on(device, coarse_x0, int), 8, step
    lines = np.arange(0, 76, 2).astype(np.int32)  # a band on every 2nd line, cells of 2 px, from px 90
    fine = CellGrid()
    fine_x0 = np.full(len(lines), 90, np.int32)
    fine.x0, fine.cell, fine.step = on(device, fine_x0, int), 2, 2
    width = 60
    moving, kept = (wp.zeros((len(lines), width), dtype=wp.uint8, device=device) for _ in range(2))
    runtime.launch_row_loops(coarse_masks_kernel, len(lines), width, [
        on(device, lines, int), fine, coarse, on(device, moving_c, wp.uint8), on(device, kept_c, wp.uint8), moving,
        kept], device, runtime.BAND_THREADS)
    positions = fine_x0[:, None] + 2 * np.arange(width)[None, :]
    line_c = np.minimum((lines + step // 2) // step, coarse_lines - 1)
    cell_c = (positions - coarse_x0[line_c][:, None]) // 8
    inside = (positions >= coarse_x0[line_c][:, None]) & (cell_c < coarse_width)
    cell_c = np.clip(cell_c, 0, coarse_width - 1)
    for got, source in ((moving, moving_c), (kept, kept_c)):
        np.testing.assert_array_equal(got.numpy(), np.where(inside, source[line_c[:, None], cell_c], 0))
