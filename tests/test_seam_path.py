"""Seam path (steps 8-9, ours): the DP kernel against brute force, the costs, the anchors, a real pair."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.imageio import read_image
from sena_warp.seam_path import (BLOCKED, anchors_on_path, coarse_path, dp_segments, refine_path, separation_cost,
                                 seam_cost_canvas)

BUNDLED = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="module")
def cfg(warp_device):
    return Config(device=warp_device, cpu_threads=2)


def brute_force(cost: np.ndarray, band_x0: np.ndarray, max_step: int, step_cost: float, start=None, end=None):
    """Every path through a small band; the cheapest one's canvas x per row and its cost."""
    rows, width = cost.shape
    best, best_path = np.inf, None
    for cols in itertools.product(range(width), repeat=rows):
        xs = band_x0 + np.array(cols)
        if start is not None and xs[0] != start or end is not None and xs[-1] != end:
            continue
        steps = np.abs(np.diff(xs))
        if np.any(steps > max_step):
            continue
        total = cost[np.arange(rows), cols].sum() + step_cost * steps.sum()
        if total < best:
            best, best_path = total, xs
    return best_path, best


def path_cost(cost, band_x0, path, step_cost):
    return cost[np.arange(len(path)), path - band_x0].sum() + step_cost * np.abs(np.diff(path)).sum()


@pytest.mark.parametrize("seed", range(4))
def test_dp_kernel_finds_the_cheapest_path(cfg, seed):
    rng = np.random.default_rng(seed)
    rows, width = 6, 5
    cost = rng.random((rows, width)).astype(np.float32) * 10
    band_x0 = np.array([10, 11, 11, 9, 10, 12], np.int32)  # the band shifts between rows
    path = dp_segments(cost, band_x0, np.array([[0, rows - 1, -1, -1]]), 1, 1.5, cfg)
    expected, expected_cost = brute_force(cost, band_x0, 1, 1.5)
    assert path_cost(cost, band_x0, path, 1.5) == pytest.approx(expected_cost, abs=1e-4)
    np.testing.assert_array_equal(path, expected)


def test_dp_kernel_segments_keep_their_fixed_ends(cfg):
    rng = np.random.default_rng(7)
    cost = rng.random((9, 6)).astype(np.float32)
    band_x0 = np.zeros(9, np.int32)
    segments = np.array([[0, 4, -1, 3], [4, 8, 3, -1]])  # the shared row 4 is an anchor at x = 3
    path = dp_segments(cost, band_x0, segments, 2, 0.5, cfg)
    assert path[4] == 3
    first, _ = brute_force(cost[:5], band_x0[:5], 2, 0.5, end=3)
    second, _ = brute_force(cost[4:], band_x0[4:], 2, 0.5, start=3)
    np.testing.assert_array_equal(path[:5], first)
    np.testing.assert_array_equal(path[4:], second)


def test_separation_cost_covers_the_span_between_two_copies_and_the_blend_s_reach(cfg):
    """Copies 8 px apart at x 10 and 18: a seam between them, or within a quarter transition plus the
    smoothing (2 + 1.5 px) of either, would show the point twice; beyond that it costs nothing."""
    copies_src = np.array([[10.0, 20.0], [40.0, 5.0], [70.0, 30.0]])
    copies_tgt = np.array([[18.0, 20.0], [41.0, 5.0], [70.0, 30.0]])  # 8 px apart, 1 px (one point), 0 px
    cost = separation_cost((40, 100), copies_src, copies_tgt, cfg)
    weight, reach = cfg.seam_separation_weight, cfg.seam_separation_rows
    blend = 0.25 * cfg.transition_px + cfg.seam_smooth_sigma_px
    assert blend == 3.5
    assert np.all(cost[20 - reach:20 + reach + 1, 6:22] == weight)
    assert cost[20, 5] == 0 and cost[20, 22] == 0 and cost[20 + reach + 1, 12] == 0
    assert cost[5].sum() == 0 and cost[30].sum() == 0


def test_anchors_keep_to_the_path_go_down_and_never_step_sideways(cfg):
    seam_x = np.full(200, 50.0)
    tgt = np.array([[50, 30], [51, 33], [52, 60], [90, 70], [49, 100], [52, 103], [48, 150]], np.float64)
    src = tgt + np.array([1.0, 0.5])
    src[4, 1] = src[2, 1] - 1.0  # goes up in the source: would fold the band
    kept = anchors_on_path(src, tgt, seam_x, (0, 199), 4.0, cfg)
    # 1: 3 rows below 0 (spacing); 3: 40 px off the path; 4: goes up in the source
    assert kept.tolist() == [0, 2, 5, 6]


def test_seam_on_a_pair_runs_through_its_anchors_inside_the_overlap(cfg):
    """A real image and a shifted copy of it: the seam through agreeing pixels, exactly through anchors."""
    img = read_image(BUNDLED / "udisd_test_000001" / "a.jpg")
    shift = 40
    src, tgt = img[:, :-shift], img[:, shift:]
    width = img.shape[1] - shift + shift  # canvas: target at offset shift, source at 0
    both = np.zeros((img.shape[0], width), bool)
    both[:, shift:img.shape[1] - shift] = True
    warped = np.zeros((img.shape[0], width, 3), np.uint8)
    placed = np.zeros_like(warped)
    warped[:, :src.shape[1]] = src
    placed[:, shift:] = tgt
    none = np.zeros((0, 2))
    cost = seam_cost_canvas(warped, placed, both, none, none, cfg)
    assert np.all(cost[~both] == BLOCKED)
    coarse, rows = coarse_path(cost, both, (shift, img.shape[1] - shift), cfg)
    assert rows == (0, img.shape[0] - 1)
    assert np.all(both[np.arange(rows[0], rows[1] + 1), np.rint(coarse[rows[0]:rows[1] + 1]).astype(int)])
    anchors = np.array([[coarse[100] + 1, 100.0], [coarse[300] - 1, 300.0]])
    seam = refine_path(cost, coarse, rows, anchors, 6, cfg)
    assert seam[100] == round(anchors[0, 0]) and seam[300] == round(anchors[1, 0])
    assert np.abs(np.diff(seam)).max() <= cfg.seam_max_step_px
