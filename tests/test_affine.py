"""The affine vocabulary: apply, invert, compose, the one homogeneous lift, distance from a similarity."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.affine import (apply_affine, as_homogeneous, compose_affine, invert_affine, scaling_about,
                              similarity_deviation)
from sena_warp.errors import GeometryError

AFFINE = np.array([[1.2, 0.3, -40.0], [-0.1, 0.9, 12.0]])
PTS = np.array([[0.0, 0.0], [100.0, 50.0], [-3.5, 7.25]])


def test_apply_and_invert_round_trip_and_singular_refusal():
    back = apply_affine(invert_affine(AFFINE), apply_affine(AFFINE, PTS))
    np.testing.assert_allclose(back, PTS, atol=1e-9)
    np.testing.assert_allclose(apply_affine(AFFINE, PTS[1]), [[1.2 * 100 + 0.3 * 50 - 40, -10 + 45 + 12]])
    stack = np.stack([AFFINE, np.array([[2.0, 0.0, 10.0], [0.0, 0.5, -4.0]])])
    np.testing.assert_allclose(invert_affine(stack)[1], [[0.5, 0.0, -5.0], [0.0, 2.0, 8.0]])
    np.testing.assert_allclose(invert_affine(stack)[0], invert_affine(AFFINE))
    with pytest.raises(GeometryError, match="singular"):
        invert_affine(np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0]]))


def test_compose_applies_the_first_affine_first():
    shift = np.array([[1.0, 0.0, 5.0], [0.0, 1.0, -2.0]])
    composed = compose_affine(AFFINE, shift)
    np.testing.assert_allclose(apply_affine(composed, PTS), apply_affine(AFFINE, apply_affine(shift, PTS)))
    np.testing.assert_allclose(compose_affine(invert_affine(AFFINE), AFFINE), [[1, 0, 0], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(apply_affine(scaling_about(np.array([10.0, 20.0]), 0.5), [[12.0, 16.0]]), [[1.0, -2.0]])


def test_homogeneous_lift_of_affines_only():
    lifted = as_homogeneous(AFFINE)
    np.testing.assert_array_equal(lifted, np.vstack([AFFINE, [0.0, 0.0, 1.0]]))
    homography = np.array([[1.0, 0.1, 3.0], [0.05, 1.0, 2.0], [1e-4, 2e-4, 1.0]])
    np.testing.assert_array_equal(as_homogeneous(homography), homography)


def test_similarity_deviation():
    rot = np.array([[[np.cos(0.3) * 2, -np.sin(0.3) * 2, 5], [np.sin(0.3) * 2, np.cos(0.3) * 2, 1]]])
    shear = np.array([[[1.0, 0.5, 0], [0.0, 1.0, 0]]])
    dev = similarity_deviation(np.concatenate([rot, shear]))
    assert dev[0] == pytest.approx(0.0, abs=1e-12)
    assert dev[1] == pytest.approx(0.6403882032, abs=1e-9)  # singular values of [[1, .5], [0, 1]]: 1.2808, 0.7808
