"""How alike the views that step 1's A_glob aligns look, on real pairs, unrelated pictures and noise
(``global_affine.check_views_alike`` and its floor ``min_overlap_correlation``).

Usage (from the repository root)::

    .venv/bin/python benchmarks/views_alike.py [--data ../shared/data] [--unrelated 30]

Prints, per input pair, the XFeat matches, the inliers of A_glob (``-``: RANSAC refuses the pair
already) and the overlap correlation ``overlap_correlation`` gives (``none``: too flat to say): every
pair of ``DATA/pairs``, ``--unrelated`` random picks of one pair's ``a`` with another pair's ``b``
(seeded), and two images of uniform noise; then the smallest correlation of the real pairs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from sena_warp.config import Config
from sena_warp.errors import MatchError
from sena_warp.features import match_images
from sena_warp.global_affine import fit_global_affine, overlap_correlation
from sena_warp.imageio import read_image

REPO = Path(__file__).resolve().parents[1]


def measure(img_a: np.ndarray, img_b: np.ndarray, cfg: Config) -> tuple[int, int | None, float | None]:
    """(matches, inliers or None when RANSAC refuses, overlap correlation or None)."""
    matches = match_images(img_a, img_b, cfg)
    try:
        glob = fit_global_affine(matches.pts_a, matches.pts_b, cfg)
    except MatchError:
        return len(matches), None, None
    return len(matches), glob.n_inliers, overlap_correlation(img_a, img_b, glob.affine_src_to_tgt)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--unrelated", type=int, default=30, help="random unrelated picks (default: %(default)s)")
    args = parser.parse_args()
    cfg = Config(device="cpu")
    folders = sorted(p for p in (args.data / "pairs").iterdir() if p.is_dir())
    images = {f.name: tuple(read_image(next(f.glob(f"{stem}.*"))) for stem in "ab") for f in folders}
    rng = np.random.default_rng(0)
    picks = [tuple(rng.choice(len(folders), 2, replace=False)) for _ in range(args.unrelated)]
    noise = tuple(np.random.default_rng(seed).integers(0, 256, (512, 512, 3), dtype=np.uint8) for seed in (1, 2))
    runs = [("pair", name, a, b) for name, (a, b) in images.items()]
    runs += [("unrelated", f"{folders[i].name} a / {folders[j].name} b", images[folders[i].name][0],
              images[folders[j].name][1]) for i, j in picks]
    runs.append(("noise", "uniform 512x512, seeds 1 and 2", *noise))
    real = []
    for kind, name, img_a, img_b in runs:
        n_matches, n_inliers, correlation = measure(img_a, img_b, cfg)
        shown = "none" if correlation is None else f"{correlation:.3f}"
        print(f"{kind:9s} {name:45s} matches {n_matches:5d} inliers {n_inliers if n_inliers else '-':>5} "
              f"correlation {shown if n_inliers else '-'}", flush=True)
        if kind == "pair" and correlation is not None:
            real.append(correlation)
    print(f"real pairs: smallest correlation {min(real):.3f}, floor min_overlap_correlation "
          f"{cfg.min_overlap_correlation}")


if __name__ == "__main__":
    main()
