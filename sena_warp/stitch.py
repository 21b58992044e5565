"""The SENA stitch, one stage per line (SENA.md steps 0-9).

``estimate_maps`` turns two images into three per-pixel maps over the output canvas (where to sample
the source, where to sample the target, the alpha between them); ``stitch_images`` applies them once.
The video path estimates maps the same way and applies them to every frame pair.

Stages run in the *working frame* of :mod:`sena_warp.rig` (source left, vertical rigs transposed):
every ``*_canvas`` array here is on the working-frame canvas. The final maps are expressed once in
the input frame (``*_input``: the same canvas, transposed back for a vertical rig) so the
compositor never transposes frames.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import cv2
import numpy as np

from .cells import grid_cells
from .chain import keypoint_chain
from .composite import Compositor
from .config import Config
from .errors import GeometryError, MatchError
from .features import Matches, match_images
from .ffd import ffd_field_canvas
from .gate import gate_canvas, guard_field
from .global_affine import GlobalAffine, fit_global_affine, near_model
from .local_affine import LocalAffines, fit_local_affines, sigma_f
from .overlap import Overlap, plan_overlap, source_only_mask
from .partition import SeamMaps, seam_maps
from .progress import LOGGER, stage
from .rig import Rig, detect_rig, image_to_working, map_from_working, matches_to_working
from .warp_map import forward_points, remap_image, source_map_canvas
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
    """Steps 1-6 in the working frame: models, overlap, gate and the source sampling map (working canvas)."""

    glob: GlobalAffine
    overlap: Overlap
    local: LocalAffines
    inliers_src: np.ndarray  # (N, 2) inlier source points, source pixels
    inliers_tgt: np.ndarray  # (N, 2) matching target points, target pixels
    field_canvas: np.ndarray  # (H, W, 2) float32 FFD displacement before the gate (source px)
    gate_canvas: np.ndarray  # (H, W) float32 G in [0, 1]
    map_src_canvas: np.ndarray  # (H, W, 2) float32 M_s: working-frame source (x, y) per working-canvas pixel


@dataclass(frozen=True)
class Seam:
    """Steps 7-9 in the working frame (positions and maps on the working canvas)."""

    zone: Zone
    anchors_src_canvas: np.ndarray  # (K, 2) warped-source anchor positions
    anchors_tgt_canvas: np.ndarray  # (K, 2) target anchor positions
    maps: SeamMaps


@dataclass
class StitchMaps:
    """What a stitch needs to be applied to any frame pair of the same two cameras.

    The three maps are in the INPUT frame (the panorama as written; ``warp`` and ``seam`` hold the
    working-frame ones): ``map_src_input[y, x]`` (H, W, 2) float32 is the (x, y) to sample in the
    source input image (``rig.source``), ``map_tgt_input`` likewise in the target input image,
    ``alpha_input`` (H, W) float32 the source weight.
    """

    rig: Rig
    map_src_input: np.ndarray
    map_tgt_input: np.ndarray
    alpha_input: np.ndarray
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
    with clock("global_affine"):
        glob = fit_global_affine(pts_src, pts_tgt, cfg)
    affine = glob.affine_src_to_tgt
    near = near_model(affine, pts_src, pts_tgt, cfg.local_match_px)
    near_src, near_tgt = pts_src[near], pts_tgt[near]
    with clock("overlap"):
        overlap = plan_overlap(img_src.shape, img_tgt.shape, affine, cfg)
    with clock("cells"):
        cells = grid_cells(overlap, cfg)
    with clock("local_affines"):
        local = fit_local_affines(near_src, near_tgt, affine, cells, cfg)
    with clock("ffd"):
        field = ffd_field_canvas(overlap.canvas, affine, local.affines_src_to_tgt, local.centres_tgt, local.conf,
                                 sigma_f(local, cfg), cfg)
    with clock("gate"):
        gate = gate_canvas(source_only_mask(overlap), overlap.canvas.tgt_to_canvas(near_tgt),
                           _diagonal_px(img_src, img_tgt), _long_side_px(img_src, img_tgt), cfg)
        field_guarded = guard_field(field, gate, cfg)
    with clock("warp_map"):
        map_src = source_map_canvas(overlap.canvas, affine, field_guarded, cfg)
    return Warp(glob, overlap, local, pts_src[glob.inliers], pts_tgt[glob.inliers], field, gate, map_src)


def estimate_seam(img_src: np.ndarray, img_tgt: np.ndarray, warp: Warp, cfg: Config, clock: StageClock) -> Seam:
    """SENA steps 7-9 ("Optimal stitching line", "Partitioning and Reconstruction") in the working frame;
    ``cfg.device`` resolved."""
    canvas, mask_canvas = warp.overlap.canvas, warp.overlap.mask_canvas
    with clock("forward_points"):
        pts_src_canvas = forward_points(warp.map_src_canvas, warp.glob.affine_src_to_tgt, canvas, warp.inliers_src, cfg)
    pts_tgt_canvas = canvas.tgt_to_canvas(warp.inliers_tgt)
    with clock("grey_canvas"):
        grey_src_canvas, grey_tgt_canvas = _grey_canvas(img_src, img_tgt, warp, cfg)
    with clock("zone"):
        zone = adequate_zone(pts_src_canvas, pts_tgt_canvas, mask_canvas, grey_src_canvas, grey_tgt_canvas, cfg)
    with clock("chain"):
        anchors_src, anchors_tgt = keypoint_chain(zone, pts_src_canvas, pts_tgt_canvas, grey_src_canvas,
                                                  grey_tgt_canvas, mask_canvas, cfg)
    with clock("seam_maps"):
        maps = seam_maps(warp.map_src_canvas, canvas, anchors_src, anchors_tgt, cfg)
    return Seam(zone, anchors_src, anchors_tgt, maps)


def estimate_maps(img_a: np.ndarray, img_b: np.ndarray, cfg: Config, reference: str = "auto",
                  matches: Matches | None = None,
                  transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> StitchMaps:
    """All of SENA on one image pair: the maps that stitch it (and every later frame of the same rig).

    ``cfg.device`` must be resolved (``runtime.resolve_config``: the job calling this, an image or a
    video stitch, chooses the device once). ``matches`` of (img_a, img_b) found earlier (e.g. while
    screening video frames) skip step 0. ``transparent``: per image, (H, W) bool pixels that are not
    content (no keypoints there) or None.
    """
    clock = StageClock()
    if matches is None:
        with clock("features"):
            matches = match_images(img_a, img_b, cfg, transparent)
    rig = detect_rig(matches.pts_a, matches.pts_b, reference)
    img_src, img_tgt = (image_to_working(img, rig) for img in rig.pick(img_a, img_b))
    pts_src, pts_tgt = matches_to_working(matches.pts_a, matches.pts_b, rig)
    warp = estimate_warp(img_src, img_tgt, pts_src, pts_tgt, cfg, clock)
    seam = estimate_seam(img_src, img_tgt, warp, cfg, clock)
    return StitchMaps(
        rig=rig,
        map_src_input=map_from_working(seam.maps.map_src_canvas, rig),
        map_tgt_input=map_from_working(seam.maps.map_tgt_canvas, rig),
        alpha_input=map_from_working(seam.maps.alpha_canvas, rig),
        matches=matches,
        warp=warp,
        seam=seam,
        seconds=clock.seconds,
    )


def stitch_images(img_a: np.ndarray, img_b: np.ndarray, cfg: Config, reference: str = "auto",
                  transparent: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> Panorama:
    """Stitch two BGR uint8 images; returns a BGRA panorama (alpha 0 where nothing was covered).

    The Warp device of ``cfg`` ("auto", "cpu" or "cuda") is resolved here, once for the whole stitch.
    ``transparent``: per image, (H, W) bool pixels that are not content (an input's alpha 0) or None:
    no keypoints there, and the canvas takes the other image there, or nothing (alpha 0).
    """
    cfg = runtime.resolve_config(cfg)
    clock = StageClock()
    with clock("load_kernels"):  # a first run's compile gets its own time, not a stage's
        runtime.prewarm(cfg.device)
    stage("estimating maps")
    with naming_scale_ratio(img_a, img_b, cfg):
        maps = estimate_maps(img_a, img_b, cfg, reference, transparent=transparent)
    clock.seconds.update(maps.seconds)
    img_src, img_tgt = maps.rig.pick(img_a, img_b)
    transparent_src, transparent_tgt = maps.rig.pick(*transparent)
    stage("compositing")
    with clock("composite"):
        compositor = Compositor(without_transparent(maps.map_src_input, transparent_src),
                                without_transparent(maps.map_tgt_input, transparent_tgt), maps.alpha_input, cfg)
        out, coverage = compositor.apply(img_src, img_tgt)
    return Panorama(np.dstack([out, coverage]), maps, clock.seconds)


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
    """The larger image diagonal, the scale of the gate's ramp band b (SENA.md step 5)."""
    return float(max(np.hypot(*img_src.shape[:2]), np.hypot(*img_tgt.shape[:2])))


def _long_side_px(img_src: np.ndarray, img_tgt: np.ndarray) -> int:
    """The longest image side, the scale of the gate's density blur sigma_d (SENA.md step 5)."""
    return max(*img_src.shape[:2], *img_tgt.shape[:2])


def _grey_canvas(img_src: np.ndarray, img_tgt: np.ndarray, warp: Warp, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """Warped-source and placed-target grey images on the canvas, float32, NaN where not covered."""
    canvas = warp.overlap.canvas
    warped, valid = remap_image(cv2.cvtColor(img_src, cv2.COLOR_BGR2GRAY)[:, :, None], warp.map_src_canvas, cfg)
    grey_src = np.where(valid, warped[:, :, 0].astype(np.float32), np.nan)
    grey_tgt = np.full(canvas.shape, np.nan, np.float32)
    ox, oy = (int(round(v)) for v in canvas.offset_tgt)
    h, w = img_tgt.shape[:2]
    grey_tgt[oy:oy + h, ox:ox + w] = cv2.cvtColor(img_tgt, cv2.COLOR_BGR2GRAY)
    return grey_src.astype(np.float32), grey_tgt
