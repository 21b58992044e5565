"""Compositor: the per-frame path, against the numpy compositing reference, for images and planes."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.composite import Compositor
from sena_warp.config import Config
from test_kernels_maps import DEVICES
from test_kernels_remap import composite_reference, scene  # noqa: F401  (scene is a fixture)


@pytest.mark.parametrize("device", DEVICES)
def test_compositor_matches_reference_and_reuses_buffers(scene, device, warp_device):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, alpha = scene
    comp = Compositor(map_src, map_tgt, alpha, Config(device=device, cpu_threads=2))
    out, coverage = comp.apply(img_src, img_tgt)
    expected, covered = composite_reference(img_src, img_tgt, map_src, map_tgt, alpha)
    assert out.shape == (*alpha.shape, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(coverage, np.where(covered, 255, 0))
    assert np.abs(out.astype(np.float64) - expected).max() <= 1.0

    # A second frame pair (swapped content) reuses the buffers and leaves the first result intact.
    first = out.copy()
    out2, _ = comp.apply(img_tgt[:, ::-1].copy(), img_src[:, ::-1].copy())
    np.testing.assert_array_equal(out, first)
    assert not np.array_equal(out2, out)
    assert comp.planned_shapes == ((img_src.shape, img_tgt.shape),)  # one plan and buffer set for both pairs
    comp.apply(np.ascontiguousarray(img_src[:, :, 0]), np.ascontiguousarray(img_tgt[:, :, 0]))
    assert comp.planned_shapes == ((img_src.shape, img_tgt.shape), ((*img_src.shape[:2], 1), (*img_tgt.shape[:2], 1)))


@pytest.mark.parametrize("device", DEVICES)
def test_compositor_planes(scene, device, warp_device):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, alpha = scene
    comp = Compositor(map_src, map_tgt, alpha, Config(device=device))
    plane_src, plane_tgt = np.ascontiguousarray(img_src[:, :, 0]), np.ascontiguousarray(img_tgt[:, :, 0])
    out, coverage = comp.apply(plane_src, plane_tgt)
    expected, covered = composite_reference(plane_src[:, :, None], plane_tgt[:, :, None], map_src, map_tgt, alpha)
    assert out.shape == alpha.shape
    assert np.abs(out.astype(np.float64) - expected[:, :, 0]).max() <= 1.0
    np.testing.assert_array_equal(coverage > 0, covered)


def test_compositor_rejects_mismatched_inputs(scene, warp_device):  # noqa: F811
    img_src, img_tgt, map_src, map_tgt, alpha = scene
    with pytest.raises(ValueError, match="share one"):
        Compositor(map_src[:-1], map_tgt, alpha, Config(device=warp_device))
    comp = Compositor(map_src, map_tgt, alpha, Config(device=warp_device))
    with pytest.raises(ValueError, match="channels"):
        comp.apply(img_src, np.ascontiguousarray(img_tgt[:, :, 0]))
