"""sena-warp: parallax-tolerant two-camera stitching (SENA) for image pairs and paired videos.

Pipeline (SENA.md): features -> global affine -> overlap and cells -> local affines -> FFD field ->
gate -> source map -> adequate zone -> keypoint chain -> seam maps -> composite. Per-pixel work runs
in NVIDIA Warp kernels (``sena_warp.kernels``); paired video I/O lives in ``sena_warp.video``.
"""

__version__ = "0.1.0"
