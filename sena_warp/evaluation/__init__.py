"""Evaluation and benchmark tooling: it imports the pipeline, the pipeline never imports it.

- ``metrics``: the quality measures of ``docs/evaluation.md`` on arrays (overlap PSNR / SSIM, anchor
  residuals, transition-band difference, shape of a forward warp);
- ``figures``: those measures on a finished stitch, one definition each (``sena-warp eval``,
  ``image --report`` and the benchmarks all use them);
- ``baselines``: the warps SENA is compared with (global affine, SIFT homography, OpenCV's stitcher);
- ``alignment``: steps 1-6 against the baselines on one pair (``benchmarks/eval_warp.py``);
- ``evaluate``: ``sena-warp eval`` (with the contact ``sheets``);
- ``bench``: ``sena-warp bench``, frame rates of the video path;
- ``sync_bench``: accuracy of ``--offset auto`` on clips cut at known shifts (``benchmarks/bench_sync.py``).
"""
