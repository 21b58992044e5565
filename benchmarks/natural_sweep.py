"""The natural-appearance figures of SENA on every shared pair for one set of Config changes: a sweep step.

    .venv/bin/python benchmarks/natural_sweep.py [--set border_blend=False ...] [--pairs cave spw_1] [--ba]
        [--save DIR] [--order [--no-figures]] --out sweep.json

Per pair (``../shared/data/pairs``, or the folders named): the stitch's natural figures
(``evaluation.figures.natural_figures``: duplicated / lost points, seam and border steps, bend,
continuity), its dense figures (``dense_figures``: misalignment at the seam and the borders, shown
twice / nowhere, tone fidelity) and its overlap PSNR, one line each on stdout and all of them in
``--out`` (JSON), so a setting is measured before and after on the same pairs without ``sena-warp
eval``'s baselines. ``--ba``: the inputs swapped (``b a``); ``--order``: both orders stitched and
their panoramas compared (``order_diff_grey``), with ``--no-figures`` that check alone.

``--save DIR``: each panorama as ``DIR/PAIR.png`` and what to look at at 100 %: ``DIR/PAIR_seam.png``,
the panorama around the seam, ``SEAM_SEGMENT_ROWS`` rows at a time, each as it is and with the seam
drawn in red; ``DIR/PAIR_switches.png``, crops around the places where the panorama switches views
beyond the seam (a view's border), one every ``CROP_PX`` px along them.
"""

from __future__ import annotations

import argparse
import ast
import json
import time
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.evaluation.evaluate import order_difference
from sena_warp.evaluation.figures import dense_figures, natural_figures, overlap_figures, panorama_views
from sena_warp.imageio import read_image, write_image
from sena_warp.kernels import runtime
from sena_warp.rig import image_to_working
from sena_warp.stitch import Panorama, stitch_images
from sena_warp.switch_align import shown_labels, switch_pixels, view_weights

PAIRS_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "pairs"
SEAM_HALF_PX = 110  # seam crops: this many px beyond the seam each side
SEAM_SEGMENT_ROWS = 700  # and this many rows a crop
CROP_PX = 300  # switch crops: this side, at least this far apart
BACKGROUND = 40  # grey behind what the panorama does not cover


def pair_images(folder: Path):
    """(a, b) BGR uint8 of a pair folder holding ``a.*`` and ``b.*``."""
    return tuple(read_image(next(folder.glob(f"{name}.*"))) for name in ("a", "b"))


def seam_strips(pano_canvas: np.ndarray, seam_x_canvas: np.ndarray, seam: np.ndarray) -> np.ndarray | None:
    """(SEAM_SEGMENT_ROWS, ..., 3) uint8: the working-canvas panorama around the seam, segment by segment
    of SEAM_SEGMENT_ROWS rows side by side, each twice: as it is and with the seam drawn in red, from
    SEAM_HALF_PX left of the seam's leftmost x to SEAM_HALF_PX right of its rightmost; None: no seam."""
    rows = np.nonzero(seam.any(axis=1))[0]
    if not len(rows):
        return None
    height, width = seam.shape
    parts = []
    for start in range(rows.min(), rows.max() + 1, SEAM_SEGMENT_ROWS):
        stop = min(height, start + SEAM_SEGMENT_ROWS)
        xs = seam_x_canvas[start:stop]
        xs = xs[np.isfinite(xs)]
        if not len(xs):
            continue
        left, right = max(0, int(xs.min()) - SEAM_HALF_PX), min(width, int(np.ceil(xs.max())) + SEAM_HALF_PX + 1)
        crop = np.full((SEAM_SEGMENT_ROWS, right - left, 3), BACKGROUND, np.uint8)
        crop[:stop - start] = pano_canvas[start:stop, left:right]
        marked = crop.copy()
        for y in range(stop - start):
            x = seam_x_canvas[start + y]
            if np.isfinite(x) and left <= x < right:
                marked[y, int(x) - left] = (0, 0, 255)
        cv2.putText(crop, f"y{start} x{left}", (8, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 255, 255), 1)
        parts += [crop, np.full((SEAM_SEGMENT_ROWS, 2, 3), 255, np.uint8), marked,
                  np.full((SEAM_SEGMENT_ROWS, 8, 3), 255, np.uint8)]
    return np.hstack(parts) if parts else None


def switch_crops(pano_canvas: np.ndarray, border: np.ndarray, columns: int = 5) -> np.ndarray | None:
    """Crops of CROP_PX x CROP_PX of the working-canvas panorama around the border switch pixels
    (row-major, one per CROP_PX), tiled ``columns`` across; None: no such switch."""
    height, width = border.shape
    taken, crops = [], []
    for y, x in zip(*np.nonzero(border)):
        if any(abs(y - y0) < CROP_PX and abs(x - x0) < CROP_PX for y0, x0 in taken):
            continue
        taken.append((y, x))
        top = int(np.clip(y - CROP_PX // 2, 0, max(0, height - CROP_PX)))
        left = int(np.clip(x - CROP_PX // 2, 0, max(0, width - CROP_PX)))
        crop = np.full((CROP_PX + 4, CROP_PX + 4, 3), 255, np.uint8)
        crop[:CROP_PX, :CROP_PX] = BACKGROUND
        part = pano_canvas[top:top + CROP_PX, left:left + CROP_PX]
        crop[:part.shape[0], :part.shape[1]] = part
        cv2.putText(crop, f"y{y} x{x}", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 255, 255), 1)
        crops.append(crop)
    if not crops:
        return None
    columns = min(columns, len(crops))
    crops += [np.full_like(crops[0], 255)] * (-len(crops) % columns)
    return np.vstack([np.hstack(crops[i:i + columns]) for i in range(0, len(crops), columns)])


def save_pictures(folder: Path, img_a: np.ndarray, img_b: np.ndarray, pano: Panorama, cfg: Config, save: Path) -> None:
    """The panorama as ``save/PAIR.png``, its seam strips and switch crops (module docstring) beside it."""
    write_image(save / f"{folder.name}.png", pano.image)
    maps = pano.maps
    img_src, img_tgt = (image_to_working(img, maps.rig) for img in maps.rig.pick(img_a, img_b))
    views = panorama_views(img_src, img_tgt, pano, cfg)
    weights = view_weights(maps.seam.maps.alpha_canvas, views.valid_src, views.valid_tgt)
    seam, border = switch_pixels(shown_labels(*weights), views.valid_src, views.valid_tgt)
    pano_canvas = image_to_working(pano.image, maps.rig)
    if pano_canvas.shape[2] == 4:
        alpha = pano_canvas[:, :, 3:] / 255.0
        pano_canvas = (pano_canvas[:, :, :3] * alpha + BACKGROUND * (1 - alpha)).astype(np.uint8)
    for name, picture in (("seam", seam_strips(pano_canvas, maps.seam.maps.seam_x_canvas, seam)),
                          ("switches", switch_crops(pano_canvas, border))):
        if picture is not None:
            write_image(save / f"{folder.name}_{name}.png", picture)


def measure(folder: Path, cfg: Config, swapped: bool = False, save: Path | None = None, figures: bool = True,
            order: bool = False) -> dict:
    """A pair's figures (``figures``), and with ``order`` the largest grey-level difference between its
    panorama and the one of the inputs swapped (``order_diff_grey``: 0 when the order does not matter)."""
    img_a, img_b = pair_images(folder)[::-1 if swapped else 1]
    t0 = time.perf_counter()
    pano = stitch_images(img_a, img_b, cfg)
    result = {"stitch_seconds": round(time.perf_counter() - t0, 3)}
    if save is not None:
        save_pictures(folder, img_a, img_b, pano, cfg, save)
    if figures:
        result |= natural_figures(img_a, img_b, pano, cfg) | dense_figures(img_a, img_b, pano, cfg)
        result["psnr_db"] = float(overlap_figures(img_a, img_b, pano, cfg)[0])
    if order:
        result["order_diff_grey"] = order_difference(pano.image, stitch_images(img_b, img_a, cfg).image)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="Config changes")
    parser.add_argument("--pairs", nargs="*", default=None, help="pair names or folders (default: every shared pair)")
    parser.add_argument("--ba", action="store_true", help="the inputs swapped: b a")
    parser.add_argument("--save", type=Path, metavar="DIR", help="write each panorama here as PAIR.png")
    parser.add_argument("--order", action="store_true", help="also stitch the inputs swapped and compare")
    parser.add_argument("--no-figures", action="store_true", help="no figures (with --order: that check alone)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    changes = {k: ast.literal_eval(v) for k, v in (item.split("=", 1) for item in args.set)}
    cfg = runtime.resolve_config(Config(**changes))
    runtime.prewarm(cfg.device)
    folders = ([Path(p) if Path(p).is_dir() else PAIRS_DIR / p for p in args.pairs] if args.pairs
               else sorted(p for p in PAIRS_DIR.iterdir() if p.is_dir()))
    if args.save is not None:
        args.save.mkdir(parents=True, exist_ok=True)
    results = {}
    for folder in folders:
        results[folder.name] = measure(folder, cfg, args.ba, args.save, not args.no_figures, args.order)
        print(folder.name, json.dumps({k: round(v, 3) if isinstance(v, float) else v
                                       for k, v in results[folder.name].items()}), flush=True)
    args.out.write_text(json.dumps({"changes": changes, "pairs": results}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
