"""``kernels/frame_seam.py`` against numpy references of the same rules (what ``video/frame_seam.py``
computed with numpy before these were kernels), on a band of cells cut from a real pair's luma."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import warp as wp

from sena_warp.kernels import runtime
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.kernels.frame_seam import CellCosts, LastSeam, SeamCosts, band_cost_kernel, strip_mean_kernel
from test_kernels_maps import DEVICES

LINES, WIDTH = 60, 41  # solved lines and cells of the band
NOISE, MOTION, BLOCKED, STAY, BLOCK, OBJECT = 6.0, 40.0, 100.0, 0.5, 1000.0, 1000.0  # the per-frame seam's costs


@pytest.fixture(scope="module")
def band(udisd_pair) -> tuple[np.ndarray, np.ndarray]:
    """(difference, sum) (LINES, WIDTH) float32 of the pair's luma; cells without both views: the first
    three of every line and a patch at the end of a few lines."""
    luma = [cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32)[200:200 + LINES, 150:150 + WIDTH]
            for img in udisd_pair]
    diff, total = luma[0] - luma[1], luma[0] + luma[1]
    outside = np.zeros(diff.shape, bool)
    outside[:, :3] = True
    outside[20:26, -6:] = True
    return np.where(outside, NOT_BOTH, diff).astype(np.float32), np.where(outside, 0.0, total).astype(np.float32)


def grid(cell: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(band's first cells x0 (LINES,), its cells' positions (LINES, WIDTH)) on a grid of ``cell`` px."""
    x0 = (cell * (300 + np.random.default_rng(seed).integers(-3, 4, LINES))).astype(np.int32)
    return x0, x0[:, None] + cell * np.arange(WIDTH, dtype=np.int32)[None, :]


def on(device: str, values: np.ndarray, dtype=float) -> wp.array:
    return wp.array(np.ascontiguousarray(values), dtype=dtype, device=device)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("cell", [1, 2, 3])
def test_band_cost_is_the_seams_cost_rule(band, device, cell, warp_device):
    diff, _ = band
    both = diff < 0.5 * NOT_BOTH
    rng = np.random.default_rng(cell)
    x0, cells = grid(cell, cell)
    moving = np.zeros(diff.shape, np.uint8)
    moving[30:45, 10:25] = 1  # something in front
    kept_off = np.zeros(diff.shape, np.uint8)
    kept_off[32:44, 12:30] = 1  # the strip its copies span
    kept_off[20:23, -8:] = 1  # ... reaching where a view is missing
    home = cells[:, WIDTH // 2]
    home_term = (0.5 * np.abs(cells - home[:, None])).astype(np.float32)
    last = cells[np.arange(LINES), rng.integers(0, WIDTH, LINES)]
    last[:4] = x0[:4] - cell * 2  # the band has moved past the last seam there
    still = rng.random(LINES) < 0.3
    speed = max(2.0, cell)
    glide_width = 2 * int(np.ceil(speed / cell)) + 1
    first = np.clip((last - x0) // cell - glide_width // 2, 0, WIDTH - glide_width)
    out = [wp.zeros(diff.shape, dtype=float, device=device) for _ in range(2)]
    glide = wp.zeros((LINES, glide_width), dtype=float, device=device)
    line_min = wp.zeros(LINES, dtype=float, device=device)
    seam = LastSeam()
    seam.last, seam.still, seam.glide_first = (on(device, last, int), on(device, still.astype(np.uint8), wp.uint8),
                                               on(device, first, int))
    costs = SeamCosts()
    costs.speed, costs.noise, costs.motion_cost, costs.blocked_cost, costs.stay_cost, costs.block_cost = (
        speed, NOISE, MOTION, BLOCKED, STAY, BLOCK)
    costs.object_cost = OBJECT
    cell_costs = CellCosts()
    cell_costs.change, cell_costs.free, cell_costs.glide, cell_costs.line_min = *out, glide, line_min
    runtime.launch_rows(band_cost_kernel, LINES, 1, [
        on(device, diff), on(device, moving, wp.uint8), on(device, kept_off, wp.uint8), on(device, home_term),
        on(device, x0, int), cell, seam, costs, cell_costs], device, runtime.BAND_THREADS)

    change = np.maximum(np.abs(diff) - np.float32(NOISE), np.float32(0.0)) + np.float32(MOTION) * moving
    change[~both] = BLOCKED
    change += np.float32(OBJECT) * kept_off
    cost = change + home_term + np.float32(STAY) * np.abs(cells - last[:, None]).astype(np.float32)
    free = cost + np.float32(BLOCK) * (still[:, None] & (cells != last[:, None]))
    taken = first[:, None] + np.arange(glide_width)[None, :]
    near = np.take_along_axis(cells, taken, axis=1)
    outside = np.maximum(np.maximum(x0 - last, last - cells[:, -1]), 0)
    far = np.abs(near - last[:, None]) > np.maximum(speed, outside)[:, None]
    blocked = far | (still[:, None] & (near != last[:, None]))
    np.testing.assert_array_equal(out[0].numpy(), change)
    np.testing.assert_array_equal(out[1].numpy(), free)
    np.testing.assert_array_equal(glide.numpy(), np.take_along_axis(cost, taken, axis=1) + np.float32(BLOCK) * blocked)
    np.testing.assert_array_equal(line_min.numpy(), change.min(axis=1))
    assert blocked.any() and not blocked.all() and (free != cost).any()  # the cases above were reached


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("cell", [1, 2, 3])
def test_strip_mean_is_the_mean_difference_within_the_strip_of_the_seam(band, device, cell, warp_device):
    diff, _ = band
    both = diff < 0.5 * NOT_BOTH
    strip_px = 12
    x0, cells = grid(cell, 10 + cell)
    path = cells[np.arange(LINES), np.random.default_rng(cell).integers(0, WIDTH, LINES)]
    path[:3], path[3:6] = cells[:3, 0], cells[3:6, -1]  # at the band's two ends
    mean = wp.zeros(LINES, dtype=float, device=device)
    count = wp.zeros(LINES, dtype=int, device=device)
    runtime.launch_rows(strip_mean_kernel, LINES, 1, [
        on(device, diff), on(device, x0, int), cell, on(device, path, int), strip_px // cell, mean, count],
        device, runtime.BAND_THREADS)

    strip = both & (np.abs(cells - path[:, None]) <= strip_px)
    np.testing.assert_array_equal(count.numpy(), strip.sum(axis=1))
    expected = np.where(strip, diff, 0.0).sum(axis=1) / np.maximum(strip.sum(axis=1), 1)
    np.testing.assert_allclose(mean.numpy(), expected, rtol=0, atol=1e-4)
    assert (count.numpy() < strip_px // cell * 2 + 1).any()  # strips cut by the band's ends or missing views
