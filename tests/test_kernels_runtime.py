"""Runtime: device choice, row bands, threaded launches equal one launch, pre-warm covers every kernel module."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import warp as wp

from sena_warp.errors import InputError
from sena_warp.kernels import runtime
from test_kernels_maps import HAS_CUDA, scene_geometry, smooth_field, source_map_reference
from test_kernels_remap import run_remap


def test_resolve_device():
    assert runtime.resolve_device("auto") == ("cuda" if HAS_CUDA else "cpu")
    assert runtime.resolve_device("cpu") == "cpu"
    with pytest.raises(InputError, match="unknown device"):
        runtime.resolve_device("tpu")


@pytest.mark.skipif(HAS_CUDA, reason="a GPU is present")
def test_cuda_without_gpu_is_an_input_error():
    with pytest.raises(InputError, match="no CUDA GPU"):
        runtime.resolve_device("cuda")


@pytest.mark.parametrize("height, bands", [(1, 4), (7, 3), (480, 16), (5, 5)])
def test_row_bands_cover_each_row_once(height, bands):
    pieces = runtime.row_bands(height, bands)
    rows = np.concatenate([np.arange(r0, r0 + n) for r0, n in pieces])
    np.testing.assert_array_equal(rows, np.arange(height))
    assert len(pieces) == min(height, bands) and min(n for _, n in pieces) >= height // bands


def test_threaded_launch_equals_single_launch(udisd_pair, warp_device):
    img_src, img_tgt = udisd_pair
    geo = scene_geometry(img_src.shape, img_tgt.shape)
    map_src = source_map_reference(geo["canvas"], geo["affine_src_to_tgt"], smooth_field(geo["canvas"].shape, 8.0))
    map_src = map_src.astype(np.float32)
    out_one, valid_one = run_remap(img_src, map_src, warp_device, threads=1)
    for threads in (2, 3, 7):
        out, valid = run_remap(img_src, map_src, warp_device, threads=threads)
        np.testing.assert_array_equal(out, out_one)
        np.testing.assert_array_equal(valid, valid_one)
    assert valid_one.any()


def test_prewarm_imports_every_kernel_module(warp_device):
    runtime.prewarm(warp_device)
    for name in ("ffd", "gate", "sampling", "remap", "composite"):
        module = sys.modules[f"sena_warp.kernels.{name}"]
        assert any(isinstance(obj, wp.Kernel) for obj in vars(module).values())
