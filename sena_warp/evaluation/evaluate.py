"""``sena-warp eval DATA_DIR --out DIR``: SENA against four baselines on every pair, in numbers and pictures.

For every pair folder of DATA_DIR (one holding ``a.*`` and ``b.*``) it runs

- ``sena``: the whole SENA stitch (``stitch_images``);
- ``sena_ba``: the same with the inputs swapped (``b a``: it must give the same panorama);
- ``sena_paper``: SENA as the paper has it (``PAPER_SETTINGS``), the ablation of
  every departure at once;
- ``affine``: SENA's own global affine ``A_glob`` alone (no local warp, no seam);
- ``homography``: a global homography from SIFT matches and RANSAC (3 px);
- ``opencv_panorama`` / ``opencv_scans``: OpenCV's stitcher (``cv2.Stitcher``) in its two modes,

and records per method: success (or why not), time, overlap PSNR/SSIM (UDIS-D protocol of
``metrics``), the shape figures (how far the warp is locally from a similarity; how far long lines
bend) and, for SENA's runs, the seam figures, the natural-appearance figures of ``naturalness``
(duplicated / lost points, seam step, bend of the lines the panorama shows, continuity of the lines
the seam cuts) and the dense figures of ``dense`` (misalignment wherever the views switch, what is
shown twice or nowhere, tone fidelity against a plain gain). SENA, affine and homography are compared with the target in
the target frame (the source warped onto it); OpenCV's stitcher is compared in its own panorama
frame, both views warped by the camera models it composed with, before its seams and blending.
Shape figures cover both views of each method's panorama: SENA and the global models leave the
target as it is; OpenCV's projection warps both.

Writes ``results.csv`` (one row per pair and method), ``summary.md``, ``sheets/PAIR.png`` (inputs,
SENA, both OpenCV modes) and ``overview.jpg`` (every pair, small). A pair or method that fails is
recorded with its message and the run goes on.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import stat
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.errors import InputError, StitchError
from sena_warp.features import match_images
from sena_warp.imageio import input_stat, read_image, write_image
from sena_warp.kernels.runtime import resolve_config
from sena_warp.outputs import OutputPlan, atomic_output, staged
from sena_warp.progress import Count, echo
from sena_warp.rig import Rig, detect_rig, image_to_working
from sena_warp.stitch import Panorama, stitch_images
from sena_warp.warp_map import forward_points

from .baselines import (OPENCV_MODES, affine_map_canvas, homography_forward, homography_to_target, opencv_forward,
                        opencv_stitch, opencv_views, sift_homography)
from .figures import (dense_figures, identity, in_target_frame, map_in_target_frame, natural_figures, overlap_figures,
                      seam_figures, shape_figures)
from .metrics import overlap_psnr_ssim
from .sheets import thumbnail, tile

SENA_RUNS = ("sena", "sena_ba", "sena_paper")
METHODS = (*SENA_RUNS, "affine", "homography", *OPENCV_MODES)
# SENA as the paper has it: every departure undone (docs/method.md; what each buys: docs/evaluation.md).
PAPER_SETTINGS = dict(ffd_model="blend", gate_model="paper", seam_model="paper", gain_model="none",
                      seam_blend_ratio=0.0, border_blend=False, transition_px=24, global_model_choice="inliers",
                      switch_align=False, thin_strip_ratio=0.0, source_past_target=True)
# The methods that make a panorama (the pictures show them), with their names on the pictures.
SHEET_METHODS = {"sena": "SENA", "sena_paper": "SENA (paper)", "opencv_panorama": "OpenCV PANORAMA",
                 "opencv_scans": "OpenCV SCANS"}
COLUMNS = 2 + len(SHEET_METHODS)  # a sheet row: both inputs, then those panoramas
PAIR_THUMB_WH = (360, 240)  # per-pair sheet: thumbnail box (px)
OVERVIEW_THUMB_WH = (180, 116)  # overview sheet: thumbnail box (px)
OVERVIEW_JPEG_QUALITY = 72
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp")


@dataclass
class MethodResult:
    """One method on one pair: the CSV row. NaN = not defined (failed, or not that method's figure)."""

    pair: str
    method: str
    ok: bool = False
    error: str = ""
    seconds: float = math.nan  # to the panorama (sena, opencv_*) or to the model (affine, homography)
    psnr_db: float = math.nan
    ssim: float = math.nan
    anisotropy: float = math.nan  # mean over both views of similarity_deviation of the local Jacobian
    line_bend_mean_pct: float = math.nan  # mean over both views' long lines
    line_bend_max_pct: float = math.nan
    lines: int = 0
    width: int = 0  # panorama size (methods that make one)
    height: int = 0
    anchors: int = 0  # SENA's seam figures (anchor residuals, seam and feather MAD)
    anchor_residual_px: float = math.nan  # median over the anchors
    anchor_residual_max_px: float = math.nan
    seam_mad: float = math.nan
    feather_mad: float = math.nan
    copies: int = 0  # the natural-appearance figures (naturalness), SENA's runs
    dup_lost_pct: float = math.nan
    dup_lost_over_4px: int = 0
    dup_lost_worst_px: float = math.nan
    seam_step: float = math.nan
    border_step: float = math.nan
    visible_bend_max_pct: float = math.nan
    continuity_px: float = math.nan
    cut_lines: int = 0
    seam_misalign_median_px: float = math.nan  # the dense figures (dense), SENA's runs
    seam_misalign_p95_px: float = math.nan
    border_misalign_median_px: float = math.nan
    border_misalign_p95_px: float = math.nan
    doubled_pct: float = math.nan
    lost_pct: float = math.nan
    dup_objects: int = 0
    dup_object_px: int = 0
    tone_spread_pct: float = math.nan
    tone_spread_plain_pct: float = math.nan
    tone_colour_pct: float = math.nan
    tone_colour_plain_pct: float = math.nan
    white_cast_grey: float = math.nan
    white_cast_plain_grey: float = math.nan
    order_diff_grey: float = math.nan  # sena_ba: largest |panorama(b, a) - panorama(a, b)|
    panorama: np.ndarray | None = field(default=None, repr=False)  # BGR(A) uint8; not written to the CSV


CSV_FIELDS = tuple(f.name for f in fields(MethodResult) if f.name != "panorama")


@dataclass(frozen=True)
class PairImages:
    """A pair in the input frame and in SENA's working frame (source left, vertical rigs transposed)."""

    name: str
    img_a: np.ndarray
    img_b: np.ndarray
    rig: Rig
    img_src: np.ndarray
    img_tgt: np.ndarray


def pair_folders(data_dir: str | os.PathLike) -> list[Path]:
    """The pair folders of ``data_dir`` (each with an ``a.*`` or a ``b.*`` image: one lacking the other
    is evaluated as failed), sorted; the folder itself when it is one. InputError when there is none."""
    data_dir = Path(data_dir)
    if not stat.S_ISDIR(input_stat(data_dir).st_mode):
        raise InputError(f"{data_dir}: not a folder; give a folder of pair folders (each with a.* and b.*)")

    def is_pair(folder: Path) -> bool:
        return any(p.suffix.lower() in IMAGE_SUFFIXES for stem in ("a", "b") for p in folder.glob(f"{stem}.*"))

    if is_pair(data_dir):
        return [data_dir]
    folders = sorted(p for p in data_dir.iterdir() if p.is_dir() and is_pair(p))
    if not folders:
        raise InputError(f"{data_dir}: no pair folders (sub-folders holding an a.* and a b.* image)")
    return folders


def _image_named(folder: Path, stem: str) -> Path | None:
    found = [p for p in folder.glob(f"{stem}.*") if p.suffix.lower() in IMAGE_SUFFIXES]
    return found[0] if len(found) == 1 else None


def run_sena(pair: PairImages, method: str, cfg: Config) -> tuple[MethodResult, Panorama]:
    """One of ``SENA_RUNS`` on the pair: the stitch, timed, and its figures."""
    img_a, img_b = (pair.img_b, pair.img_a) if method == "sena_ba" else (pair.img_a, pair.img_b)
    run_cfg = cfg.replace(**PAPER_SETTINGS) if method == "sena_paper" else cfg
    t0 = time.perf_counter()
    pano = stitch_images(img_a, img_b, run_cfg)
    result = MethodResult(pair.name, method, True, seconds=time.perf_counter() - t0, panorama=pano.image,
                          width=pano.image.shape[1], height=pano.image.shape[0])
    warp, seam = pano.maps.warp, pano.maps.seam
    result.psnr_db, result.ssim = overlap_figures(img_a, img_b, pano, run_cfg)
    src, tgt = (image_to_working(img, pano.maps.rig) for img in pano.maps.rig.pick(img_a, img_b))

    def forward(pts: np.ndarray) -> np.ndarray:
        return forward_points(seam.maps.map_src_canvas, warp.glob.affine_src_to_tgt, warp.overlap.canvas, pts, run_cfg)

    _set(result, **shape_figures([(src, forward), (tgt, identity)]), **seam_figures(img_a, img_b, pano, run_cfg),
         **natural_figures(img_a, img_b, pano, run_cfg), **dense_figures(img_a, img_b, pano, run_cfg))
    return result, pano


def run_affine(pair: PairImages, pano: Panorama, cfg: Config) -> MethodResult:
    """SENA's own global affine ``A_glob`` alone (no local warp), from the same stitch."""
    warp = pano.maps.warp
    src, tgt = pair.img_src, pair.img_tgt
    result = MethodResult(pair.name, "affine", True, seconds=pano.seconds["features"] + pano.seconds["global_affine"])
    result.psnr_db, result.ssim = in_target_frame(
        src, map_in_target_frame(affine_map_canvas(warp, cfg), warp, tgt.shape), tgt, cfg)
    _set(result, **shape_figures([(src, homography_forward(warp.glob.affine_src_to_tgt)), (tgt, identity)]))
    return result


def run_homography(pair: PairImages, cfg: Config) -> MethodResult:
    """The SIFT + RANSAC homography, source warped into the target frame."""
    t0 = time.perf_counter()
    homography = sift_homography(pair.img_src, pair.img_tgt, cfg)
    result = MethodResult(pair.name, "homography", True, seconds=time.perf_counter() - t0)
    warped, valid = homography_to_target(pair.img_src, homography, pair.img_tgt.shape)
    result.psnr_db, result.ssim = overlap_psnr_ssim(warped, valid, pair.img_tgt, np.ones(valid.shape, bool))
    _set(result, **shape_figures([(pair.img_src, homography_forward(homography)), (pair.img_tgt, identity)]))
    return result


def run_opencv(pair: PairImages, method: str) -> MethodResult:
    """OpenCV's stitcher in ``method``'s mode; overlap figures in its panorama frame."""
    stitch = opencv_stitch(pair.img_a, pair.img_b, method)
    result = MethodResult(pair.name, method, True, seconds=stitch.seconds, panorama=stitch.panorama,
                          width=stitch.panorama.shape[1], height=stitch.panorama.shape[0])
    (view_a, valid_a), (view_b, valid_b) = opencv_views(stitch, (pair.img_a, pair.img_b))
    result.psnr_db, result.ssim = overlap_psnr_ssim(view_a, valid_a, view_b, valid_b)
    _set(result, **shape_figures([(pair.img_a, opencv_forward(stitch, 0)), (pair.img_b, opencv_forward(stitch, 1))]))
    return result


def _set(result: MethodResult, **values) -> None:
    for name, value in values.items():
        setattr(result, name, value)


def failure_message(exc: BaseException) -> str:
    """A StitchError's own message; anything else (a bug, or an error inside OpenCV) with its type."""
    if isinstance(exc, StitchError):
        return str(exc)
    traceback.print_exc(file=sys.stderr)
    return f"{type(exc).__name__}: {exc}".strip()


def read_inputs(folder: Path, max_megapixels: float) -> tuple[list[np.ndarray | None], str]:
    """The pair's two images (None where missing or unreadable) and the reading errors, joined."""
    images, errors = [], []
    for stem in ("a", "b"):
        path = _image_named(folder, stem)
        try:
            if path is None:
                raise InputError(f"{folder}: no {stem}.* image, or more than one")
            images.append(read_image(path, max_megapixels))
        except StitchError as exc:
            images.append(None)
            errors.append(str(exc))
    return images, "; ".join(errors)


def evaluate_pair(folder: Path, img_a: np.ndarray, img_b: np.ndarray, cfg: Config) -> list[MethodResult]:
    """Every method on one pair, in ``METHODS`` order; failures recorded, never raised."""
    pair = PairImages(folder.name, img_a, img_b, None, img_a, img_b)
    results, panoramas = {}, {}
    for method in SENA_RUNS:
        try:
            results[method], panoramas[method] = run_sena(pair, method, cfg)
        except Exception as exc:  # noqa: BLE001 - recorded, the run goes on
            results[method] = MethodResult(folder.name, method, error=failure_message(exc))
    pano = panoramas.get("sena")
    if pano is not None and "sena_ba" in panoramas:
        results["sena_ba"].order_diff_grey = order_difference(pano.image, panoramas["sena_ba"].image)
    # SENA's rig orients the global baselines (source = its left view); without it, SIFT's matches do.
    rig = pano.maps.rig if pano is not None else _sift_rig(img_a, img_b, cfg)
    img_src, img_tgt = (image_to_working(img, rig) for img in rig.pick(img_a, img_b))
    pair = PairImages(folder.name, img_a, img_b, rig, img_src, img_tgt)
    runners = {"affine": lambda: run_affine(pair, pano, cfg), "homography": lambda: run_homography(pair, cfg)}
    runners.update({method: (lambda method=method: run_opencv(pair, method)) for method in OPENCV_MODES})
    for name, runner in runners.items():
        if pano is None and name == "affine":
            results[name] = MethodResult(folder.name, name, error=results["sena"].error)
            continue
        try:
            results[name] = runner()
        except Exception as exc:  # noqa: BLE001 - recorded, the run goes on
            results[name] = MethodResult(folder.name, name, error=failure_message(exc))
    return [results[name] for name in METHODS]


def order_difference(pano_ab: np.ndarray, pano_ba: np.ndarray) -> float:
    """Largest absolute difference (grey levels) between the panoramas of ``a b`` and ``b a``; inf when
    their sizes differ."""
    if pano_ab.shape != pano_ba.shape:
        return math.inf
    return float(np.abs(pano_ab.astype(np.int16) - pano_ba.astype(np.int16)).max())


def _sift_rig(img_a: np.ndarray, img_b: np.ndarray, cfg: Config) -> Rig:
    sift = match_images(img_a, img_b, cfg.replace(features="sift"))
    return detect_rig(sift.pts_a, sift.pts_b, img_a.shape)


def input_cells(folder: Path, images: list[np.ndarray | None], box_wh: tuple[int, int]) -> list[np.ndarray]:
    """Thumbnails of a pair's two inputs (an empty cell for an unreadable one)."""
    return [thumbnail(img, f"{folder.name}: {stem}" + ("" if img is not None else " unreadable"), box_wh)
            for stem, img in zip(("a", "b"), images)]


def method_cells(results: list[MethodResult], box_wh: tuple[int, int], with_size: bool) -> list[np.ndarray]:
    """Thumbnails of the panoramas of ``SHEET_METHODS``, labelled with PSNR (and size), or FAILED."""
    by_method = {r.method: r for r in results}
    cells = []
    for method, name in SHEET_METHODS.items():
        r = by_method[method]
        size = f", {r.width}x{r.height}" if with_size else ""
        label = f"{name}: {r.psnr_db:.1f} dB{size}" if r.ok else f"{name}: FAILED"
        cells.append(thumbnail(r.panorama, label, box_wh))
    return cells


def _fmt(value, digits: int = 4) -> str:
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.{digits}f}"
    return str(value)


def write_csv(path: Path, rows: list[MethodResult]) -> None:
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_FIELDS)
        for row in rows:
            values = asdict(row)
            writer.writerow([_fmt(values[name]) for name in CSV_FIELDS])


def _finite(values) -> np.ndarray:
    return np.asarray([v for v in values if math.isfinite(v)], np.float64)


def _mean(values) -> float:
    values = _finite(values)
    return float(values.mean()) if values.size else math.nan


def _median(values) -> float:
    values = _finite(values)
    return float(np.median(values)) if values.size else math.nan


def _max(values) -> float:
    values = _finite(values)
    return float(values.max()) if values.size else math.nan


def summary_markdown(rows: list[MethodResult], data_dir: Path, cfg: Config, seconds: float) -> str:
    """``summary.md``: per method, per pair PSNR/SSIM, SENA's seam figures, the failures."""
    pairs = sorted({r.pair for r in rows})
    table = {(r.pair, r.method): r for r in rows}
    common = [p for p in pairs if all(table[p, m].ok for m in METHODS)]
    lines = [
        "# sena-warp eval", "",
        f"Data: `{data_dir}` ({len(pairs)} pairs); features {cfg.features}, device {cfg.device}; "
        f"{time.strftime('%Y-%m-%d %H:%M %Z')}; {os.cpu_count()} CPUs; {seconds:.0f} s in all.", "",
        "Overlap PSNR (dB) / SSIM, UDIS-D protocol: `sena`, `affine`, `homography` in the target frame (source "
        "warped onto the target); `opencv_*` in OpenCV's panorama frame (both views warped by its cameras, before "
        "its seams and blending). Time: to the panorama (`sena`, `opencv_*`, all stages) or to the model "
        "(`affine`: XFeat matching and RANSAC; `homography`: SIFT matching and RANSAC). Anisotropy: mean over both "
        "views of s_max / s_min - 1 of the warp's local Jacobian (0 = a similarity). Line bend: largest distance of "
        "a long line's warped image from its chord, % of its length, mean / max over both views' long lines. PSNR, "
        "SSIM, time: mean over pairs; anisotropy and mean line bend: median over pairs (a degenerate panorama "
        "would swamp a mean); max line bend: over all pairs.", "",
        f"## Methods ({len(common)} pairs stitched by all five: the 'common' columns)", "",
        "| method | stitched | mean time s | mean PSNR / SSIM | common PSNR / SSIM | anisotropy | line bend mean / max % |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for method in METHODS:
        own = [table[p, method] for p in pairs if table[p, method].ok]
        shared = [table[p, method] for p in common]
        lines.append(
            f"| {method} | {len(own)}/{len(pairs)} | {_fmt(_mean(r.seconds for r in own), 2)} | "
            f"{_fmt(_mean(r.psnr_db for r in own), 2)} / {_fmt(_mean(r.ssim for r in own), 3)} | "
            f"{_fmt(_mean(r.psnr_db for r in shared), 2)} / {_fmt(_mean(r.ssim for r in shared), 3)} | "
            f"{_fmt(_median(r.anisotropy for r in own), 3)} | {_fmt(_median(r.line_bend_mean_pct for r in own), 2)} / "
            f"{_fmt(_max(r.line_bend_max_pct for r in own), 2)} |")
    lines += ["", "## Overlap PSNR / SSIM per pair", "",
              "| pair | " + " | ".join(METHODS) + " |", "|---|" + "---:|" * len(METHODS)]
    for p in pairs:
        cells = [f"{table[p, m].psnr_db:.2f} / {table[p, m].ssim:.3f}" if table[p, m].ok else "failed" for m in METHODS]
        lines.append(f"| {p} | " + " | ".join(cells) + " |")
    lines += ["", "## SENA's seam per pair", "",
              "| pair | anchors | median anchor residual px | seam MAD | feather MAD |", "|---|---:|---:|---:|---:|"]
    for p in pairs:
        r = table[p, "sena"]
        if r.ok:
            lines.append(f"| {p} | {r.anchors} | {r.anchor_residual_px:.3f} | {r.seam_mad:.2f} | {r.feather_mad:.2f} |")
    lines += natural_markdown(pairs, table)
    lines += dense_markdown(pairs, table)
    failures = [r for r in rows if not r.ok]
    lines += ["", "## Failures", ""]
    lines += [f"- {r.pair}, {r.method}: {r.error}" for r in failures] or ["- none"]
    return "\n".join(lines) + "\n"


def natural_markdown(pairs: list[str], table: dict) -> list[str]:
    """The summary's natural-appearance section: the targets per SENA run over all pairs, then each pair."""
    lines = ["", "## Natural appearance", "",
             "Duplicated / lost: reliable matches in the overlap whose two copies are > 2 px apart and both "
             "visible or neither (`naturalness`); seam step and border step (across the target's border beyond "
             "the seam's ends) in grey levels; bend: largest of the long lines each "
             "view shows whole (%); continuity: median offset of the lines the seam cuts (px); order: largest "
             "difference of the `b a` panorama from `a b`'s (grey levels).", "",
             "| run | pairs with a point > 4 px | pairs > 0.5 % | worst % | seam step median / max | border step median / "
             "max | bend max % (pairs > 2 %) | continuity median px | seam MAD < feather MAD | order diff max |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for run in SENA_RUNS:
        done = _done(pairs, table, run)
        lines.append(
            f"| {run} | {sum(r.dup_lost_over_4px > 0 for r in done)} | {sum(r.dup_lost_pct > 0.5 for r in done)} | "
            f"{_fmt(_max(r.dup_lost_pct for r in done), 2)} | {_fmt(_median(r.seam_step for r in done), 2)} / "
            f"{_fmt(_max(r.seam_step for r in done), 2)} | {_fmt(_median(r.border_step for r in done), 2)} / "
            f"{_fmt(_max(r.border_step for r in done), 2)} | {_fmt(_max(r.visible_bend_max_pct for r in done), 2)} "
            f"({sum(r.visible_bend_max_pct > 2 for r in done)}) | {_fmt(_median(r.continuity_px for r in done), 2)} | "
            f"{sum(r.seam_mad < r.feather_mad for r in done)}/{len(done)} | "
            f"{_fmt(_max(r.order_diff_grey for r in done), 1)} |")
    lines += ["", "| pair | run | dup/lost % (> 4 px, worst px) | seam step | border step | bend max % | "
              "continuity px (cut lines) |", "|---|---|---:|---:|---:|---:|---:|"]
    lines += _pair_rows(pairs, table, lambda r: (
        f"{r.dup_lost_pct:.2f} ({r.dup_lost_over_4px}, {_fmt(r.dup_lost_worst_px, 1)}) | {_fmt(r.seam_step, 2)} | "
        f"{_fmt(r.border_step, 2)} | {_fmt(r.visible_bend_max_pct, 2)} | {_fmt(r.continuity_px, 2)} ({r.cut_lines})"))
    return lines


def _done(pairs: list[str], table: dict, run: str) -> list:
    """The results of ``run`` on ``pairs`` that succeeded."""
    return [table[p, run] for p in pairs if table[p, run].ok]


def _pair_rows(pairs: list[str], table: dict, cells) -> list[str]:
    """A table row per pair and SENA run that succeeded: ``| pair | run | cells(result) |``."""
    return [f"| {p} | {run} | {cells(table[p, run])} |" for p in pairs for run in SENA_RUNS if table[p, run].ok]


def dense_markdown(pairs: list[str], table: dict) -> list[str]:
    """The summary's dense-figures section: per SENA run over all pairs, then each pair."""
    lines = ["", "## Dense figures", "",
             "Misalignment: optical flow between the views as the panorama shows them, at textured pixels within "
             "T/2 of the seam and near the borders where the views switch beyond it (px, median / 95th percentile); "
             "doubled / lost: of the consistent textured overlap pixels, % whose two copies (the flow) are > 2 px "
             "apart and both shown or neither; objects: such regions of >= 60 px (largest px); tone: spread of "
             "log(panorama / view) within 12 px blocks and the colour a block takes on, 99th percentile over blocks "
             "(%), against the plain panorama (each view times its gains: 'plain'); white cast: channel spread of "
             "clipped whites (grey levels) against the plain one's (`dense`).", "",
             "| run | seam p95 median / max / pairs > 2 | border p95 median / max / pairs > 2 | pairs with an object | "
             "tone spread worse than plain by > 1 (pairs) | tone colour worse than plain by > 1 (pairs) | white cast max |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for run in SENA_RUNS:
        done = _done(pairs, table, run)
        seam_p95 = [r.seam_misalign_p95_px for r in done]
        border_p95 = [r.border_misalign_p95_px for r in done]
        lines.append(
            f"| {run} | {_fmt(_median(seam_p95), 2)} / {_fmt(_max(seam_p95), 2)} / {sum(v > 2 for v in seam_p95)} | "
            f"{_fmt(_median(border_p95), 2)} / {_fmt(_max(border_p95), 2)} / {sum(v > 2 for v in border_p95)} | "
            f"{sum(r.dup_objects > 0 for r in done)} | "
            f"{sum(r.tone_spread_pct > r.tone_spread_plain_pct + 1 for r in done)} | "
            f"{sum(r.tone_colour_pct > r.tone_colour_plain_pct + 1 for r in done)} | "
            f"{_fmt(_max(r.white_cast_grey for r in done), 1)} |")
    lines += ["", "| pair | run | seam px median / p95 | border px median / p95 | doubled / lost % (objects, largest px) | "
              "tone spread / plain % | tone colour / plain % | white cast / plain |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    lines += _pair_rows(pairs, table, lambda r: (
        f"{_fmt(r.seam_misalign_median_px, 2)} / {_fmt(r.seam_misalign_p95_px, 2)} | "
        f"{_fmt(r.border_misalign_median_px, 2)} / {_fmt(r.border_misalign_p95_px, 2)} | "
        f"{r.doubled_pct:.2f} / {r.lost_pct:.2f} ({r.dup_objects}, {r.dup_object_px}) | "
        f"{_fmt(r.tone_spread_pct, 1)} / {_fmt(r.tone_spread_plain_pct, 1)} | "
        f"{_fmt(r.tone_colour_pct, 1)} / {_fmt(r.tone_colour_plain_pct, 1)} | "
        f"{_fmt(r.white_cast_grey, 1)} / {_fmt(r.white_cast_plain_grey, 1)}"))
    return lines


def pair_line(results: list[MethodResult]) -> str:
    """One stdout line per pair: each method's PSNR or 'failed'."""
    parts = [f"{r.method} {r.psnr_db:.2f} dB" if r.ok else f"{r.method} failed" for r in results]
    return f"{results[0].pair}: " + ", ".join(parts)


def run_eval(data_dir: str | os.PathLike, out_dir: str | os.PathLike, cfg: Config,
             plan: OutputPlan | None = None) -> list[MethodResult]:
    """Evaluate every pair of ``data_dir`` into ``out_dir`` (see the module docstring); the rows of results.csv.

    The Warp device of ``cfg`` is resolved once, here, for every pair and method. ``plan``: commit the
    folder with that plan's other outputs (see ``sena_warp.outputs``).
    """
    t0 = time.perf_counter()
    cfg = resolve_config(cfg)
    folders = pair_folders(data_dir)
    with staged(plan, out_dir, (data_dir,), folder=True) as plan, plan.writing(out_dir) as out_dir:
        sheets_dir = out_dir / "sheets"
        sheets_dir.mkdir()
        bar = Count("pairs", len(folders))
        rows, overview = [], []
        for done, folder in enumerate(folders):
            bar.update(done)
            images, read_error = read_inputs(folder, cfg.max_input_megapixels)
            if read_error:
                results = [MethodResult(folder.name, name, error=read_error) for name in METHODS]
            else:
                results = evaluate_pair(folder, *images, cfg)
            write_image(sheets_dir / f"{folder.name}.png",
                        tile(input_cells(folder, images, PAIR_THUMB_WH) + method_cells(results, PAIR_THUMB_WH, True),
                             COLUMNS))
            overview += input_cells(folder, images, OVERVIEW_THUMB_WH) + method_cells(results, OVERVIEW_THUMB_WH, False)
            for r in results:
                r.panorama = None  # drawn; memory stays flat over many pairs
            rows += results
            echo(pair_line(results))
        bar.close(len(folders))
        write_csv(out_dir / "results.csv", rows)
        write_image(out_dir / "overview.jpg", tile(overview, COLUMNS),
                    params=(cv2.IMWRITE_JPEG_QUALITY, OVERVIEW_JPEG_QUALITY))
        with atomic_output(out_dir / "summary.md") as tmp:
            tmp.write_text(summary_markdown(rows, Path(data_dir), cfg, time.perf_counter() - t0))
    return rows


def cmd_eval(args: argparse.Namespace) -> int:
    """``sena-warp eval``: evaluate, then print where the results are."""
    from sena_warp.jobs import checked, job_config

    cfg = job_config(args.settings)
    plan = OutputPlan((args.data_dir,), args.overwrite)
    plan.add(args.out, "--out", folder=True)
    if not checked(plan):
        return 0
    with plan:
        rows = run_eval(args.data_dir, args.out, cfg, plan)
    stitched = sum(r.ok for r in rows if r.method == "sena")
    echo(f"{args.out}: results.csv, summary.md, overview.jpg, sheets/ ({stitched}/{len(rows) // len(METHODS)} "
          f"pairs stitched by SENA)")
    return 0
