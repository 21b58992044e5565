"""Affine transforms, the one geometry vocabulary of every stage (and of the evaluation's baselines).

An affine is a ``(2, 3)`` float64 matrix named by direction: ``affine_a_to_b`` maps ``[x, y, 1]`` of
frame a to frame b. Points are float64 ``(N, 2)`` arrays of ``(x, y)`` pixels. Affines compose and
invert in this form; :func:`as_homogeneous` is the one place a ``(2, 3)`` becomes ``(3, 3)``, for
code that treats affines and homographies alike.
"""

from __future__ import annotations

import numpy as np

from .errors import GeometryError

HOMOGENEOUS_ROW = (0.0, 0.0, 1.0)  # the bottom row of an affine's 3x3 matrix


def as_homogeneous(matrix: np.ndarray) -> np.ndarray:
    """``(3, 3)`` float64 of a ``(2, 3)`` affine (bottom row 0, 0, 1); a ``(3, 3)`` homography as it is."""
    matrix = np.asarray(matrix, dtype=np.float64)
    return matrix if matrix.shape == (3, 3) else np.vstack([matrix, HOMOGENEOUS_ROW])


def apply_affine(affine: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map ``(N, 2)`` ``(x, y)`` points through a ``(2, 3)`` affine; returns ``(N, 2)`` float64."""
    affine = np.asarray(affine, dtype=np.float64)
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    return pts @ affine[:, :2].T + affine[:, 2]


def compose_affine(affine_b_to_c: np.ndarray, affine_a_to_b: np.ndarray) -> np.ndarray:
    """``affine_a_to_c``: first ``affine_a_to_b``, then ``affine_b_to_c``; ``(2, 3)`` float64."""
    return (as_homogeneous(affine_b_to_c) @ as_homogeneous(affine_a_to_b))[:2]


def invert_affine(affine: np.ndarray) -> np.ndarray:
    """Inverse of a ``(2, 3)`` affine, or of each in a ``(..., 2, 3)`` stack (``a_to_b`` -> ``b_to_a``), float64.

    Raises ``GeometryError`` when a linear part is singular (the model collapses the image).
    """
    affine = np.asarray(affine, dtype=np.float64)
    linear = affine[..., :2]
    # Relative test: |det| against the squared size of the entries, so pixel scale does not matter.
    scale_sq = np.maximum(1.0, np.abs(linear).max(axis=(-2, -1)) ** 2)
    if np.any(np.abs(np.linalg.det(linear)) < np.finfo(np.float64).eps * scale_sq):
        raise GeometryError("the affine model is singular (it collapses the image); check the matches")
    linear_inv = np.linalg.inv(linear)
    translation_inv = -np.einsum("...ij,...j->...i", linear_inv, affine[..., 2])
    return np.concatenate([linear_inv, translation_inv[..., None]], axis=-1)


def scaling_about(centre: np.ndarray, scale: float) -> np.ndarray:
    """The ``(2, 3)`` affine ``p -> (p - centre) * scale`` (a normalisation of coordinates about ``centre``)."""
    return np.array([[scale, 0.0, -scale * centre[0]], [0.0, scale, -scale * centre[1]]])


def similarity_deviation(affines: np.ndarray) -> np.ndarray:
    """Per affine of a ``(J, 2, 3)`` stack, how far its linear part is from a similarity: the
    singular-value ratio s_max / s_min - 1; 0 for a rotation + uniform scale, growing with shear and
    anisotropic scale. ``(J,)`` float64."""
    sv = np.linalg.svd(np.asarray(affines, np.float64)[:, :, :2], compute_uv=False)
    return sv[:, 0] / np.maximum(sv[:, 1], 1e-12) - 1.0
