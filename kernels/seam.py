"""Seam maps: per-pixel source map, target map and alpha around the seam (docs/method.md step 9, paper
"Partitioning and Reconstruction").

Per canvas row y the host gives the seam x ``s(y)`` (interpolated between target anchors), the
source row ``y + dy(y)`` and the x shift ``dx(y)`` that move the source anchors onto the target
anchors. For pixel (x, y), with t = x - s(y):

* alpha = the linear ramp ``clip(1/2 - t/T, 0, 1)`` across the transition T, convolved with a
  Gaussian of sigma across the seam (the paper's "light Gaussian smoothing", closed form below);
  it differs from the plain ramp only within a few sigma of the ramp's ends, and is 0 or 1 exactly
  where it is within 1e-4 of them, as the compositor shows it.
* the step-6 source map is resampled at ``(x + f dx, y + f dy)`` where the fade f is 1 inside the
  transition and falls to 0 (smootherstep) over ``fade_px`` beyond it, so the source far from the
  seam keeps its step-6 shape.
* the target map is ``u - o``.
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS
from sena_warp.kernels.gate import smootherstep

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring

INV_SQRT2 = 0.7071067811865476
INV_SQRT_2PI = 0.3989422804014327
ALPHA_TAIL_SIGMAS = wp.constant(8.0)  # the smoothed ramp is within 1e-4 of 0 or 1 this many sigmas past its ends


@wp.func
def smoothed_positive_part(z: float, sigma: float) -> float:
    """E[max(z + n, 0)] for n ~ N(0, sigma^2): z Phi(z / sigma) + sigma phi(z / sigma)."""
    u = z / sigma
    cdf = 0.5 * (1.0 + wp.erf(u * INV_SQRT2))
    pdf = INV_SQRT_2PI * wp.exp(-0.5 * u * u)
    return z * cdf + sigma * pdf


@wp.func
def source_alpha(t: float, transition_px: float, sigma_px: float) -> float:
    """Weight of the source at signed distance t = x - seam_x: the ramp clip(1/2 - t/T, 0, 1)
    (= ((T/2 - t)+ - (-T/2 - t)+) / T), Gaussian-smoothed across the seam when sigma > 0."""
    half = 0.5 * transition_px
    if sigma_px <= 0.0:
        return wp.clamp(0.5 - t / transition_px, 0.0, 1.0)
    ramp = smoothed_positive_part(half - t, sigma_px) - smoothed_positive_part(-half - t, sigma_px)
    return wp.clamp(ramp / transition_px, 0.0, 1.0)


@wp.func
def shown_source_alpha(t: float, transition_px: float, sigma_px: float) -> float:
    """:func:`source_alpha` as the panorama shows it: exactly 0 or 1 where it is within 1e-4 of them
    (the compositor's band rule, ``kernels/composite.py``'s ``pixel_rule``). The smoothed ramp's tails
    pass 1e-4 well within ``ALPHA_TAIL_SIGMAS`` of the ramp's ends, so there no erf or exp is evaluated."""
    if wp.abs(t) >= 0.5 * transition_px + ALPHA_TAIL_SIGMAS * sigma_px:
        return wp.where(t > 0.0, 0.0, 1.0)
    a = source_alpha(t, transition_px, sigma_px)
    return wp.where(a > 0.9999, 1.0, wp.where(a < 0.0001, 0.0, a))


@wp.func
def correction_fade(t: float, transition_px: float, fade_px: float) -> float:
    """1 within the transition, smootherstep down to 0 over fade_px beyond it."""
    return 1.0 - smootherstep((wp.abs(t) - 0.5 * transition_px) / fade_px)


@wp.func
def bilinear_map(map_canvas: wp.array2d(dtype=wp.vec2), p: wp.vec2) -> wp.vec2:
    """map_canvas bilinearly interpolated at canvas (x, y), clamped to the grid."""
    x = wp.clamp(p[0], 0.0, float(map_canvas.shape[1] - 1))
    y = wp.clamp(p[1], 0.0, float(map_canvas.shape[0] - 1))
    x0 = wp.min(int(wp.floor(x)), map_canvas.shape[1] - 1)
    y0 = wp.min(int(wp.floor(y)), map_canvas.shape[0] - 1)
    x1 = wp.min(x0 + 1, map_canvas.shape[1] - 1)
    y1 = wp.min(y0 + 1, map_canvas.shape[0] - 1)
    fx = x - float(x0)
    fy = y - float(y0)
    top = (1.0 - fx) * map_canvas[y0, x0] + fx * map_canvas[y0, x1]
    bottom = (1.0 - fx) * map_canvas[y1, x0] + fx * map_canvas[y1, x1]
    return (1.0 - fy) * top + fy * bottom


@wp.kernel
def seam_maps_kernel(
    row0: int,
    map_src_in: wp.array2d(dtype=wp.vec2),
    seam_x: wp.array(dtype=float),
    src_row_y: wp.array(dtype=float),
    shift_x: wp.array(dtype=float),
    offset_tgt: wp.vec2,
    transition_px: float,
    smooth_sigma_px: float,
    fade_px: float,
    map_src_out: wp.array2d(dtype=wp.vec2),
    map_tgt_out: wp.array2d(dtype=wp.vec2),
    alpha_out: wp.array2d(dtype=float),
):
    """One canvas pixel (x, y = row0 + i): reconstructed source map, target map, source alpha."""
    i, x = wp.tid()
    y = row0 + i
    fx = float(x)
    fy = float(y)
    t = fx - seam_x[y]
    fade = correction_fade(t, transition_px, fade_px)
    q = wp.vec2(fx + fade * shift_x[y], fy + fade * (src_row_y[y] - fy))
    map_src_out[y, x] = bilinear_map(map_src_in, q)
    map_tgt_out[y, x] = wp.vec2(fx, fy) - offset_tgt
    alpha_out[y, x] = shown_source_alpha(t, transition_px, smooth_sigma_px)


@wp.kernel
def displaced_map_kernel(
    row0: int,
    map_in: wp.array2d(dtype=wp.vec2),
    field: wp.array2d(dtype=wp.vec2),
    map_out: wp.array2d(dtype=wp.vec2),
):
    """One canvas pixel (x, y = row0 + i): the map resampled at (x, y) + field[y, x] (the switch
    alignment's ``M_a(u) = M_s(u + C(u))``)."""
    i, x = wp.tid()
    y = row0 + i
    map_out[y, x] = bilinear_map(map_in, wp.vec2(float(x), float(y)) + field[y, x])
