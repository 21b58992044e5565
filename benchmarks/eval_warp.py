"""Warp alignment benchmark: SENA warp vs the global affine vs a SIFT+RANSAC homography.

For every pair of ``--data`` (folders holding ``a.*`` and ``b.*``), with the default ``Config``
(XFeat): match, detect the rig (source = left), run SENA steps 1-6 (``estimate_warp``) and measure
overlap PSNR/SSIM (UDIS-D protocol, ``sena_warp.evaluation.metrics``) in the TARGET frame: the
canvas maps are cropped to the target rectangle at the canvas's integer offset and the warped
source is compared with the target there (``sena_warp.evaluation.alignment``), for

- SENA: the guarded source map ``M_s`` (docs/method.md step 6),
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
import statistics
import sys
from pathlib import Path

import numpy as np

from sena_warp.config import Config
from sena_warp.evaluation.alignment import PairFigures, PairInputs, evaluate_pair, load_pair, parse_setting
from sena_warp.evaluation.evaluate import pair_folders
from sena_warp.kernels.runtime import resolve_config
from sena_warp.stitch import StageClock, estimate_warp

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "pairs"
WARP_STAGES = ("global_affine", "overlap", "cells", "local_affines", "ffd", "gate", "warp_map")


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
    """The targets: SENA wins over the affine, mean gain, mean PSNR / SSIM of the three warps."""
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
