"""sena-warp: parallax-tolerant two-camera stitching (SENA) for image pairs and paired videos.

From Python, files in and files out (``sena_warp.api``)::

    from sena_warp import Config, stitch_images, stitch_videos

    report = stitch_images("a.jpg", "b.jpg", "pano.png", Config(grid_x=8), crop=True)
    report = stitch_videos("left.mp4", "right.mp4", "pano.mp4", Config(video_crf=18), offset=0.2)

Pipeline (``docs/method.md``): features -> global affine -> overlap and cells -> local affines -> FFD field ->
gate -> source map -> adequate zone -> keypoint chain -> seam maps -> composite. Per-pixel work runs
in NVIDIA Warp kernels (``sena_warp.kernels``); paired video I/O lives in ``sena_warp.video``.
"""

from .config import Config
from .errors import StitchError

__version__ = "0.1.0"
__all__ = ["Config", "StitchError", "load_config", "stitch_images", "stitch_videos"]
_API = ("load_config", "stitch_images", "stitch_videos")  # imported when first used: they load Warp


def __getattr__(name: str):
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
