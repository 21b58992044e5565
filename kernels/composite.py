"""Per-frame compositing along a seam (docs/method.md "Maps, not images"), with the gains and the seam blend.

The source is shown on one side of the seam, the target on the other; across a transition of width T
the two are mixed by ``kernels/seam.py``'s ``source_alpha`` (the rule the seam maps' alpha follows). Each side gets its own per-channel affine gain (exposure
compensation) and, within ``lf_px`` of the seam, a per-line offset that fades linearly to 0 (the
low-frequency part of the seam blend: what is left of an exposure difference after the gains is
spread over a wide band, while detail switches sides within T): added in grey levels, or (an
image's panorama) a relative change of the side's gain, so that it is a smooth gain and changes no
colour or contrast. The same kind of offset, per position
along it, fades out from each of the target's two borders across the seam's direction (its top and
bottom edges for a horizontal rig): beyond the seam's ends the canvas switches from the target to the
source there, and the border blend hides what the gains leave of that step too.

The seam is one position per *line*: per canvas row (x of the seam) when ``lines_are_rows`` is 1,
per canvas column (y of the seam) for a vertical rig. The source lies at positions below the seam.

Fixed-point plan. The maps do not change between frames, so what depends only on them (validity,
which side, tap positions, sub-pixel fractions, coverage) is worked out once per map set by
``composite_plan_kernel``; the per-frame ``COMPOSITE_FRAME_KERNELS`` read one int64 word per pixel.
A plan word: bits 0-1 the kind (KIND_*), bits 2-12 fx and 13-23 fy (bilinear fractions in
1/1024 px, 0..1024), bits 24+ the flat element offset of the top-left tap in the image of the side
shown (the source for a band pixel, whose target word, same layout, is in ``plan_tgt``).

Runs. Most of a video's canvas is one side alone, further from the seam and the borders than any
offset reaches (whatever the frame's seam within its band does). Per canvas row ``row_runs_kernel``
finds from the plan the longest run of each side there (again when the border blend or the offsets'
reach changes), and ``frame_runs_kernel`` fits them to each frame's seam. The target's run is the unwarped target
at whole pixels: each pixel is its target element through the frame's gains, which
``gain_table_kernel`` tabulates per frame, so the frame kernel copies it through the table. The
source's run is sampled and gained without working out each pixel's seam, blend and offsets.

The per-pixel loops over a thread's columns are ``while`` loops: Warp's CPU code for a ``range()``
with run-time bounds steps a general iterator (its step's sign unknown), a cost of its own per pixel
(``kernels/seam_path.py`` measured it first).
"""

from __future__ import annotations

import warp as wp

from sena_warp.kernels import MODULE_OPTIONS
from sena_warp.kernels.seam import source_alpha

wp.set_module_options(MODULE_OPTIONS)  # see the package docstring

KIND_FILL = wp.constant(0)  # no side covers the pixel: the fill value
KIND_SOURCE = wp.constant(1)  # the source alone
KIND_TARGET = wp.constant(2)  # the target alone
KIND_BAND = wp.constant(3)  # both valid near the seam: the side (or the mix) follows the seam of the frame
FRAC_BITS = wp.constant(10)  # sub-pixel steps of 1/1024 px: the value moves < 0.25 grey level
FRAC_ONE = wp.constant(1 << 10)
FRAC_MASK = wp.constant(2047)  # 11 bits: a fraction may be exactly 1 at the last row / column
ALPHA_TAIL_SIGMAS = wp.constant(8.0)  # the smoothed ramp is within 1e-4 of 0 or 1 this many sigmas past its ends


@wp.struct
class Planes:
    """A frame pair on the device: the source's and the target's (H, W, C) uint8 elements, flat, and
    ``steps`` = (source x step, source y step, target x step, target y step) in elements."""

    src: wp.array(dtype=wp.uint8)
    tgt: wp.array(dtype=wp.uint8)
    steps: wp.vec4i


@wp.struct
class Layout:
    """The seam's geometry on the canvas (``composite.SeamLayout``): lines are canvas rows when
    ``lines_are_rows`` is 1, else columns; widths in canvas pixels."""

    lines_are_rows: int
    band_px: float
    transition_px: float
    smooth_sigma_px: float
    lf_px: float


@wp.struct
class Border:
    """The border blend: with ``on`` 1, each side's offsets per position along the target's two borders
    (``src``, ``tgt``: (2, positions, C) int in 1/2**20 grey levels, flat; border k at line coordinate
    ``lines[k]``; ``second``: border 1's first element, positions x C)."""

    on: int
    lines: wp.vec2
    second: int
    src: wp.array(dtype=int)
    tgt: wp.array(dtype=int)


@wp.struct
class SeamState:
    """A frame's seam: its position per line (``seam``) and each side's low-frequency offsets per line
    (``lf_src``, ``lf_tgt``: (lines, C) int in 1/2**20 grey levels, flat)."""

    seam: wp.array(dtype=float)
    lf_src: wp.array(dtype=int)
    lf_tgt: wp.array(dtype=int)


@wp.struct
class Gains:
    """A frame's gains per channel of each side: gains in 1/2**12, biases in 1/2**20 grey levels;
    ``tone`` = (knee, white, peak) (knee and white in 1/2**20 grey levels, white 0: no knee; peak 1: the
    channels near a pixel's largest share its knee, ``adjusted``); ``relative`` 1:
    the seam's and the borders' offsets change each side's gain relatively (``with_offset``), 0: they
    are added; ``table``: the target's gains tabulated per channel and grey level
    (``gain_table_kernel``)."""

    gain_src: wp.vec4i
    bias_src: wp.vec4i
    gain_tgt: wp.vec4i
    bias_tgt: wp.vec4i
    tone: wp.vec3i
    relative: int
    table: wp.array(dtype=wp.uint8)


@wp.func
def lf_weight(d: float, lf_px: float) -> float:
    """How much of a line's low-frequency offset a pixel at distance d from the seam gets."""
    if lf_px <= 0.0:
        return 0.0
    return wp.max(0.0, 1.0 - wp.abs(d) / lf_px)


@wp.func
def side_offset(lf: float, lf_line: wp.array(dtype=int), lo: int, border: wp.vec2, border_pos: wp.array(dtype=int),
                bo: int, second: int) -> int:
    """A side's low-frequency offset of one channel: its seam line's (element ``lo``) weighted ``lf``,
    plus each border's at this position (elements ``bo`` and ``bo + second``) weighted ``border``."""
    off = float(0.0)
    if lf > 0.0:
        off = lf * float(lf_line[lo])
    if border[0] > 0.0:
        off += border[0] * float(border_pos[bo])
    if border[1] > 0.0:
        off += border[1] * float(border_pos[bo + second])
    return int(off)


@wp.func
def border_weights(line: int, border_lines: wp.vec2, border_on: int, lf_px: float) -> wp.vec2:
    """How much of each border's offsets a pixel on ``line`` gets (0 without a border blend)."""
    if border_on == 0:
        return wp.vec2(0.0, 0.0)
    return wp.vec2(lf_weight(float(line) - border_lines[0], lf_px), lf_weight(float(line) - border_lines[1], lf_px))


@wp.func
def tap_origin(p: wp.vec2, height: int, width: int) -> wp.vec2:
    """(x0, y0) top-left bilinear tap of a valid (x, y), kept at x0 <= W-2, y0 <= H-2 (when W, H >= 2)."""
    x0 = wp.min(wp.floor(p[0]), float(wp.max(width - 2, 0)))
    y0 = wp.min(wp.floor(p[1]), float(wp.max(height - 2, 0)))
    return wp.vec2(x0, y0)


@wp.func
def plan_word(kind: int, p: wp.vec2, shape: wp.vec3i) -> wp.int64:
    """The plan word of sampling an (H, W, C) image (``shape``) at a valid (x, y), tagged ``kind``."""
    o = tap_origin(p, shape[0], shape[1])
    fx = int((p[0] - o[0]) * float(FRAC_ONE) + 0.5)
    fy = int((p[1] - o[1]) * float(FRAC_ONE) + 0.5)
    offset = (int(o[1]) * shape[1] + int(o[0])) * shape[2]
    return (wp.int64(offset) << wp.int64(24)) | (wp.int64(fy) << wp.int64(13)) | (wp.int64(fx) << wp.int64(2)) \
        | wp.int64(kind)


@wp.func
def inside(p: wp.vec2, shape: wp.vec3i) -> bool:
    return p[0] >= 0.0 and p[1] >= 0.0 and p[0] <= float(shape[1] - 1) and p[1] <= float(shape[0] - 1)


@wp.func
def line_and_position(x: int, y: int, lines_are_rows: int) -> wp.vec2i:
    if lines_are_rows != 0:
        return wp.vec2i(y, x)
    return wp.vec2i(x, y)


@wp.func(inline=True)  # per pixel: inlined, its array arguments are not copied per call
def plan_pixel(q: int, lp: wp.vec2i, p_src: wp.vec2, p_tgt: wp.vec2, seam: wp.array(dtype=float), layout: Layout,
               shape_src: wp.vec3i, shape_tgt: wp.vec3i, plan: wp.array(dtype=wp.int64),
               plan_tgt: wp.array(dtype=wp.int64)) -> int:
    """plan[q] (and plan_tgt[q] for a band pixel) of a canvas pixel at (line, position) ``lp`` that samples the
    source at ``p_src`` and the target at ``p_tgt`` (NaN: nowhere); returns its coverage, 255 or 0.

    Where both sides are valid, pixels within ``layout.band_px`` of the seam are band pixels (the frame
    decides the side); the others show the source below the seam and the target above it."""
    ok_src = inside(p_src, shape_src)
    ok_tgt = inside(p_tgt, shape_tgt)
    d = float(lp[1]) - seam[lp[0]]
    word = wp.int64(KIND_FILL)
    if ok_src and ok_tgt:
        if wp.abs(d) <= layout.band_px:
            word = plan_word(KIND_BAND, p_src, shape_src)
            plan_tgt[q] = plan_word(KIND_TARGET, p_tgt, shape_tgt)
        elif d < 0.0:
            word = plan_word(KIND_SOURCE, p_src, shape_src)
        else:
            word = plan_word(KIND_TARGET, p_tgt, shape_tgt)
    elif ok_src:
        word = plan_word(KIND_SOURCE, p_src, shape_src)
    elif ok_tgt:
        word = plan_word(KIND_TARGET, p_tgt, shape_tgt)
    plan[q] = word
    return wp.where(ok_src or ok_tgt, 255, 0)


@wp.kernel
def composite_plan_kernel(
    row0: int,
    col_step: int,
    width: int,
    map_src: wp.array2d(dtype=wp.vec2),
    map_tgt: wp.array2d(dtype=wp.vec2),
    seam: wp.array(dtype=float),
    layout: Layout,
    shape_src: wp.vec3i,
    shape_tgt: wp.vec3i,
    plan: wp.array(dtype=wp.int64),
    plan_tgt: wp.array(dtype=wp.int64),
    coverage: wp.array2d(dtype=wp.uint8),
):
    """Per canvas pixel q = y * Wc + x: plan[q], plan_tgt[q] for band pixels, coverage 255 / 0
    (``plan_pixel``). Thread (i, j) does row ``row0 + i``, columns j, j + col_step, ...
    (``runtime.launch_row_loops``): a blended-in map makes a plan every frame.
    """
    i, j = wp.tid()
    y = row0 + i
    x = j
    while x < width:  # while loops, not range(): see the module docstring
        q = y * width + x
        covered = plan_pixel(q, line_and_position(x, y, layout.lines_are_rows), map_src[y, x], map_tgt[y, x], seam,
                             layout, shape_src, shape_tgt, plan, plan_tgt)
        coverage[y, x] = wp.uint8(covered)
        x = x + col_step


@wp.struct
class Window:
    """An output window on a canvas: output pixel (x, y) shows canvas (x, y) + corner, corner = ``whole`` (x, y)
    + ``frac`` (each in [0, 1)); the target pixel it shows is (x, y) - ``origin_tgt`` (where target pixel
    (0, 0) sits on the window)."""

    whole: wp.vec2i
    frac: wp.vec2
    origin_tgt: wp.vec2


@wp.func(inline=True)
def field_tap(field: wp.array2d(dtype=wp.vec2), x: int, y: int) -> wp.vec2:
    """field[y, x], NaN off the field."""
    if x < 0 or y < 0 or y >= field.shape[0] or x >= field.shape[1]:
        return wp.vec2(wp.nan, wp.nan)
    return field[y, x]


@wp.func(inline=True)
def window_sample(field: wp.array2d(dtype=wp.vec2), x: int, y: int, window: Window) -> wp.vec2:
    """A canvas map at window pixel (x, y) (canvas (x, y) + the corner), bilinearly: a tap of weight 0 does
    not count, a counted tap off the canvas or NaN makes NaN (``video.maps.translated``'s rule)."""
    cx = x + window.whole[0]
    cy = y + window.whole[1]
    fx = window.frac[0]
    fy = window.frac[1]
    if cx >= 0 and cy >= 0 and cx + 1 < field.shape[1] and cy + 1 < field.shape[0]:  # every tap on the canvas
        top = (1.0 - fx) * field[cy, cx] + fx * field[cy, cx + 1]
        bottom = (1.0 - fx) * field[cy + 1, cx] + fx * field[cy + 1, cx + 1]
        if fx <= 0.0:
            top = field[cy, cx]
            bottom = field[cy + 1, cx]
        if fy <= 0.0:
            return top
        return (1.0 - fy) * top + fy * bottom
    top = field_tap(field, cx, cy)
    if fx > 0.0:
        top = (1.0 - fx) * top + fx * field_tap(field, cx + 1, cy)
    if fy <= 0.0:
        return top
    bottom = field_tap(field, cx, cy + 1)
    if fx > 0.0:
        bottom = (1.0 - fx) * bottom + fx * field_tap(field, cx + 1, cy + 1)
    return (1.0 - fy) * top + fy * bottom


@wp.kernel
def window_plan_kernel(
    row0: int,
    col_step: int,
    width: int,
    map_src: wp.array2d(dtype=wp.vec2),
    window: Window,
    seam: wp.array(dtype=float),
    layout: Layout,
    shape_src: wp.vec3i,
    shape_tgt: wp.vec3i,
    plan: wp.array(dtype=wp.int64),
    plan_tgt: wp.array(dtype=wp.int64),
    coverage: wp.array2d(dtype=wp.uint8),
):
    """``composite_plan_kernel`` for the output window ``window`` on a canvas whose source map is ``map_src``:
    per window pixel q = y * W + x, the source where the canvas position it shows samples it
    (``window_sample``), the target at (x, y) - ``window.origin_tgt``; ``seam`` and ``layout`` the window's.
    Each pixel samples the inputs once, and no map of the window is made (a moving rig's steady window, a
    new one every frame)."""
    i, j = wp.tid()
    y = row0 + i
    x = j
    while x < width:
        q = y * width + x
        p_tgt = wp.vec2(float(x), float(y)) - window.origin_tgt
        covered = plan_pixel(q, line_and_position(x, y, layout.lines_are_rows), window_sample(map_src, x, y, window),
                             p_tgt, seam, layout, shape_src, shape_tgt, plan, plan_tgt)
        coverage[y, x] = wp.uint8(covered)
        x = x + col_step


@wp.func
def word_offset(word: wp.int64) -> int:
    return int(word >> wp.int64(24))


@wp.func
def word_fx(word: wp.int64) -> int:
    return int((word >> wp.int64(2)) & wp.int64(FRAC_MASK))


@wp.func
def word_fy(word: wp.int64) -> int:
    return int((word >> wp.int64(13)) & wp.int64(FRAC_MASK))


@wp.func
def sample_fixed(img: wp.array(dtype=wp.uint8), p: int, fx: int, fy: int, step_x: int, step_y: int) -> int:
    """The element at flat offset p bilinearly sampled at fractions (fx, fy), in 1/2**20 grey levels."""
    if fx == 0 and fy == 0:  # an exact copy (the unwarped target): one load
        return int(img[p]) << (2 * FRAC_BITS)
    top = (FRAC_ONE - fx) * int(img[p]) + fx * int(img[p + step_x])
    bottom = (FRAC_ONE - fx) * int(img[p + step_y]) + fx * int(img[p + step_y + step_x])
    return (FRAC_ONE - fy) * top + fy * bottom


GAIN_BITS = wp.constant(12)  # gains in 1/4096
ONE20 = wp.constant(1 << 20)  # one grey level in sample units


@wp.func
def grey_level(sample: int) -> wp.uint8:
    """A sample in 1/2**20 grey levels rounded to uint8, saturating at both ends."""
    return wp.uint8(wp.clamp((sample + (1 << (2 * FRAC_BITS - 1))) >> (2 * FRAC_BITS), 0, 255))


@wp.func
def knee_line(v: int, gain: int, bias: int, knee: int, white: int) -> int:
    """The gain's line at v (1/2**20 grey levels), bent at ``knee`` to run straight on to (white, white)
    where the knee's own value is below white (``gains.tone_curve``)."""
    at_knee = int((wp.int64(knee) * wp.int64(gain)) >> wp.int64(GAIN_BITS)) + bias
    if v > knee and at_knee < white:
        return at_knee + int(wp.int64(v - knee) * wp.int64(white - at_knee) / wp.int64(white - knee))
    return int((wp.int64(v) * wp.int64(gain)) >> wp.int64(GAIN_BITS)) + bias


@wp.func
def adjusted(sample: int, gain: int, bias: int, offset: int, tone: wp.vec3i, extent: wp.vec2i) -> int:
    """gain * sample + bias + offset, all in 1/2**20 grey levels (gain in 1/2**GAIN_BITS), with a
    highlight knee: above ``tone[0]`` the gain's line runs straight on to (``tone[1]``, ``tone[1]``),
    so a view's white stays white whatever its gain (``tone[1]`` 0: no knee). With ``tone[2]`` a
    pixel's channels share its largest one's knee as it nears white (``gains.tone_curve``: no colour
    made); ``extent``: (smallest, largest) of the pixel's channels."""
    knee = tone[0]
    white = tone[1]
    if knee >= white:
        return int((wp.int64(sample) * wp.int64(gain)) >> wp.int64(GAIN_BITS)) + bias + offset
    v = knee_line(sample, gain, bias, knee, white)
    peak = extent[1]
    if tone[2] != 0 and peak > knee:
        near = wp.clamp(extent[0] - (2 * knee - white), 0, white - knee)  # of white - knee: 0 a knee's width below
        if near > 0:
            shared = bias + int(wp.int64(wp.min(knee_line(peak, gain, bias, knee, white), white) - bias)
                                * wp.int64(sample) / wp.int64(peak))
            v = v + int(wp.int64(shared - v) * wp.int64(near) / wp.int64(white - knee))
    return v + offset


@wp.func
def with_offset(sample: int, gain: int, bias: int, offset: int, tone: wp.vec3i, relative: int,
                extent: wp.vec2i) -> int:
    """:func:`adjusted` with a side's low-frequency offset: added in 1/2**20 grey levels, or with
    ``relative``, a relative change of the gain in 1/2**20 (the gain times 1 + offset / 2**20, before
    the knee: the offset is a smooth gain, and white stays white)."""
    if relative != 0:
        return adjusted(sample, gain + int((wp.int64(gain) * wp.int64(offset)) >> wp.int64(20)), bias, 0, tone,
                        extent)
    return adjusted(sample, gain, bias, offset, tone, extent)


@wp.func
def clear_of_offsets(d: float, clear_px: float, border: wp.vec2, border_side: wp.array(dtype=int), bo: int, second: int,
                     channels: int) -> bool:
    """Whether no offset of a side reaches a pixel whatever the frame: at distance ``d`` from the static
    seam, at least ``clear_px`` from it, and each border's offset of the side zero or not reaching it
    (``border``: the borders' weights there; ``bo``: the position's first element in ``border_side``)."""
    if not (wp.abs(d) >= clear_px):  # a NaN seam line is clear of nothing
        return False
    for c in range(channels):
        if border[0] > 0.0 and border_side[bo + c] != 0:
            return False
        if border[1] > 0.0 and border_side[bo + second + c] != 0:
            return False
    return True


@wp.func
def longer_run(best: wp.vec3i, start: int, x: int, start_offset: int) -> wp.vec3i:
    """``best`` (a, b, offset), or the run [start, x + 1) from ``start_offset`` when that is longer."""
    if start >= 0 and x + 1 - start > best[1] - best[0]:
        return wp.vec3i(start, x + 1, start_offset)
    return best


RowRuns = wp.types.vector(length=5, dtype=int)  # (copy a, copy b, the copy's target element at column 0, sample a, sample b)
RUN_NONE = wp.constant(0)  # the frame kernel's parts of a row: the full rule,
RUN_COPY = wp.constant(1)  # the target's element through the gains' table,
RUN_SAMPLE = wp.constant(2)  # the source sampled with its gains


@wp.struct
class Plan:
    """What a map set fixes for a frame kernel (``composite_plan_kernel``): the plan words per canvas
    pixel, the target's words of band pixels, each row's runs for this frame (all empty: the full rule
    everywhere), the canvas's (width, height) and the fill value per channel where no side is sampled."""

    words: wp.array(dtype=wp.int64)
    words_tgt: wp.array(dtype=wp.int64)
    runs: wp.array(dtype=RowRuns)
    size: wp.vec2i
    fill: wp.vec4i


@wp.kernel
def row_runs_kernel(
    row0: int,
    width: int,
    plan: wp.array(dtype=wp.int64),
    seam: wp.array(dtype=float),
    layout: Layout,
    clear_px: float,
    border: Border,
    channels: int,
    runs: wp.array(dtype=RowRuns),
):
    """Per canvas row y = row0 + i, the longest run of columns of each kind that no offset reaches
    (``clear_of_offsets``), as (copy a, copy b, the copy's target element at column 0, sample a, sample
    b), empty runs (0, 0): a copy run [a, b) shows the target alone at whole pixels, consecutive
    elements; a sample run the source alone.

    ``seam``: the static seam; ``clear_px``: how far from it no frame's seam offsets reach (the reach
    of its offsets beyond the band the frame's seam stays in, ``composite.plan_runs``; 0 where
    ``frame_runs_kernel`` cuts each row around the frame's seam instead); the border as the frame
    kernel takes it."""
    i, _ = wp.tid()
    y = row0 + i
    bw_row = border_weights(y, border.lines, border.on, layout.lf_px)
    copy = wp.vec3i(0, 0, 0)
    sample = wp.vec3i(0, 0, 0)
    copy_start = int(-1)
    copy_offset = int(0)
    sample_start = int(-1)
    for x in range(width):
        word = plan[y * width + x]
        kind = int(word & wp.int64(3))
        lp = line_and_position(x, y, layout.lines_are_rows)
        bw = bw_row
        if layout.lines_are_rows == 0:
            bw = border_weights(lp[0], border.lines, border.on, layout.lf_px)
        d = float(lp[1]) - seam[lp[0]]
        bo = lp[1] * channels
        copies = kind == KIND_TARGET and word_fx(word) == 0 and word_fy(word) == 0
        copies = copies and clear_of_offsets(d, clear_px, bw, border.tgt, bo, border.second, channels)
        if copies and copy_start >= 0 and word_offset(word) != copy_offset + (x - copy_start) * channels:
            copy_start = -1  # the target jumps (a cropped or shifted canvas): a new run
        if copies and copy_start < 0:
            copy_start = x
            copy_offset = word_offset(word)
        if not copies:
            copy_start = -1
        copy = longer_run(copy, copy_start, x, copy_offset)
        samples = kind == KIND_SOURCE and clear_of_offsets(d, clear_px, bw, border.src, bo, border.second, channels)
        if samples and sample_start < 0:
            sample_start = x
        if not samples:
            sample_start = -1
        sample = longer_run(sample, sample_start, x, 0)
    runs[y] = RowRuns(copy[0], copy[1], copy[2] - copy[0] * channels, sample[0], sample[1])


@wp.func
def clear_part(a: int, b: int, seam: float, cut_px: float) -> wp.vec2i:
    """The longer part of columns [a, b) at least ``cut_px`` from ``seam`` on a row, (0, 0) if none."""
    if not (seam == seam):  # no seam on this row: nothing is known to be clear
        return wp.vec2i(0, 0)
    left = wp.vec2i(a, wp.min(b, int(wp.floor(seam - cut_px)) + 1))
    right = wp.vec2i(wp.max(a, int(wp.ceil(seam + cut_px))), b)
    part = left
    if right[1] - right[0] > left[1] - left[0]:
        part = right
    if part[1] <= part[0]:
        return wp.vec2i(0, 0)
    return part


@wp.kernel
def frame_runs_kernel(row0: int, runs: wp.array(dtype=RowRuns), seam: wp.array(dtype=float), cut_px: float,
                      frame_runs: wp.array(dtype=RowRuns)):
    """Per canvas row, where the lines are rows: its runs for this frame. The plan's runs hold one side
    alone anywhere beyond the band; the part ``cut_px`` (the seam offsets' reach) from the frame's seam
    ``seam`` is kept. (Where the lines are columns the plan's runs already keep clear of any frame's
    seam, ``row_runs_kernel``, and serve every frame as they are.)"""
    i, _ = wp.tid()
    y = row0 + i
    run = runs[y]
    copy = clear_part(run[0], run[1], seam[y], cut_px)
    sample = clear_part(run[3], run[4], seam[y], cut_px)
    frame_runs[y] = RowRuns(copy[0], copy[1], run[2], sample[0], sample[1])


@wp.kernel
def gain_table_kernel(gain: wp.vec4i, bias: wp.vec4i, tone: wp.vec3i, table: wp.array(dtype=wp.uint8)):
    """table[c * 256 + v]: grey level v of channel c through the gain, bias and knee, with no offset:
    what the frame kernel makes of an unwarped target element in a copy run (where, with ``tone[2]``,
    its pixel is not near white: each channel its own knee)."""
    t = wp.tid()
    c = t / 256
    v = (t - c * 256) << (2 * FRAC_BITS)
    table[t] = grey_level(adjusted(v, gain[c], bias[c], 0, wp.vec3i(tone[0], tone[1], 0), wp.vec2i(v, v)))


@wp.func
def placed_run(a: int, b: int, how: int, width: int) -> wp.vec3i:
    """(a, b, how) of a row's run, an empty one placed at the row's end (width, width): the five parts
    of the row then cover each column once whichever runs it has."""
    if b <= a:
        return wp.vec3i(width, width, how)
    return wp.vec3i(a, b, how)


@wp.func
def first_column(j: int, start: int, col_step: int) -> int:
    """The first of a thread's columns j, j + col_step, ... at or after ``start``."""
    if j >= start:
        return j
    return j + (start - j + col_step - 1) / col_step * col_step


@wp.struct
class PixelRule:
    """What the full rule needs of one canvas pixel, its channels aside (``pixel_rule``): its kind, the
    source's weight ``a`` (1: the source alone, 0: the target alone), the seam offsets' weight ``lf``
    and the line's first element ``lo`` in them, each border's weight ``bw`` and the position's first
    element ``bo`` in theirs, the taps (element, fractions) of the side shown (the target's where ``a``
    is 0) and of the target where both are mixed."""

    kind: int
    a: float
    lf: float
    lo: int
    bw: wp.vec2
    bo: int
    p: int
    fx: int
    fy: int
    p_t: int
    fx_t: int
    fy_t: int


@wp.func(inline=True)  # per pixel: inlined, its struct arguments are not copied per call
def pixel_rule(x: int, y: int, q: int, plan: Plan, seam: SeamState, layout: Layout, border: Border, bw_row: wp.vec2,
               channels: int) -> PixelRule:
    """The full rule's terms of canvas pixel (x, y), flat index q, for images of ``channels``
    channels; ``bw_row``: the borders' weights of row y (what they are where the lines are rows)."""
    r = PixelRule()
    word = plan.words[q]
    r.kind = int(word & wp.int64(3))
    if r.kind == KIND_FILL:
        return r
    lp = line_and_position(x, y, layout.lines_are_rows)
    d = float(lp[1]) - seam.seam[lp[0]]
    r.lf = lf_weight(d, layout.lf_px)
    r.lo = lp[0] * channels
    r.bw = bw_row
    if layout.lines_are_rows == 0:
        r.bw = border_weights(lp[0], border.lines, border.on, layout.lf_px)
    r.bo = lp[1] * channels
    a = float(1.0)
    if r.kind == KIND_TARGET:
        a = 0.0
    elif r.kind == KIND_BAND:
        # The smoothed ramp's tails never reach 0 or 1 exactly: one side alone beyond 1e-4, which
        # they pass well within ALPHA_TAIL_SIGMAS of the ramp's ends (no erf or exp there).
        if wp.abs(d) >= 0.5 * layout.transition_px + ALPHA_TAIL_SIGMAS * layout.smooth_sigma_px:
            a = wp.where(d > 0.0, 0.0, 1.0)
        else:
            a = source_alpha(d, layout.transition_px, layout.smooth_sigma_px)
            a = wp.where(a > 0.9999, 1.0, wp.where(a < 0.0001, 0.0, a))
    r.a = a
    if a <= 0.0 and r.kind == KIND_BAND:
        word = plan.words_tgt[q]
    r.p = word_offset(word)
    r.fx = word_fx(word)
    r.fy = word_fy(word)
    if a > 0.0 and a < 1.0:
        word_t = plan.words_tgt[q]
        r.p_t = word_offset(word_t)
        r.fx_t = word_fx(word_t)
        r.fy_t = word_fy(word_t)
    return r


@wp.func(inline=True)
def rule_samples(r: PixelRule, c: int, planes: Planes) -> wp.vec2i:
    """Channel c of a pixel by the full rule, sampled: (source, target) in 1/2**20 grey levels, 0 for a
    side the pixel does not show."""
    steps = planes.steps
    vs = int(0)
    vt = int(0)
    if r.kind == KIND_FILL:
        return wp.vec2i(vs, vt)
    if r.a >= 1.0:
        vs = sample_fixed(planes.src, r.p + c, r.fx, r.fy, steps[0], steps[1])
    elif r.a <= 0.0:
        vt = sample_fixed(planes.tgt, r.p + c, r.fx, r.fy, steps[2], steps[3])
    else:
        vs = sample_fixed(planes.src, r.p + c, r.fx, r.fy, steps[0], steps[1])
        vt = sample_fixed(planes.tgt, r.p_t + c, r.fx_t, r.fy_t, steps[2], steps[3])
    return wp.vec2i(vs, vt)


@wp.func
def extent_of(v: wp.vec4i, channels: int) -> wp.vec2i:
    """(smallest, largest) of a pixel's samples in its first ``channels`` entries."""
    e = wp.vec2i(v[0], v[0])
    for c in range(1, channels):
        e = wp.vec2i(wp.min(e[0], v[c]), wp.max(e[1], v[c]))
    return e


@wp.func(inline=True)
def rule_channel(r: PixelRule, c: int, vs: int, vt: int, extent_src: wp.vec2i, extent_tgt: wp.vec2i,
                 seam: SeamState, border: Border, gains: Gains, fill: wp.vec4i) -> wp.uint8:
    """Channel c of a pixel by the full rule from its samples ``vs``, ``vt`` (``rule_samples``; ``extent_*``:
    each side's (smallest, largest) over the channels, for the knee): ``fill[c]`` where no side covers it, else per
    side ``gain * sample + bias`` with ``lf * lf[line, c]`` plus each border's weighted offset
    (``side_offset``) added or as a relative change of the gain (``gains.relative``, ``with_offset``),
    mixed by ``a``."""
    if r.kind == KIND_FILL:
        return wp.uint8(fill[c])
    if r.a >= 1.0:
        off = side_offset(r.lf, seam.lf_src, r.lo + c, r.bw, border.src, r.bo + c, border.second)
        return grey_level(with_offset(vs, gains.gain_src[c], gains.bias_src[c], off, gains.tone, gains.relative,
                                      extent_src))
    if r.a <= 0.0:
        off = side_offset(r.lf, seam.lf_tgt, r.lo + c, r.bw, border.tgt, r.bo + c, border.second)
        return grey_level(with_offset(vt, gains.gain_tgt[c], gains.bias_tgt[c], off, gains.tone, gains.relative,
                                      extent_tgt))
    vs = with_offset(vs, gains.gain_src[c], gains.bias_src[c],
                     side_offset(r.lf, seam.lf_src, r.lo + c, r.bw, border.src, r.bo + c, border.second),
                     gains.tone, gains.relative, extent_src)
    vt = with_offset(vt, gains.gain_tgt[c], gains.bias_tgt[c],
                     side_offset(r.lf, seam.lf_tgt, r.lo + c, r.bw, border.tgt, r.bo + c, border.second),
                     gains.tone, gains.relative, extent_tgt)
    return grey_level(int(r.a * float(vs) + (1.0 - r.a) * float(vt)))



@wp.func(inline=True)  # per pixel: inlined, its struct and array arguments are not copied per call
def by_rule(r: PixelRule, o: int, channels: int, planes: Planes, seam: SeamState, border: Border, gains: Gains,
            fill: wp.vec4i, out: wp.array(dtype=wp.uint8)):
    """A pixel's ``channels`` channels by the full rule (``pixel_rule``'s terms ``r``) into ``out[o:o + channels]``:
    each side sampled (``rule_samples``), its (smallest, largest) for the knee, then ``rule_channel``."""
    vs = wp.vec4i()
    vt = wp.vec4i()
    for c in range(4):  # unrolled over the most channels (MAX_CHANNELS), the used ones kept: per pixel
        if c < channels:
            st = rule_samples(r, c, planes)
            vs[c] = st[0]
            vt[c] = st[1]
    e_src = extent_of(vs, channels)
    e_tgt = extent_of(vt, channels)
    for c in range(4):
        if c < channels:
            out[o + c] = rule_channel(r, c, vs[c], vt[c], e_src, e_tgt, seam, border, gains, fill)

def _composite_frame_kernel(channels: int):
    """The row-run frame kernel for images of ``channels`` (1 to 4) channels, its channel loops unrolled.

    A compile-time channel count matters on the CPU: a dynamic per-pixel channel loop doubled the
    kernel's time at 1080p. Integer arithmetic throughout; the low-frequency offsets only cost a
    multiply inside ``lf_px`` of the seam.
    """

    @wp.kernel(module="unique", module_options=MODULE_OPTIONS)
    def composite_frame(
        row0: int,
        col_step: int,
        width: int,
        planes: Planes,
        plan: Plan,
        seam: SeamState,
        layout: Layout,
        border: Border,
        gains: Gains,
        out: wp.array(dtype=wp.uint8),
    ):
        """out[y, x, c] (flat (Hc, Wc, C)) by the full rule (``pixel_rule``, ``rule_channel``), and along
        each row's runs for this frame (``plan.runs``, ``frame_runs_kernel``) by their shortcuts: the
        copy run's pixels through ``gains.table`` (``gain_table_kernel``), the sample run's with the
        source's gains alone. Thread (i, j) does row ``row0 + i``, columns j, j + col_step, ... (see
        ``runtime.launch_row_loops``), five parts of the row in turn: before the first run, the first,
        between them, the second, after it.
        """
        i, j = wp.tid()
        y = row0 + i
        bw_row = border_weights(y, border.lines, border.on, layout.lf_px)  # a row's, where the lines are rows
        run = plan.runs[y]
        first = placed_run(run[0], run[1], RUN_COPY, width)
        later = placed_run(run[3], run[4], RUN_SAMPLE, width)
        if later[0] < first[0]:
            first = later
            later = placed_run(run[0], run[1], RUN_COPY, width)
        for part in range(5):
            begin = int(0)
            end = first[0]
            how = RUN_NONE
            if part == 1:
                begin = first[0]
                end = first[1]
                how = first[2]
            elif part == 2:
                begin = first[1]
                end = later[0]
            elif part == 3:
                begin = later[0]
                end = later[1]
                how = later[2]
            elif part == 4:
                begin = later[1]
                end = width
            x = first_column(j, begin, col_step)
            if how == RUN_COPY:
                while x < end:  # while loops, not range(): see the module docstring
                    o = (y * width + x) * wp.static(channels)
                    p = run[2] + x * wp.static(channels)
                    e = wp.vec2i(255, 0)
                    for c in range(wp.static(channels)):
                        e = wp.vec2i(wp.min(e[0], int(planes.tgt[p + c])), wp.max(e[1], int(planes.tgt[p + c])))
                    e = wp.vec2i(e[0] << (2 * FRAC_BITS), e[1] << (2 * FRAC_BITS))
                    if gains.tone[2] != 0 and e[1] > gains.tone[0] and e[0] > 2 * gains.tone[0] - gains.tone[1]:
                        for c in range(wp.static(channels)):  # near white: not the table's rule
                            v = adjusted(int(planes.tgt[p + c]) << (2 * FRAC_BITS), gains.gain_tgt[c],
                                         gains.bias_tgt[c], 0, gains.tone, e)
                            out[o + c] = grey_level(v)
                    else:
                        for c in range(wp.static(channels)):
                            out[o + c] = gains.table[c * 256 + int(planes.tgt[p + c])]
                    x = x + col_step
                continue
            if how == RUN_SAMPLE:
                while x < end:
                    q = y * width + x
                    word = plan.words[q]
                    p = word_offset(word)
                    fx = word_fx(word)
                    fy = word_fy(word)
                    s = wp.vec4i()
                    for c in range(wp.static(channels)):
                        s[c] = sample_fixed(planes.src, p + c, fx, fy, planes.steps[0], planes.steps[1])
                    e = extent_of(s, wp.static(channels))
                    for c in range(wp.static(channels)):
                        v = adjusted(s[c], gains.gain_src[c], gains.bias_src[c], 0, gains.tone, e)
                        out[q * wp.static(channels) + c] = grey_level(v)
                    x = x + col_step
                continue
            while x < end:
                q = y * width + x
                r = pixel_rule(x, y, q, plan, seam, layout, border, bw_row, wp.static(channels))
                by_rule(r, q * wp.static(channels), wp.static(channels), planes, seam, border, gains, plan.fill, out)
                x = x + col_step

    return composite_frame


def _composite_pixel_kernel(channels: int):
    """The per-pixel frame kernel (CUDA's) for images of ``channels`` (1 to 4) channels: the full rule at
    every pixel, no runs; the same planes as the row-run kernel's."""

    @wp.kernel(module="unique", module_options=MODULE_OPTIONS)
    def composite_pixels(
        row0: int,
        planes: Planes,
        plan: Plan,
        seam: SeamState,
        layout: Layout,
        border: Border,
        gains: Gains,
        out: wp.array(dtype=wp.uint8),
    ):
        """out[y, x, c] (flat (Hc, Wc, C)) of pixel (x, y = row0 + i) by the full rule; thread (i, x)
        (``runtime.launch_rows``)."""
        i, x = wp.tid()
        y = row0 + i
        q = y * plan.size[0] + x
        bw_row = border_weights(y, border.lines, border.on, layout.lf_px)
        r = pixel_rule(x, y, q, plan, seam, layout, border, bw_row, wp.static(channels))
        by_rule(r, q * wp.static(channels), wp.static(channels), planes, seam, border, gains, plan.fill, out)

    return composite_pixels


MAX_CHANNELS = 4  # gains, biases and fill values travel as one vec4 each
# The frame kernels per channel count, built at import so that ``runtime.prewarm`` loads them all.
COMPOSITE_FRAME_KERNELS = {channels: _composite_frame_kernel(channels) for channels in range(1, MAX_CHANNELS + 1)}
COMPOSITE_PIXEL_KERNELS = {channels: _composite_pixel_kernel(channels) for channels in range(1, MAX_CHANNELS + 1)}


NOT_BOTH = wp.constant(1.0e9)  # band_difference_kernel: the cell is not a band pixel (a view is missing)


@wp.func
def holds_both(diff: float) -> bool:
    """Whether a band cell of difference ``diff`` (``band_difference_kernel``) holds both views."""
    return diff < 0.5 * NOT_BOTH


@wp.struct
class BandCells:
    """The per-frame seam's band of cells: band line k is seam line ``lines[k]``; its cell j is at
    position ``x0[k] + cell j`` along the line (canvas pixels), read at pixel (x, y) - ``origin`` of the
    plan (one whose pixel (0, 0) shows canvas pixel ``origin``, to the nearest pixel: a steady window's)."""

    lines: wp.array(dtype=int)
    x0: wp.array(dtype=int)
    cell: int
    origin: wp.vec2i


BandWord = wp.types.vector(length=2, dtype=wp.int64)  # a band cell's plan words: (the source's, the target's)


@wp.struct
class BandWords:
    """A plan's words on a band's cells and further each side (``band_words_kernel``): band line k's cell
    m is at position ``first[k] + m cell`` along the line; (0, 0), a fill pixel's, where the plan does not
    hold both taps."""

    first: wp.array(dtype=int)
    words: wp.array2d(dtype=BandWord)


@wp.kernel
def band_words_kernel(
    row0: int,
    col_step: int,
    width: int,
    plan: Plan,
    layout: Layout,
    band: BandCells,
    reach: int,
    out: BandWords,
):
    """Per band line k = row0 + i: the plan's words on its cells and ``reach`` cells further each side
    (``width`` cells from ``out.first[k]`` = ``band.x0[k] - reach band.cell``), the source's and the
    target's where the plan holds both taps (a band pixel), else (0, 0). Made once while the plan holds
    and the band stays within them, so that each frame's ``band_difference_kernel`` reads a small array,
    not the canvas's plan (whose words the last frame's compositing left out of the caches). Thread (i,
    j) does cells j, j + col_step, ... of its line (``runtime.launch_row_loops``)."""
    i, j0 = wp.tid()
    k = row0 + i
    line = band.lines[k]
    canvas_width = plan.size[0]
    canvas_height = plan.size[1]
    first = band.x0[k] - reach * band.cell
    if j0 == 0:
        out.first[k] = first
    j = j0
    while j < width:  # while loops, not range(): see the module docstring
        pos = first + j * band.cell
        x = pos
        y = line
        if layout.lines_are_rows == 0:
            x = line
            y = pos
        x = x - band.origin[0]
        y = y - band.origin[1]
        cell_words = BandWord(wp.int64(0), wp.int64(0))
        if x >= 0 and y >= 0 and x < canvas_width and y < canvas_height:
            q = y * canvas_width + x
            word = plan.words[q]
            if int(word & wp.int64(3)) == KIND_BAND:
                cell_words = BandWord(word, plan.words_tgt[q])
        out.words[k, j] = cell_words
        j = j + col_step


@wp.kernel
def band_difference_kernel(
    row0: int,
    col_step: int,
    width: int,
    planes: Planes,
    words: BandWords,
    band: BandCells,
    gains: Gains,
    diff: wp.array2d(dtype=float),
    total: wp.array2d(dtype=float),
    delta: wp.array2d(dtype=float),
):
    """Per band line k = row0 + i and cell j < width: channel 0 of the source minus the target there
    into ``diff`` and their sum into ``total``, both with their gains and knee (grey levels), or
    ``NOT_BOTH`` and 0 where the plan does not hold both taps (outside the overlap or the band: its
    ``words`` there, ``band_words_kernel``'s, are a fill pixel's, as are those of cells beyond them);
    ``delta``: how much ``diff`` changed from the value it held (the last frame's), 0 where either lacks
    a view. The per-frame seam reads them. Thread (i, j) does cells j, j + col_step, ... of its line
    (``runtime.launch_row_loops``)."""
    i, j0 = wp.tid()
    k = row0 + i
    steps = planes.steps
    copied = words.words.shape[1]
    m0 = (band.x0[k] - words.first[k]) / band.cell  # cell j's in the copy: m0 + j
    j = j0
    while j < width:  # while loops, not range(): see the module docstring
        value = float(NOT_BOTH)
        both_sum = float(0.0)
        m = m0 + j
        if m >= 0 and m < copied:
            cell_words = words.words[k, m]
            word = cell_words[0]
            if int(word & wp.int64(3)) == KIND_BAND:
                word_t = cell_words[1]
                ss = sample_fixed(planes.src, word_offset(word), word_fx(word), word_fy(word), steps[0], steps[1])
                st = sample_fixed(planes.tgt, word_offset(word_t), word_fx(word_t), word_fy(word_t), steps[2], steps[3])
                vs = adjusted(ss, gains.gain_src[0], gains.bias_src[0], 0, gains.tone, wp.vec2i(ss, ss))
                vt = adjusted(st, gains.gain_tgt[0], gains.bias_tgt[0], 0, gains.tone, wp.vec2i(st, st))
                value = float(vs - vt) / float(ONE20)
                both_sum = float(vs + vt) / float(ONE20)
        last = diff[k, j]
        diff[k, j] = value
        total[k, j] = both_sum
        change = float(0.0)
        if holds_both(value) and holds_both(last):
            change = wp.abs(value - last)
        delta[k, j] = change
        j = j + col_step


@wp.kernel
def seam_weights_kernel(
    row0: int,
    seam: wp.array(dtype=float),
    layout: Layout,
    alpha: wp.array2d(dtype=float),
    lf: wp.array2d(dtype=float),
):
    """Per canvas pixel: the source weight and the low-frequency offsets' weight the frame kernel gives it
    for the seam ``seam`` (where both views are valid), for figures and reference implementations."""
    i, x = wp.tid()
    y = row0 + i
    lp = line_and_position(x, y, layout.lines_are_rows)
    d = float(lp[1]) - seam[lp[0]]
    alpha[y, x] = source_alpha(d, layout.transition_px, layout.smooth_sigma_px)
    lf[y, x] = lf_weight(d, layout.lf_px)
