"""Seam evaluation (steps 7-9, ``docs/evaluation.md``): every shared pair in both input orders.

For each pair folder (``a.*``, ``b.*``) and each input order (a, b) and (b, a), runs
``stitch_images`` with the default Config and measures, in the pipeline's working frame:

* zone: the adequate zone's canvas x-range [x0, x1) and whether it fell back to the whole overlap;
* anchors: number of keypoint-chain anchors (edge extensions included) and the median over them of
  the canvas distance between where the warped-source anchor lands after the step-9 reconstruction
  and its target anchor (``evaluation.metrics.anchor_residuals_px``);
* seam MAD: mean |src - tgt| (grey levels, averaged over B, G, R) between the seam-corrected warped
  source and the placed target over the pixels where both are valid and |x - seam_x(y)| <= T/2
  (T = ``cfg.transition_px``), i.e. where the step-9 alpha blends;
* feather MAD: the same mean between the step-6 warped source (no seam correction) and the placed
  target over every pixel where both are valid and the canvas x lies in the overlap's x-extent: a
  linear feather ramping across that extent blends there, so that is its transition band.

Prints a Markdown table and summary lines; optionally writes them to ``--markdown`` and a JPEG contact
sheet of the default-order panoramas to ``--sheet``. Not a test: no assertions.

    .venv/bin/python benchmarks/eval_seam.py [--data ../shared/data] [--markdown FILE] [--sheet FILE]
        [--orders ab ba] [--set transition_px=32 ...]

``--set NAME=VALUE`` (repeatable) changes a Config field, for the step 7-9 sweeps of docs/evaluation.md.
"""

from __future__ import annotations

import argparse
import math
import traceback
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.errors import StitchError
from sena_warp.evaluation.alignment import parse_setting
from sena_warp.evaluation.figures import seam_figures
from sena_warp.evaluation.sheets import thumbnail, tile
from sena_warp.imageio import read_image
from sena_warp.kernels.runtime import resolve_config
from sena_warp.stitch import Panorama, stitch_images

REPO = Path(__file__).resolve().parents[1]
ORDERS = ("ab", "ba")
TARGET_RESIDUAL_PX = 1.5  # target: median anchor residual at most this
TARGET_SEAM_WINS = 14  # target: seam MAD below feather MAD on at least this many pairs
THUMB_WH = (400, 260)  # contact-sheet thumbnail box (px)
SHEET_COLUMNS = 4
SHEET_JPEG_QUALITY = 82


@dataclass(frozen=True)
class SeamFigures:
    """Seam figures of one stitch (canvas pixels of the working frame, grey levels for MADs)."""

    zone_x0: float
    zone_x1: float
    fallback: bool
    n_anchors: int
    anchor_residual_px: float  # median over anchors; NaN if none could be located
    seam_mad: float
    feather_mad: float


@dataclass(frozen=True)
class Row:
    """One (pair, order) result: figures on success, else the error message."""

    pair: str
    order: str
    figures: SeamFigures | None
    error: str = ""
    is_bug: bool = False  # an exception outside the StitchError family


def figures_of(img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config) -> SeamFigures:
    """The zone and the seam figures (``evaluation.figures.seam_figures``) of a finished stitch of (img_a, img_b)."""
    zone, f = pano.maps.seam.zone, seam_figures(img_a, img_b, pano, cfg)
    return SeamFigures(zone.x0, zone.x1, zone.fallback, f["anchors"], f["anchor_residual_px"], f["seam_mad"],
                       f["feather_mad"])


def evaluate(pair: str, order: str, img_a: np.ndarray, img_b: np.ndarray, cfg: Config) -> tuple[Row, Panorama | None]:
    """Stitch one pair in one order; a StitchError is a recorded failure, any other exception a bug."""
    first, second = (img_a, img_b) if order == "ab" else (img_b, img_a)
    try:
        pano = stitch_images(first, second, cfg)
        return Row(pair, order, figures_of(first, second, pano, cfg)), pano
    except StitchError as err:
        return Row(pair, order, None, f"{type(err).__name__}: {err}"), None
    except Exception as err:  # noqa: BLE001 - a benchmark reports bugs instead of stopping at the first
        traceback.print_exc()
        return Row(pair, order, None, f"BUG {type(err).__name__}: {err}", is_bug=True), None


def table_line(row: Row) -> str:
    """One Markdown table line for ``row``."""
    if row.figures is None:
        return f"| {row.pair} | {row.order} | {'bug' if row.is_bug else 'failed'}: {row.error} | | | | | |"
    f = row.figures
    zone = f"{f.zone_x0:.0f}-{f.zone_x1:.0f}" + (" (fallback)" if f.fallback else "")
    win = "yes" if f.seam_mad < f.feather_mad else "no"
    return (f"| {row.pair} | {row.order} | ok | {zone} | {f.n_anchors} | {f.anchor_residual_px:.3f} | "
            f"{f.seam_mad:.2f} / {f.feather_mad:.2f} | {win} |")


def summary_lines(rows: list[Row]) -> list[str]:
    """Summary of the seam targets over all rows."""
    done = [r for r in rows if r.figures is not None]
    pairs = sorted({r.pair for r in rows})
    residuals = np.array([r.figures.anchor_residual_px for r in done])
    wins = {order: sum(r.figures.seam_mad < r.figures.feather_mad for r in done if r.order == order)
            for order in ORDERS if any(r.order == order for r in rows)}
    failures = [f"{r.pair} ({r.order}): {r.error}" for r in rows if r.figures is None]
    median_residual = float(np.nanmedian(residuals)) if residuals.size else math.nan
    return [
        f"- stitched: {len(done)} of {len(rows)} pair x order runs ({len(pairs)} pairs)",
        f"- median anchor residual over all runs: {median_residual:.3f} px (target <= {TARGET_RESIDUAL_PX})",
        "- seam MAD < feather MAD: " + "; ".join(f"{n} of {len(pairs)} pairs in order ({order[0]}, {order[1]})"
                                                  for order, n in wins.items())
        + f" (target >= {TARGET_SEAM_WINS} in order (a, b))",
        f"- median seam MAD {np.median([r.figures.seam_mad for r in done]):.2f}, median feather MAD "
        f"{np.median([r.figures.feather_mad for r in done]):.2f} (grey levels, all runs)",
        "- failures: " + ("; ".join(failures) if failures else "none"),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--markdown", type=Path, help="also write the table and summary to this file")
    parser.add_argument("--sheet", type=Path, help="write a JPEG contact sheet of the (a, b) panoramas here")
    parser.add_argument("--orders", nargs="+", choices=ORDERS, default=list(ORDERS), help="input orders to run")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a Config field")
    args = parser.parse_args()
    cfg = resolve_config(parse_setting(",".join(args.set) or "default", Config()))
    lines = ["| pair | order | result | zone x (canvas) | anchors | median anchor residual px | "
             "seam MAD / feather MAD | seam wins |", "|---|---|---|---|---:|---:|---:|---|"]
    print("\n".join(lines), flush=True)
    rows, cells = [], []
    for folder in sorted(p for p in (args.data / "pairs").iterdir() if p.is_dir()):
        img_a, img_b = read_image(next(folder.glob("a.*"))), read_image(next(folder.glob("b.*")))
        for order in args.orders:
            row, pano = evaluate(folder.name, order, img_a, img_b, cfg)
            rows.append(row)
            lines.append(table_line(row))
            print(lines[-1], flush=True)
            if order == "ab":
                cells.append(thumbnail(pano.image if pano else None, folder.name + ("" if pano else " FAILED"), THUMB_WH))
    summary = summary_lines(rows)
    print("\n" + "\n".join(summary))
    if args.markdown:
        args.markdown.write_text("\n".join(lines) + "\n\n" + "\n".join(summary) + "\n")
    if args.sheet:
        cv2.imwrite(str(args.sheet), tile(cells, SHEET_COLUMNS), [cv2.IMWRITE_JPEG_QUALITY, SHEET_JPEG_QUALITY])


if __name__ == "__main__":
    main()
