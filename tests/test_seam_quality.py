"""Seam quality on real pairs, both input orders: the panorama is produced, the step-9
reconstruction puts every warped-source anchor on its target anchor (median <= 1.5 px), and inside
the transition band the two images differ less than a linear feather's over the whole overlap.

The figures are ``sena_warp.evaluation.figures.seam_figures`` (docs/evaluation.md: anchor residual, seam and feather MAD).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation.figures import feather_mad, seam_figures
from sena_warp.stitch import stitch_images
from helpers import read_pair

MAX_MEDIAN_RESIDUAL_PX = 1.5
# Pairs of different kinds: the bundled udisd_test_000001 and graf_gt (a planar scene with a ground
# truth), and from ../shared strong parallax (dhw_carpark) and a wide street with repeated facades
# (spw_0). Each runs in both input orders, so the left view comes first once and second once (the
# rig detection must pick it either way).
PAIRS = ("udisd_test_000001", "graf_gt", pytest.param("dhw_carpark", marks=pytest.mark.shared),
         pytest.param("spw_0", marks=pytest.mark.shared))


ORDERS = ("ab", "ba")


def _pair(folder: Path, order: str) -> tuple[np.ndarray, np.ndarray]:
    img_a, img_b = read_pair(folder)
    return (img_a, img_b) if order == "ab" else (img_b, img_a)


def _check_seam(img_first: np.ndarray, img_second: np.ndarray) -> None:
    cfg = Config(device="cpu")
    pano = stitch_images(img_first, img_second, cfg)
    coverage = pano.image[:, :, 3] > 0
    # the panorama holds both inputs: each view shows at least a tenth of it, and it covers nearly all of
    # the larger input (thin strips and the source past the target where the views disagree are left out)
    maps = pano.maps
    alpha = maps.alpha_input
    shown_src = coverage & np.isfinite(maps.map_src_input[..., 0]) & (alpha >= 0.5)
    shown_tgt = coverage & np.isfinite(maps.map_tgt_input[..., 0]) & (alpha < 0.5)
    assert min(shown_src.sum(), shown_tgt.sum()) > 0.1 * coverage.sum()
    assert coverage.sum() > 0.99 * max(img_first.shape[0] * img_first.shape[1], img_second.shape[0] * img_second.shape[1])
    figures = seam_figures(img_first, img_second, pano, cfg)
    assert figures["anchors"] >= 3  # two edge extensions and at least one real match
    assert figures["anchor_residual_px"] <= MAX_MEDIAN_RESIDUAL_PX
    assert figures["seam_mad"] < figures["feather_mad"]


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("pair", PAIRS)
def test_pair_seam(pair_folder, pair, order):
    _check_seam(*_pair(pair_folder(pair), order))


def test_feather_mad_is_the_mean_difference_over_the_overlap_extent():
    """A linear feather blends over the whole overlap x-extent: every valid pixel there counts, none outside."""
    valid = np.ones((6, 20), bool)
    overlap = np.zeros((6, 20), bool)
    overlap[1:5, 8:14] = True
    src = np.zeros((6, 20, 3), np.uint8)
    tgt = np.zeros((6, 20, 3), np.uint8)
    tgt[:, 8:14] = 10  # every row of the overlap's columns counts, as the feather ramps per column
    tgt[:, :8] = 200  # outside the overlap's x-extent: ignored
    assert feather_mad(src, valid, tgt, valid, overlap) == pytest.approx(10.0)
