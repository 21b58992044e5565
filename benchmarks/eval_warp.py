"""Warp alignment benchmark (issue 3): SENA warp vs the global affine vs a SIFT+RANSAC homography.

For every pair of ``--data`` (folders holding ``a.*`` and ``b.*``), with the default ``Config``
(XFeat): match, detect the rig (source = left), run SENA steps 1-6 (``estimate_warp``) and measure
overlap PSNR/SSIM (UDIS-D protocol, ``sena_warp.metrics``) in the TARGET frame: the canvas maps
are cropped to the target rectangle at the canvas's integer offset and the warped source is
compared with the target there, for

- SENA: the guarded source map ``M_s`` (SENA.md step 6),
- affine: ``A_glob`` alone (``source_map_canvas`` with a zero field),
- homography: OpenCV SIFT matches, ``cv2.findHomography`` RANSAC 3 px, source warped into the target
  frame with ``cv2.warpPerspective`` (valid where a warped image of ones is 1), same rig orientation.

Prints a Markdown table and summary lines; a pair that raises is listed with its message. The
"stretch" and "folded" columns are the shape cost of the local warp (``field_stretch``,
``folded_fraction``): alignment bought by folding the source is no gain.
``--set NAME=VALUE`` changes Config fields; ``--sweep S [S ...]`` matches each pair once and
re-runs steps 1-6 per setting S (``default`` or ``NAME=VALUE,NAME=VALUE``), printing one line per
setting (wins over the affine, mean gain, mean SENA and affine PSNR, stretch, folded pairs).
``--timing PAIR`` prints the per-stage seconds of ``estimate_warp`` (median of ``--runs`` runs
after one warm-up run) instead.

    .venv/bin/python benchmarks/eval_warp.py [--data ../shared/data/pairs] [--markdown FILE]
    .venv/bin/python benchmarks/eval_warp.py --sweep default grid_x=3,grid_y=3 lambda1=0.02
    .venv/bin/python benchmarks/eval_warp.py --timing sva_chessgirl [--runs 3]

Not a test: no assertions.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from sena_warp.baselines import HOMOGRAPHY_RANSAC_PX, affine_map_canvas, homography_to_target, map_in_target_frame
from sena_warp.config import Config
from sena_warp.evaluate import in_target_frame, pair_folders
from sena_warp.features import match_images
from sena_warp.imageio import read_image
from sena_warp.kernels.runtime import resolve_config
from sena_warp.metrics import overlap_psnr_ssim
from sena_warp.rig import Rig, detect_rig, image_to_working, matches_to_working
from sena_warp.stitch import StageClock, Warp, estimate_warp

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "pairs"
# The sweep's best setting that does not fold the source (docs/evaluation.md, "Warp alignment"):
# meets the wins and gain targets, not the homography one; kept out of the defaults (see there).
TUNED_SETTING = "ransac_reproj_px=25,grid_x=6,grid_y=6,lambda1=0.005,gamma_min=0.9"
WARP_STAGES = ("global_affine", "overlap", "cells", "local_affines", "ffd", "gate", "warp_map")


@dataclass(frozen=True)
class PairInputs:
    """One pair in the working frame (source left, vertical rigs transposed), with both match sets.

    ``pts_*`` (N, 2) float64 (x, y) XFeat matches; ``sift_*`` (M, 2) the SIFT matches, same frames.
    """

    name: str
    rig: Rig
    img_src: np.ndarray
    img_tgt: np.ndarray
    pts_src: np.ndarray
    pts_tgt: np.ndarray
    sift_src: np.ndarray
    sift_tgt: np.ndarray


@dataclass(frozen=True)
class PairFigures:
    """Overlap (PSNR dB, SSIM) of the three warps on one pair, and the match counts."""

    name: str
    matches: int
    inliers: int
    sena: tuple[float, float]
    affine: tuple[float, float]
    homography: tuple[float, float]
    stretch: float  # field_stretch of the SENA map: its departure from A_glob's shape
    folded: float  # folded_fraction of the SENA map over the overlap

    @property
    def gain_db(self) -> float:
        return self.sena[0] - self.affine[0]


def load_pair(folder: Path, cfg: Config) -> PairInputs:
    """Read ``folder/a.*`` and ``folder/b.*``, match them (cfg's detector and SIFT) and orient the rig."""
    img_a, img_b = read_image(next(folder.glob("a.*"))), read_image(next(folder.glob("b.*")))
    matches = match_images(img_a, img_b, cfg)
    sift = match_images(img_a, img_b, cfg.replace(features="sift"))
    rig = detect_rig(matches.pts_a, matches.pts_b)
    img_src, img_tgt = (image_to_working(img, rig) for img in rig.pick(img_a, img_b))
    pts_src, pts_tgt = matches_to_working(matches.pts_a, matches.pts_b, rig)
    sift_src, sift_tgt = matches_to_working(sift.pts_a, sift.pts_b, rig)
    return PairInputs(folder.name, rig, img_src, img_tgt, pts_src, pts_tgt, sift_src, sift_tgt)


def field_stretch(field_canvas: np.ndarray, mask_canvas: np.ndarray) -> float:
    """99th percentile over ``mask_canvas`` of |dD/du| (Frobenius norm, source px per canvas px).

    ``field_canvas`` (H, W, 2): how far M_s leaves A_glob. 0 for a pure affine; the shape cost of the
    local warp (0.1 changes a 10 px segment's length or direction by up to about 1 px).
    """
    if not mask_canvas.any():
        return 0.0
    grads = [np.gradient(field_canvas[:, :, k].astype(np.float64)) for k in range(2)]
    norm = np.sqrt(sum(g * g for pair_of_grads in grads for g in pair_of_grads))
    return float(np.percentile(norm[mask_canvas], 99))


def folded_fraction(map_src_canvas: np.ndarray, mask_canvas: np.ndarray) -> float:
    """Fraction of ``mask_canvas`` where M_s (H, W, 2) folds: det(dM_s/du) <= 0 (source content mirrored)."""
    if not mask_canvas.any():
        return 0.0
    # np.gradient returns (d/drow, d/dcol) = (d/dy, d/dx) of each map component.
    dsx_dy, dsx_dx = np.gradient(map_src_canvas[:, :, 0].astype(np.float64))
    dsy_dy, dsy_dx = np.gradient(map_src_canvas[:, :, 1].astype(np.float64))
    det = dsx_dx * dsy_dy - dsx_dy * dsy_dx
    return float(np.mean(det[mask_canvas] <= 0.0))


def homography_figures(pair: PairInputs) -> tuple[float, float]:
    """Overlap figures of the SIFT + RANSAC (3 px) homography baseline, target frame; nan when it fails."""
    if len(pair.sift_src) < 4:
        return float("nan"), float("nan")
    homography, _ = cv2.findHomography(pair.sift_src, pair.sift_tgt, cv2.RANSAC, HOMOGRAPHY_RANSAC_PX)
    if homography is None:
        return float("nan"), float("nan")
    warped, valid = homography_to_target(pair.img_src, homography, pair.img_tgt.shape)
    return overlap_psnr_ssim(warped, valid, pair.img_tgt, np.ones(valid.shape, bool))


def evaluate_pair(pair: PairInputs, cfg: Config) -> tuple[Warp, PairFigures]:
    """SENA steps 1-6 on one loaded pair and all three warps' overlap figures."""
    warp = estimate_warp(pair.img_src, pair.img_tgt, pair.pts_src, pair.pts_tgt, cfg, StageClock())
    map_affine = affine_map_canvas(warp, cfg)
    sena, affine = (
        in_target_frame(pair.img_src, map_in_target_frame(map_src, warp, pair.img_tgt.shape), pair.img_tgt, cfg)
        for map_src in (warp.map_src_canvas, map_affine)
    )
    stretch = field_stretch(warp.map_src_canvas - map_affine, warp.overlap.mask_canvas)
    folded = folded_fraction(warp.map_src_canvas, warp.overlap.mask_canvas)
    figures = PairFigures(pair.name, len(pair.pts_src), warp.glob.n_inliers, sena, affine,
                          homography_figures(pair), stretch, folded)
    return warp, figures


def load_all(data: Path, cfg: Config) -> tuple[list[PairInputs], list[tuple[str, str]]]:
    """Every loadable pair of ``data``, and (name, message) of those that failed to load."""
    pairs, failures = [], []
    for folder in pair_folders(data):
        try:
            pairs.append(load_pair(folder, cfg))
        except Exception as exc:  # a benchmark lists every failing pair instead of stopping at the first
            failures.append((folder.name, f"{type(exc).__name__}: {exc}"))
    return pairs, failures


def evaluate_all(pairs: list[PairInputs], cfg: Config) -> tuple[list[PairFigures], list[tuple[str, str]]]:
    """Figures per pair, and (name, message) of the pairs whose warp or figures raised."""
    rows, failures = [], []
    for pair in pairs:
        try:
            rows.append(evaluate_pair(pair, cfg)[1])
        except Exception as exc:  # a StitchError (e.g. too few inliers) or anything else: listed, not fatal
            failures.append((pair.name, f"{type(exc).__name__}: {exc}"))
    return rows, failures


def finite_mean(values) -> float:
    """Mean of the finite values (a failed homography gives nan); nan when there is none."""
    values = np.asarray(list(values), np.float64)
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else float("nan")


def summary(rows: list[PairFigures], n_pairs: int) -> dict[str, float]:
    """Issue 3 targets: SENA wins over the affine, mean gain, mean PSNR / SSIM of the three warps."""
    return {
        "wins": sum(r.gain_db > 0 for r in rows),
        "pairs": n_pairs,
        "mean_gain_db": finite_mean(r.gain_db for r in rows),
        "mean_sena_db": finite_mean(r.sena[0] for r in rows),
        "mean_affine_db": finite_mean(r.affine[0] for r in rows),
        "mean_homography_db": finite_mean(r.homography[0] for r in rows),
        "mean_sena_ssim": finite_mean(r.sena[1] for r in rows),
        "mean_affine_ssim": finite_mean(r.affine[1] for r in rows),
        "mean_homography_ssim": finite_mean(r.homography[1] for r in rows),
        "mean_stretch": finite_mean(r.stretch for r in rows),
        "folded_pairs": sum(r.folded > 0 for r in rows),
    }


def markdown_table(rows: list[PairFigures], failures: list[tuple[str, str]], n_pairs: int) -> str:
    """The per-pair table, the failures and the summary lines, as Markdown."""
    lines = [
        "| pair | matches | inliers | SENA PSNR / SSIM | affine PSNR / SSIM | homography PSNR / SSIM | SENA - affine (dB) "
        "| SENA stretch | SENA folded % |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r.name} | {r.matches} | {r.inliers} | {r.sena[0]:.2f} / {r.sena[1]:.3f} | "
                     f"{r.affine[0]:.2f} / {r.affine[1]:.3f} | {r.homography[0]:.2f} / {r.homography[1]:.3f} | "
                     f"{r.gain_db:+.2f} | {r.stretch:.3f} | {100 * r.folded:.2f} |")
    s = summary(rows, n_pairs)
    lines.append("")
    lines.extend(f"- failed: {name}: {message}" for name, message in failures)
    lines.append(f"- SENA beats the global affine on {s['wins']} of {s['pairs']} pairs; "
                 f"mean gain {s['mean_gain_db']:+.2f} dB")
    lines.append(f"- mean PSNR / SSIM: SENA {s['mean_sena_db']:.2f} / {s['mean_sena_ssim']:.3f}, "
                 f"affine {s['mean_affine_db']:.2f} / {s['mean_affine_ssim']:.3f}, "
                 f"homography {s['mean_homography_db']:.2f} / {s['mean_homography_ssim']:.3f}")
    lines.append(f"- mean SENA stretch (p99 |dD/du| over the overlap): {s['mean_stretch']:.3f}; "
                 f"pairs where the SENA map folds: {s['folded_pairs']}")
    return "\n".join(lines)


def parse_setting(text: str, base: Config) -> Config:
    """``default`` or ``NAME=VALUE[,NAME=VALUE...]`` -> a Config; each VALUE is cast to its field's type."""
    if text == "default":
        return base
    types = {f.name: type(getattr(base, f.name)) for f in dataclasses.fields(base)}
    changes = {}
    for item in text.split(","):
        name, _, value = item.partition("=")
        if name not in types:
            raise SystemExit(f"unknown Config field {name!r} in {text!r}")
        changes[name] = types[name](value)
    return base.replace(**changes)


def run_sweep(pairs: list[PairInputs], settings: list[str], base: Config) -> str:
    """One Markdown row per setting: wins over the affine, mean gain, mean SENA and affine PSNR, shape cost."""
    lines = ["| setting | wins | mean gain (dB) | mean SENA PSNR (dB) | mean affine PSNR (dB) | mean stretch "
             "| folded pairs | failures |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for text in settings:
        rows, failures = evaluate_all(pairs, parse_setting(text, base))
        s = summary(rows, len(pairs))
        line = (f"| {text} | {s['wins']}/{len(pairs)} | {s['mean_gain_db']:+.3f} | {s['mean_sena_db']:.3f} | "
                f"{s['mean_affine_db']:.3f} | {s['mean_stretch']:.3f} | {s['folded_pairs']} | {len(failures)} |")
        print(line, flush=True)
        lines.append(line)
    return "\n".join(lines)


def stage_timing(pair: PairInputs, cfg: Config, runs: int) -> dict[str, float]:
    """Median seconds per stage of ``estimate_warp`` over ``runs`` runs, after one warm-up run."""
    estimate_warp(pair.img_src, pair.img_tgt, pair.pts_src, pair.pts_tgt, cfg, StageClock())
    per_run = []
    for _ in range(runs):
        clock = StageClock()
        estimate_warp(pair.img_src, pair.img_tgt, pair.pts_src, pair.pts_tgt, cfg, clock)
        per_run.append(clock.seconds)
    medians = {stage: statistics.median(run[stage] for run in per_run) for stage in WARP_STAGES}
    medians["total (steps 1-6)"] = statistics.median(sum(run.values()) for run in per_run)
    return medians


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of pair folders (a.*, b.*)")
    parser.add_argument("--markdown", type=Path, help="also write the table (or sweep/timing) to this file")
    parser.add_argument("--set", default="default", help="Config changes NAME=VALUE[,NAME=VALUE...]")
    parser.add_argument("--sweep", nargs="+", metavar="SETTING", help="settings to compare (steps 1-6)")
    parser.add_argument("--timing", metavar="PAIR", help="per-stage warp seconds on this pair")
    parser.add_argument("--runs", type=int, default=3, help="timed runs for --timing")
    args = parser.parse_args()
    cfg = resolve_config(parse_setting(args.set, Config()))

    if args.timing:
        pair = load_pair(args.data / args.timing, cfg)
        shape = pair.img_src.shape
        lines = [f"{args.timing} ({shape[1]}x{shape[0]}), median of {args.runs} runs after a warm-up run:", "",
                 "| stage | seconds |", "|---|---:|"]
        lines += [f"| {stage} | {sec:.3f} |" for stage, sec in stage_timing(pair, cfg, args.runs).items()]
        text = "\n".join(lines)
        print(text)
    else:
        pairs, load_failures = load_all(args.data, cfg)
        if args.sweep:
            text = run_sweep(pairs, args.sweep, cfg)
        else:
            rows, failures = evaluate_all(pairs, cfg)
            text = markdown_table(rows, load_failures + failures, len(pairs) + len(load_failures))
            print(text)
        if load_failures:
            print("\n".join(f"- failed: {n}: {m}" for n, m in load_failures), file=sys.stderr)
    if args.markdown:
        args.markdown.write_text(text + "\n")


if __name__ == "__main__":
    main()
