"""Feature benchmark (docs/method.md step 0): XFeat (onnxruntime) vs SIFT over every shared pair.

Prints a Markdown table: pair, resolution, matches per detector, extraction time per image
(``detect``: XFeat = resize + ONNX backbone + numpy post-processing; SIFT = OpenCV at native
resolution; median of --runs runs, averaged over the two images), then the graf_gt ground-truth
figures (matches within 3 px of the homography's prediction). Not a test: no assertions.

    .venv/bin/python benchmarks/bench_features.py [--pairs ../shared/data/pairs] [--runs 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.features import detect, match_images
from sena_warp.imageio import read_image

REPO = Path(__file__).resolve().parents[1]
DETECTORS = ("xfeat", "sift")
GT_PAIR = "graf_gt"
GT_TOLERANCE_PX = 3.0


def median_detect_ms(img: np.ndarray, cfg: Config, runs: int) -> float:
    """Median wall time of ``detect(img, cfg)`` in milliseconds."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        detect(img, cfg)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=Path, default=REPO.parent / "shared" / "data" / "pairs")
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    configs = {name: Config(features=name) for name in DETECTORS}
    detect(np.zeros((64, 64, 3), np.uint8), configs["xfeat"])  # load the ONNX session outside the timing

    print("| pair | resolution (a) | XFeat matches | SIFT matches | XFeat ms/image | SIFT ms/image |")
    print("|---|---|---:|---:|---:|---:|")
    gt_rows = []
    for folder in sorted(p for p in args.pairs.iterdir() if p.is_dir()):
        img_a, img_b = read_image(next(folder.glob("a.*"))), read_image(next(folder.glob("b.*")))
        matches = {name: match_images(img_a, img_b, cfg) for name, cfg in configs.items()}
        ms = {name: (median_detect_ms(img_a, cfg, args.runs) + median_detect_ms(img_b, cfg, args.runs)) / 2
              for name, cfg in configs.items()}
        print(f"| {folder.name} | {img_a.shape[1]}x{img_a.shape[0]} | {len(matches['xfeat'])} | "
              f"{len(matches['sift'])} | {ms['xfeat']:.0f} | {ms['sift']:.0f} |", flush=True)
        if folder.name == GT_PAIR:
            homography = np.loadtxt(folder / "H_a_to_b.txt")
            for name, m in matches.items():
                pts_b_expected = cv2.perspectiveTransform(m.pts_a[None], homography)[0]
                correct = int(np.sum(np.linalg.norm(pts_b_expected - m.pts_b, axis=1) <= GT_TOLERANCE_PX))
                gt_rows.append(f"| {name} | {m.n_keypoints_a}/{m.n_keypoints_b} | {len(m)} | {correct} | "
                               f"{correct / max(len(m), 1):.1%} |")
    if gt_rows:
        print(f"\n{GT_PAIR} against the ground-truth homography (within {GT_TOLERANCE_PX:g} px):\n")
        print(f"| detector | keypoints a/b | matches | within {GT_TOLERANCE_PX:g} px | fraction |")
        print("|---|---:|---:|---:|---:|")
        print("\n".join(gt_rows))


if __name__ == "__main__":
    main()
