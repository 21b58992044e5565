"""Seam guard G and the guarded displacement G * D (docs/method.md step 5).

``G = S(R)^gamma_p * (gamma_min + (1 - gamma_min) S(Dn))``, ``R = clip(sdf / b, 0, 1)``,
``S(t) = 6t^5 - 15t^4 + 10t^3`` (monotone on [0, 1], unlike the authors' .py).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring


@wp.func
def smootherstep(t: float) -> float:
    """Perlin's smootherstep 6t^5 - 15t^4 + 10t^3 of t clipped to [0, 1]."""
    t = wp.clamp(t, 0.0, 1.0)
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@wp.kernel
def gate_kernel(
    row0: int,
    sdf_px: wp.array2d(dtype=float),
    density: wp.array2d(dtype=float),
    ramp_px: float,
    gamma_p: float,
    gamma_min: float,
    gate: wp.array2d(dtype=float),
):
    """gate[y, x] = G from the inside-overlap distance (px) and the [0, 1] inlier density."""
    i, x = wp.tid()
    y = row0 + i
    ramp = wp.clamp(sdf_px[y, x] / ramp_px, 0.0, 1.0)
    support = gamma_min + (1.0 - gamma_min) * smootherstep(density[y, x])
    gate[y, x] = wp.pow(smootherstep(ramp), gamma_p) * support


@wp.kernel
def gated_field_kernel(
    row0: int,
    field: wp.array2d(dtype=wp.vec2),
    gate: wp.array2d(dtype=float),
    field_gated: wp.array2d(dtype=wp.vec2),
):
    """field_gated[y, x] = G * D on both components (the authors scale only x)."""
    i, x = wp.tid()
    y = row0 + i
    field_gated[y, x] = gate[y, x] * field[y, x]
