"""The SENA stitch, one stage per line (docs/method.md, steps 0-9).

``estimate_maps`` turns two images into what the compositor needs over the output canvas: where to
sample the source, where to sample the target, the seam between them (and so the alpha), each view's
exposure gains and the seam blend's offsets; ``stitch_images`` applies them once. The video path
estimates maps the same way and applies them to every frame pair.

Stages run in the *working frame* of :mod:`sena_warp.rig` (source left, vertical rigs transposed):
every ``*_canvas`` array here is on the working-frame canvas. The final maps are expressed once in
the input frame (``*_input``: the same canvas, transposed back for a vertical rig) so the
compositor never transposes frames.

Where this departs from the paper (``docs/method.md``; what each departure buys: ``docs/evaluation.md``),
the paper's version stays one setting away: ``ffd_model="blend"`` (steps 3-4), ``gate_model="paper"`` (step 5),
``seam_model="paper"`` (steps 8-9), ``thin_strip_ratio=0``, ``source_past_target=True`` (step 9),
``gain_model="none"``, ``seam_blend_ratio=0``, ``border_blend=False``, ``transition_px=24``. Switch alignment (``switch_align=True``), no step of the paper,
is off by default: it costs more than the stitch's time allows.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .cells import grid_cells
from .composite import (BorderBlend, CompositePlan, FrameState, SeamLayout, composite_image, composite_plan,
                        coverage)
from .config import CHOICES, Config, require_config
from .errors import GeometryError, InputError, MatchError
from .features import Matches, match_images, neighbour_supported
from .ffd import LatticeFit, field_from_lattice, fitted_lattice, smoothed_blend_lattice
from .gains import Gains, compensated_views, view_gains
from .gate import gate_canvas, guard_field
from .global_affine import GlobalAffine, check_views_alike, fit_global_affine, near_model
from .imageio import check_image, described
from .local_affine import LocalAffines, fit_local_affines, sigma_f
from .overlap import Overlap, plan_overlap, source_only_mask
from .partition import (BorderOffsets, SeamMaps, SeamOffsets, border_offsets, past_target_src, seam_maps,
                        seam_offsets, thin_strips)
from .progress import LOGGER, stage
from .rig import Rig, detect_rig, image_to_working, map_from_working, matches_to_working
from .seam_path import SeamPath, seam_line
from .switch_align import aligned_source_map, seam_side_alpha, shown_labels, view_weights
from .warp_map import CanvasViews, canvas_views, forward_points, source_map_canvas
from .zone import Zone, adequate_zone
from sena_warp.kernels import runtime


class StageClock:
    """Wall-clock seconds per stage, in the order the stages first ran: ``with clock("gate"): ...``.

    Each stage is announced as a step (``progress.stage``) and its time logged at DEBUG (shown with -v).
    """

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        stage(name, step=True)
        t0 = time.perf_counter()
        yield
        elapsed = time.perf_counter() - t0
        self.seconds[name] = self.seconds.get(name, 0.0) + elapsed
        LOGGER.debug("%s: %.3f s", name, elapsed)


@dataclass(frozen=True)
class Warp:
    """Steps 1-6 in the working frame: models, overlap, the FFD field and the source sampling map
    (working canvas).

    ``local`` (the paper's local affines) is None with ``ffd_model="fit"``, ``fit`` (the fitted
    lattice) None with ``"blend"``; ``gate_canvas`` is None without a gate (``gate_model="none"``).
    ``inliers_*`` are the matches the warp follows: the fit's matches it kept, or A_glob's inliers.
    """

    glob: GlobalAffine
    overlap: Overlap
    local: LocalAffines | None
    fit: LatticeFit | None
    inliers_src: np.ndarray  # (N, 2) source points, working-frame source pixels
    inliers_tgt: np.ndarray  # (N, 2) matching target points, working-frame target pixels
    lattice: np.ndarray  # (Ny, Nx, 2) float32 FFD lattice (source px) before the gate
    field_canvas: np.ndarray  # (H, W, 2) float32 FFD displacement before the gate (source px)
    gate_canvas: np.ndarray | None  # (H, W) float32 G in [0, 1]
    map_src_canvas: np.ndarray  # (H, W, 2) float32 M_s: working-frame source (x, y) per working-canvas pixel


@dataclass(frozen=True)
class Seam:
    """Steps 7-9 in the working frame (positions and maps on the working canvas): the zone, the seam's
    path and anchors, the seam maps, each view's gains and the seam blend's offsets (along the seam and
    along the target's borders beyond its ends). ``map_cut_canvas``: (H, W, 2) float32 the source map
    they ran on (step 6's, or step 6's aligned at the switches: ``switch_align``)."""

    zone: Zone
    path: SeamPath
    maps: SeamMaps
    gains: Gains
    offsets: SeamOffsets
    border: BorderOffsets
    map_cut_canvas: np.ndarray

    @property
    def anchors_src_canvas(self) -> np.ndarray:
        return self.path.anchors_src_canvas

    @property
    def anchors_tgt_canvas(self) -> np.ndarray:
        return self.path.anchors_tgt_canvas


@dataclass
class StitchMaps:
    """What a stitch needs to be applied to any frame pair of the same two cameras.

    The maps are in the INPUT frame (the panorama as written; ``warp`` and ``seam`` hold the
    working-frame ones): ``map_src_input[y, x]`` (H, W, 2) float32 is the (x, y) to sample in the
    source input image (``rig.source``), ``map_tgt_input`` likewise in the target input image,
    ``alpha_input`` (H, W) float32 the source weight (what ``seam_input`` gives), ``seam_input`` the
    seam's layout for the compositor (per input row, or per input column for a vertical rig).
    """

    rig: Rig
    map_src_input: np.ndarray
    map_tgt_input: np.ndarray
    alpha_input: np.ndarray
    seam_input: SeamLayout
    matches: Matches
    warp: Warp
    seam: Seam
    seconds: dict[str, float] = field(default_factory=dict)


@dataclass
class Panorama:
    image: np.ndarray  # (H, W, 4) uint8 BGRA; alpha 0 where neither input covers the canvas
    maps: StitchMaps
    seconds: dict[str, float]


def estimate_warp(img_src: np.ndarray, img_tgt: np.ndarray, pts_src: np.ndarray, pts_tgt: np.ndarray,
                  cfg: Config, clock: StageClock) -> Warp:
    """SENA steps 1-6 ("Locally adaptive image warping") in the working frame; ``cfg.device`` resolved."""
    if cfg.ffd_model not in CHOICES["ffd_model"] or cfg.gate_model not in CHOICES["gate_model"]:
        raise InputError(f"ffd_model must be one of {CHOICES['ffd_model']} and gate_model one of {CHOICES['gate_model']}")
    with clock("global_affine"):
        glob = fit_global_affine(pts_src, pts_tgt, cfg)
        check_views_alike(img_src, img_tgt, glob, cfg)
    affine = glob.affine_src_to_tgt
    near = near_model(affine, pts_src, pts_tgt, cfg.local_match_px)
    with clock("overlap"):
        overlap = plan_overlap(img_src.shape, img_tgt.shape, affine, cfg)
    local, fit = None, None
    if cfg.ffd_model == "fit":
        with clock("ffd"):
            fit = fitted_lattice(overlap.canvas, affine, pts_src, pts_tgt, _diagonal_px(img_src, img_tgt), cfg)
        kept = np.flatnonzero(fit.used)[fit.weights > 0]
        inliers_src, inliers_tgt, lattice = pts_src[kept], pts_tgt[kept], fit.lattice
    else:
        with clock("cells"):
            cells = grid_cells(overlap, cfg)
        with clock("local_affines"):
            local = fit_local_affines(pts_src[near], pts_tgt[near], affine, cells, cfg)
        with clock("ffd"):
            lattice = smoothed_blend_lattice(overlap.canvas, affine, local.affines_src_to_tgt, local.centres_tgt,
                                             local.conf, sigma_f(local, cfg), cfg)
        inliers_src, inliers_tgt = pts_src[glob.inliers], pts_tgt[glob.inliers]
    field_canvas = field_from_lattice(lattice, overlap.canvas)
    gate, field_guarded = None, field_canvas
    if cfg.gate_model == "paper":
        with clock("gate"):
            gate = gate_canvas(source_only_mask(overlap), overlap.canvas.tgt_to_canvas(pts_tgt[near]),
                               _diagonal_px(img_src, img_tgt), _long_side_px(img_src, img_tgt), cfg)
            field_guarded = guard_field(field_canvas, gate, cfg)
    with clock("warp_map"):
        map_src = source_map_canvas(overlap.canvas, affine, field_guarded, cfg)
    return Warp(glob, overlap, local, fit, inliers_src, inliers_tgt, lattice, field_canvas, gate, map_src)


def estimate_seam(img_src: np.ndarray, img_tgt: np.ndarray, matches_src: np.ndarray, matches_tgt: np.ndarray,
                  warp: Warp, cfg: Config, clock: StageClock, prior_seam_tgt: np.ndarray | None = None) -> Seam:
    """SENA steps 7-9 ("Optimal stitching line", "Partitioning and Reconstruction") in the working frame,
    with each view's gains and the seam blend; ``cfg.device`` resolved. ``matches_*``: every match
    (N, 2), working-frame source / target pixels: where its neighbours support it, the seam does not
    separate its two copies. ``prior_seam_tgt``: a seam to stay near, x per target row in target
    pixels (NaN: none), e.g. the current seam of a video.

    With ``cfg.switch_align`` the source is aligned to the target wherever the cut switches views
    (``switch_align``) and the seam cut again on the aligned source, ``cfg.switch_rounds`` times; step
    9 runs once, on the last cut.
    """
    supported = neighbour_supported(matches_src, matches_tgt, cfg.support_neighbours, cfg.support_tol_px,
                                    cfg.support_min)
    prior = _prior_on_canvas(prior_seam_tgt, warp.overlap.canvas)
    copies = matches_src[supported], matches_tgt[supported]
    cut = cut_seam(img_src, img_tgt, *copies, warp, warp.map_src_canvas, cfg, clock, prior)
    for _ in range(cfg.switch_rounds if cfg.switch_align else 0):
        with clock("switch_align"):
            map_aligned = aligned_source_map(cut.map_src_canvas, *cut.views.grey(), cut.views.valid_src,
                                             cut.views.valid_tgt, cut.path.seam_x_canvas, cfg)
        cut = cut_seam(img_src, img_tgt, *copies, warp, map_aligned, cfg, clock, prior, cut.gains)
    return partitioned(cut, warp.overlap.canvas, img_tgt.shape[0], _diagonal_px(img_src, img_tgt), cfg, clock)


@dataclass(frozen=True)
class SeamCut:
    """Steps 7-8 on one source map: the zone, the seam's path, the views it was cut on (with their
    gains, where the panorama shows them: the source past the target and thin strips left out), the
    gains, what is left out (``thin_src``, ``thin_tgt``: (H, W) bool) and ``map_src_canvas`` (H, W, 2)
    float32 the source map."""

    zone: Zone
    path: SeamPath
    views: CanvasViews
    gains: Gains
    thin_src: np.ndarray
    thin_tgt: np.ndarray
    map_src_canvas: np.ndarray


def cut_seam(img_src: np.ndarray, img_tgt: np.ndarray, copies_src: np.ndarray, copies_tgt: np.ndarray, warp: Warp,
             map_src_canvas: np.ndarray, cfg: Config, clock: StageClock, prior_x_canvas: np.ndarray | None,
             gains: Gains | None = None) -> SeamCut:
    """Steps 7-8 on the source map ``map_src_canvas`` (H, W, 2) (step 6's, or aligned at the switches):
    the seam runs where that source and the target agree. ``copies_*``: the matches whose two copies
    the seam does not separate (N, 2), working-frame source / target pixels; ``prior_x_canvas``:
    ``seam_line``'s; ``gains``: the views' gains, measured here when None (a source aligned locally
    keeps the gains measured before)."""
    canvas = warp.overlap.canvas
    affine = warp.glob.affine_src_to_tgt
    with clock("forward_points"):
        pts_src_canvas = forward_points(map_src_canvas, affine, canvas, warp.inliers_src, cfg)
        copies_src_canvas = forward_points(map_src_canvas, affine, canvas, copies_src, cfg)
    pts_tgt_canvas = canvas.tgt_to_canvas(warp.inliers_tgt)
    with clock("views"):
        views = canvas_views(img_src, img_tgt, map_src_canvas, canvas, cfg)
    with clock("gains"):
        gains = view_gains(views, cfg) if gains is None else gains
        views = compensated_views(views, gains)
    with clock("zone"):
        zone = adequate_zone(pts_src_canvas, pts_tgt_canvas, views.both, *views.grey(), cfg)
    with clock("chain"):
        path = seam_line(zone, views, pts_src_canvas, pts_tgt_canvas, copies_src_canvas,
                         canvas.tgt_to_canvas(copies_tgt), cfg, prior_x_canvas)
    thin_src = thin_tgt = np.zeros(canvas.shape, bool)
    if not cfg.source_past_target:  # left out: the source where the seam gives the target, which has no pixel there
        with clock("past_target"):
            thin_src = past_target_src(views, path.seam_x_canvas, canvas.offset_tgt, img_tgt.shape, cfg)
            views = replace(views, valid_src=views.valid_src & ~thin_src)
    if cfg.thin_strip_ratio > 0:  # left out: a view shown only in a thin strip where the other takes over
        with clock("thin_strips"):
            label = shown_labels(*view_weights(seam_side_alpha(path.seam_x_canvas, canvas.width), views.valid_src,
                                               views.valid_tgt))
            strip_src, thin_tgt = thin_strips(label, cfg.thin_strip_ratio * _diagonal_px(img_src, img_tgt))
            thin_src = thin_src | strip_src
            views = replace(views, valid_src=views.valid_src & ~thin_src, valid_tgt=views.valid_tgt & ~thin_tgt)
    return SeamCut(zone, path, views, gains, thin_src, thin_tgt, map_src_canvas)


def partitioned(cut: SeamCut, canvas, height_tgt: int, diag_px: float, cfg: Config, clock: StageClock) -> Seam:
    """Step 9 on a cut: the seam maps (the thin strips sampling nothing), the seam and border blend."""
    with clock("seam_maps"):
        maps = seam_maps(cut.map_src_canvas, canvas, cut.path, cfg)
        if cut.thin_src.any() or cut.thin_tgt.any():
            nan = np.float32(np.nan)
            maps = replace(maps, map_src_canvas=np.where(cut.thin_src[..., None], nan, maps.map_src_canvas),
                           map_tgt_canvas=np.where(cut.thin_tgt[..., None], nan, maps.map_tgt_canvas))
    with clock("seam_blend"):
        offsets = seam_offsets(cut.views, cut.path.seam_x_canvas, diag_px, cfg)
        border = border_offsets(cut.views, cut.path.seam_x_canvas, offsets, canvas.offset_tgt, height_tgt, cfg)
    return Seam(cut.zone, cut.path, maps, cut.gains, offsets, border, cut.map_src_canvas)


def estimate_maps(img_a: np.ndarray, img_b: np.ndarray, cfg: Config, reference: str = "auto",
                  matches: Matches | None = None, prior_seam_tgt: np.ndarray | None = None,
                  transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> StitchMaps:
    """All of SENA on one image pair: the maps that stitch it (and every later frame of the same rig).

    ``cfg.device`` must be resolved (``runtime.resolve_config``: the job calling this, an image or a
    video stitch, chooses the device once). ``matches`` of (img_a, img_b) found earlier (e.g. while
    screening video frames) skip step 0; ``prior_seam_tgt`` as ``estimate_seam``'s (working frame).
    ``transparent``: per image, (H, W) bool pixels that are not content (no keypoints there) or None.
    """
    clock = StageClock()
    if matches is None:
        with clock("features"):
            matches = match_images(img_a, img_b, cfg, transparent)
    rig = detect_rig(matches.pts_a, matches.pts_b, img_a.shape, reference)
    img_src, img_tgt = (image_to_working(img, rig) for img in rig.pick(img_a, img_b))
    pts_src, pts_tgt = matches_to_working(matches.pts_a, matches.pts_b, rig)
    warp = estimate_warp(img_src, img_tgt, pts_src, pts_tgt, cfg, clock)
    seam = estimate_seam(img_src, img_tgt, pts_src, pts_tgt, warp, cfg, clock, prior_seam_tgt)
    return StitchMaps(
        rig=rig,
        map_src_input=map_from_working(seam.maps.map_src_canvas, rig),
        map_tgt_input=map_from_working(seam.maps.map_tgt_canvas, rig),
        alpha_input=map_from_working(seam.maps.alpha_canvas, rig),
        seam_input=seam_layout(seam, rig, cfg),
        matches=matches,
        warp=warp,
        seam=seam,
        seconds=clock.seconds,
    )


def seam_layout(seam: Seam, rig: Rig, cfg: Config, band_px: float | None = None) -> SeamLayout:
    """The seam as the compositor takes it: per working-frame row = per input row, or per input column
    for a vertical rig. ``band_px`` defaults to the transition's reach (a seam fixed for good)."""
    reach = 0.5 * cfg.transition_px + 3.0 * cfg.seam_smooth_sigma_px
    return SeamLayout(positions=np.asarray(seam.path.seam_x_canvas, np.float32), lines_are_rows=not rig.vertical,
                      band_px=reach if band_px is None else band_px, transition_px=float(cfg.transition_px),
                      smooth_sigma_px=float(cfg.seam_smooth_sigma_px), lf_px=seam.offsets.fade_px)


def panorama_plan(maps: StitchMaps, shapes: tuple[tuple[int, ...], tuple[int, ...]], cfg: Config,
                  transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> CompositePlan:
    """The compositing plan for BGR images of the two inputs of (H, W, C) ``shapes`` (source, target):
    the maps, the seam and the border blend (relative changes of the gains with ``cfg.seam_blend_gain``).
    ``transparent``: per input (a, b), (H, W) bool pixels it must not sample (``without_transparent``)."""
    transparent_src, transparent_tgt = maps.rig.pick(*transparent)
    border = maps.seam.border
    offsets = border.relative() if cfg.seam_blend_gain else (border.src, border.tgt)
    blend = BorderBlend(border.lines, *offsets) if border.on else None
    return composite_plan(without_transparent(maps.map_src_input, transparent_src),
                          without_transparent(maps.map_tgt_input, transparent_tgt), maps.seam_input, shapes, cfg,
                          border=blend)


def panorama_state(maps: StitchMaps, cfg: Config) -> FrameState:
    """What the panorama is composited with: the estimate's seam, both views' gains and the seam blend's
    offsets (with ``cfg.seam_blend_gain`` as relative gains: a smooth gain changes no colour or contrast)."""
    gains, offsets = maps.seam.gains, maps.seam.offsets
    relative = cfg.seam_blend_gain
    return FrameState(maps.seam_input.positions, (gains.gain_src, gains.bias_src, gains.gain_tgt, gains.bias_tgt),
                      offsets.relative() if relative else (offsets.src, offsets.tgt), relative)


def stitch_images(img_a: np.ndarray, img_b: np.ndarray, cfg: Config, reference: str = "auto",
                  transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> Panorama:
    """Stitch two BGR uint8 images; returns a BGRA panorama (alpha 0 where nothing was covered).

    The Warp device of ``cfg`` ("auto", "cpu" or "cuda") is resolved here, once for the whole stitch.
    ``transparent``: per image, (H, W) bool pixels that are not content (an input's alpha 0) or None:
    no keypoints there, and the canvas takes the other image there, or nothing (alpha 0). Arguments
    of another kind or shape raise InputError saying what was expected.
    """
    for name, img, mask in (("img_a", img_a, transparent[0]), ("img_b", img_b, transparent[1])):
        check_image(img, f"stitch_images: {name}")
        if mask is not None and not (isinstance(mask, np.ndarray) and mask.dtype == bool
                                     and mask.shape == img.shape[:2]):
            raise InputError(f"stitch_images: the transparent mask of {name} must be None or a bool array of shape "
                             f"{img.shape[:2]}, got {described(mask)}")
    cfg = runtime.resolve_config(require_config(cfg, "stitch_images"))
    clock = StageClock()
    with clock("load_kernels"):  # a first run's compile starts in the background (a launch waits for its module)
        runtime.prewarm(cfg.device, channels=(3,), wait=False)  # BGR images: the 3-channel frame kernel
    stage("estimating maps")
    with naming_scale_ratio(img_a, img_b, cfg):
        maps = estimate_maps(img_a, img_b, cfg, reference, transparent=transparent)
    clock.seconds.update(maps.seconds)
    stage("compositing")
    with clock("composite"):
        image = panorama_image(img_a, img_b, maps, cfg, transparent)
    return Panorama(image, maps, clock.seconds)


def panorama_image(img_a: np.ndarray, img_b: np.ndarray, maps: StitchMaps, cfg: Config,
                   transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> np.ndarray:
    """The BGRA panorama of BGR images ``img_a``, ``img_b`` composited with ``maps`` (alpha 0 where
    neither covers the canvas); ``transparent`` as :func:`stitch_images`'."""
    img_src, img_tgt = maps.rig.pick(img_a, img_b)
    plan = panorama_plan(maps, (img_src.shape, img_tgt.shape), cfg, transparent)
    return np.dstack([composite_image(img_src, img_tgt, plan, panorama_state(maps, cfg), cfg), coverage(plan)])


def _prior_on_canvas(prior_seam_tgt: np.ndarray | None, canvas) -> np.ndarray | None:
    """A seam given per target row in target pixels, per canvas row in canvas pixels (NaN off the target)."""
    if prior_seam_tgt is None:
        return None
    ox, oy = (int(round(v)) for v in canvas.offset_tgt)
    prior = np.full(canvas.height, np.nan)
    rows = np.arange(len(prior_seam_tgt)) + oy
    inside = (rows >= 0) & (rows < canvas.height)
    prior[rows[inside]] = np.asarray(prior_seam_tgt, np.float64)[inside] + ox
    return prior


@contextmanager
def naming_scale_ratio(img_a: np.ndarray, img_b: np.ndarray, cfg: Config) -> Iterator[None]:
    """Inside the block, a failed stitch of two images more than ``cfg.scale_hint_ratio`` apart in
    size (square root of the area ratio) says so first: the likely cause, and what to do."""
    (h_a, w_a), (h_b, w_b) = img_a.shape[:2], img_b.shape[:2]
    ratio = float(np.sqrt(max(w_a * h_a, w_b * h_b) / min(w_a * h_a, w_b * h_b)))
    try:
        yield
    except (MatchError, GeometryError) as exc:
        if ratio <= cfg.scale_hint_ratio:
            raise
        raise type(exc)(f"the images differ {ratio:.1f}x in size (a {w_a}x{h_a} px, b {w_b}x{h_b} px), more than "
                        f"features match across (about {cfg.scale_hint_ratio:g}x): resize the larger one to about "
                        f"the other's size first ({exc})") from exc


def without_transparent(map_input: np.ndarray, transparent: np.ndarray | None) -> np.ndarray:
    """An input-frame (H, W, 2) float32 sampling map (``StitchMaps.map_*_input``) that samples nothing
    (NaN) where it would touch a pixel of ``transparent`` ((h, w) bool over the image it samples; None:
    the map as it is).

    Any bilinear tap on a transparent pixel counts, so no fill colour bleeds into the edge; the
    compositor then shows the other image there, or nothing.
    """
    if transparent is None:
        return map_input
    opaque = np.where(transparent, 0, 255).astype(np.uint8)
    sampled = cv2.remap(opaque, map_input, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = map_input.copy()
    out[sampled < 255] = np.nan
    return out


def _diagonal_px(img_src: np.ndarray, img_tgt: np.ndarray) -> float:
    """The larger image diagonal: the scale of the lattice (step 4), the gate's ramp band b (step 5) and
    the seam blend's fade."""
    return float(max(np.hypot(*img_src.shape[:2]), np.hypot(*img_tgt.shape[:2])))


def _long_side_px(img_src: np.ndarray, img_tgt: np.ndarray) -> int:
    """The longest image side, the scale of the gate's density blur sigma_d (docs/method.md step 5)."""
    return max(*img_src.shape[:2], *img_tgt.shape[:2])
