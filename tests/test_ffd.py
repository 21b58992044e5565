"""Step 4 host path: the paper's blended lattice on a real pair's geometry, the cubic taps, the fitted lattice."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.affine import apply_affine, invert_affine
from sena_warp.config import Config
from sena_warp.canvas import Canvas
from sena_warp.ffd import field_from_lattice, fitted_lattice, lattice_taps, smoothed_blend_lattice
from test_kernels_maps import scene_geometry

CFG = Config(device="cpu")


@pytest.fixture(scope="module")
def geo(udisd_pair):
    img_src, img_tgt = udisd_pair
    return scene_geometry(img_src.shape, img_tgt.shape)


def field_of(geo, affines, cfg=CFG):
    lattice = smoothed_blend_lattice(geo["canvas"], geo["affine_src_to_tgt"], affines, geo["centres_tgt"][: len(affines)],
                                     geo["conf"][: len(affines)], geo["sigma_f"], cfg)
    return field_from_lattice(lattice, geo["canvas"])


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


def test_cubic_taps_reproduce_cv2_resize():
    """The fit's data term samples the lattice exactly as the bicubic upsampling does."""
    rng = np.random.default_rng(3)
    lattice = rng.random((7, 9, 2)).astype(np.float32)
    canvas = Canvas(width=157, height=123, offset_tgt=(0.0, 0.0))
    dense = field_from_lattice(lattice, canvas)
    pts = np.rint(rng.random((300, 2)) * [156, 122])
    index, weight = lattice_taps(pts, canvas, lattice.shape[:2])
    values = np.einsum("nk,nkc->nc", weight, lattice.reshape(-1, 2)[index])
    np.testing.assert_allclose(values, dense[pts[:, 1].astype(int), pts[:, 0].astype(int)], atol=1e-5)


def fit_cfg(**changes):
    return Config(device="cpu", **changes)


def test_fit_recovers_an_affine_field_and_drops_wrong_matches():
    """Bending energy does not penalise an affine field: matches displaced by one are fitted exactly,
    and the field continues affinely beyond them; wrong matches get zero Tukey weight."""
    rng = np.random.default_rng(5)
    canvas = Canvas(width=600, height=400, offset_tgt=(100.0, 0.0))
    affine_src_to_tgt = np.array([[1.0, 0.0, -100.0], [0.0, 1.0, 0.0]])
    pts_tgt = rng.uniform([10, 10], [390, 390], (300, 2))
    correction = lambda p: np.stack([0.01 * p[:, 0] + 2.0, -0.005 * p[:, 1] + 1.0], 1)  # noqa: E731
    offset = np.array([100.0, 0.0])  # the canvas offset o of the target; A_glob^-1 t = t + o here
    pts_src = pts_tgt + offset + correction(pts_tgt)
    pts_src[:10] += 30.0  # wrong matches, still within fit_match_px of A_glob
    fit = fitted_lattice(canvas, affine_src_to_tgt, pts_src, pts_tgt, 500.0, fit_cfg())
    assert np.all(fit.weights[:10] == 0) and np.all(fit.weights[10:] > 0.9)
    field = field_from_lattice(fit.lattice, canvas)
    far = np.array([[30, 200], [560, 300]])  # canvas points outside the matches (source-only, target-only)
    expected = correction(far - offset)
    np.testing.assert_allclose(field[far[:, 1], far[:, 0]], expected, atol=0.05)
