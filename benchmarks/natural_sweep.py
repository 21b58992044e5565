"""Issue 13's figures of SENA on every shared pair for one set of Config changes: a sweep step.

    .venv/bin/python benchmarks/natural_sweep.py [--set border_blend=False ...] [--pairs cave spw_1] [--ba] --out sweep.json

Per pair (``../shared/data/pairs``, or the folders named): the stitch's natural figures
(``evaluation.figures.natural_figures``: duplicated / lost points, seam and border steps, bend,
continuity), its dense figures (``dense_figures``: misalignment at the seam and the borders, shown
twice / nowhere, tone fidelity) and its overlap PSNR, one line each on stdout and all of them in
``--out`` (JSON), so a setting is measured before and after on the same pairs without ``sena-warp
eval``'s baselines. ``--ba``: the inputs swapped (``b a``).
"""

from __future__ import annotations

import argparse
import ast
import json
import time
from pathlib import Path

from sena_warp.config import Config
from sena_warp.evaluation.figures import dense_figures, natural_figures, overlap_figures
from sena_warp.imageio import read_image
from sena_warp.kernels import runtime
from sena_warp.stitch import stitch_images

PAIRS_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "pairs"


def pair_images(folder: Path):
    """(a, b) BGR uint8 of a pair folder holding ``a.*`` and ``b.*``."""
    return tuple(read_image(next(folder.glob(f"{name}.*"))) for name in ("a", "b"))


def measure(folder: Path, cfg: Config, swapped: bool = False) -> dict:
    img_a, img_b = pair_images(folder)[::-1 if swapped else 1]
    t0 = time.perf_counter()
    pano = stitch_images(img_a, img_b, cfg)
    figures = natural_figures(img_a, img_b, pano, cfg) | dense_figures(img_a, img_b, pano, cfg)
    figures["psnr_db"] = float(overlap_figures(img_a, img_b, pano, cfg)[0])
    figures["seconds"] = round(time.perf_counter() - t0, 3)
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="Config changes")
    parser.add_argument("--pairs", nargs="*", default=None, help="pair names or folders (default: every shared pair)")
    parser.add_argument("--ba", action="store_true", help="the inputs swapped: b a")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    changes = {k: ast.literal_eval(v) for k, v in (item.split("=", 1) for item in args.set)}
    cfg = runtime.resolve_config(Config(**changes))
    runtime.prewarm(cfg.device)
    folders = ([Path(p) if Path(p).is_dir() else PAIRS_DIR / p for p in args.pairs] if args.pairs
               else sorted(p for p in PAIRS_DIR.iterdir() if p.is_dir()))
    results = {}
    for folder in folders:
        results[folder.name] = measure(folder, cfg, args.ba)
        print(folder.name, json.dumps({k: round(v, 3) if isinstance(v, float) else v
                                       for k, v in results[folder.name].items()}), flush=True)
    args.out.write_text(json.dumps({"changes": changes, "pairs": results}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
