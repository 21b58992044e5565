"""Step 4 host path: ffd_field_canvas on a real pair's geometry."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.affine import apply_affine, invert_affine
from sena_warp.config import Config
from sena_warp.ffd import ffd_field_canvas
from test_kernels_maps import scene_geometry

CFG = Config(device="cpu")


@pytest.fixture(scope="module")
def geo(udisd_pair):
    img_src, img_tgt = udisd_pair
    return scene_geometry(img_src.shape, img_tgt.shape)


def field_of(geo, affines, cfg=CFG):
    return ffd_field_canvas(
        geo["canvas"], geo["affine_src_to_tgt"], affines, geo["centres_tgt"][: len(affines)], geo["conf"][: len(affines)],
        geo["sigma_f"], cfg,
    )


def test_local_affines_equal_to_global_give_zero_field(geo):
    affines = np.repeat(geo["affine_src_to_tgt"][None], 4, axis=0)
    field = field_of(geo, affines)
    assert field.shape == (*geo["canvas"].shape, 2) and field.dtype == np.float32
    assert np.abs(field).max() < 1e-4


def test_single_local_affine_reproduces_its_displacement(geo):
    """With one T, D(u) = T^-1 p_t - A^-1 p_t is affine in u: lattice blur and bicubic upsampling keep it."""
    canvas = geo["canvas"]
    affine_local = geo["affines_src_to_tgt"][:1]
    field = field_of(geo, affine_local)
    u = np.stack(np.meshgrid(np.arange(canvas.width), np.arange(canvas.height)), axis=-1).astype(np.float64)
    p_tgt = u - np.asarray(canvas.offset_tgt)
    expected = (apply_affine(invert_affine(affine_local[0]), p_tgt)
                - apply_affine(invert_affine(geo["affine_src_to_tgt"]), p_tgt)).reshape(p_tgt.shape)
    assert np.abs(expected).max() > 3.0
    margin_y, margin_x = 2 * canvas.height // 64, 2 * canvas.width // 64  # two lattice nodes from the border
    inner = (slice(margin_y, -margin_y), slice(margin_x, -margin_x))
    assert np.abs(field[inner] - expected[inner]).max() < 0.05


def test_field_is_clipped_to_d_max(geo):
    affines = geo["affines_src_to_tgt"].copy()
    affines[:, :, 2] += 500.0
    cfg = CFG.replace(d_max_px=25.0)
    field = field_of(geo, affines, cfg)
    assert np.abs(field).max() <= cfg.d_max_px + 1e-3
    assert np.abs(field).max() > cfg.d_max_px - 0.5
