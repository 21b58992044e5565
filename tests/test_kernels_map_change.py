"""``kernels/map_change.py`` through ``video/maps.map_change_px``: the per-frame map change figure against
numpy's strided version of it, exactly (the same float32 arithmetic, the same pixels counted)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sena_warp.video.maps import map_change_px, sampled_mask
from test_video_stitch import synthetic_maps


def numpy_map_change(before, after, shape_src, percentile, shape_tgt=None, stride=1) -> float:
    """The figure as numpy gives it on the strided grid: |after - before| where both sample the source
    (and the target samples its plane, with ``shape_tgt``)."""
    map_before, map_after = before.map_src_luma[::stride, ::stride], after.map_src_luma[::stride, ::stride]
    both = sampled_mask(map_before, shape_src) & sampled_mask(map_after, shape_src)
    if shape_tgt is not None:
        both &= sampled_mask(after.map_tgt_luma[::stride, ::stride], shape_tgt)
    if not both.any():
        return 0.0
    delta = map_after - map_before
    return float(np.percentile(np.sqrt(delta[:, :, 0] * delta[:, :, 0] + delta[:, :, 1] * delta[:, :, 1])[both],
                               percentile))


@pytest.mark.parametrize("stride", [1, 3, 4])
def test_the_kernels_figure_is_numpys_on_maps_with_holes_and_edges(stride):
    rng = np.random.default_rng(stride)

    def noisy(map_src: np.ndarray) -> None:
        map_src[:] += rng.normal(scale=4.0, size=map_src.shape).astype(np.float32)
        map_src[rng.random(map_src.shape[:2]) < 0.15] = np.nan

    before, after = synthetic_maps(0.0, 300, (62, 90), noisy), synthetic_maps(3.0, 300, (62, 90), noisy)
    map_tgt = after.map_tgt_luma.copy()
    map_tgt[rng.random(after.shape) < 0.15] = np.nan
    after = replace(after, map_tgt_luma=map_tgt)
    for shape_tgt in (None, (62, 70)):
        for percentile in (50.0, 99.0):
            figure = map_change_px(before, after, (55, 100), percentile, shape_tgt, stride)
            assert figure == numpy_map_change(before, after, (55, 100), percentile, shape_tgt, stride)
            assert figure > 2.0  # the source map moved by 3 px and noise


def test_maps_that_share_no_sampled_pixel_change_by_nothing():
    before, after = synthetic_maps(0.0, 300), synthetic_maps(3.0, 300, change=lambda m: m.fill(np.nan))
    assert map_change_px(before, after, (40, 60), 99.0, stride=4) == 0.0
