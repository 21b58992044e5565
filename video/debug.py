"""``video --debug DIR``: the first estimate's stage pictures, as ``image --debug`` draws them.

The pictures are of the frame pair the first estimate was made on. Frames larger than
``video_estimate_max_side`` are estimated made that small and the maps scaled up (``working.py``);
their pictures are drawn from that estimate made again on the smaller pair with its matches (the
same stages, each result at one resolution).
"""

from __future__ import annotations

import os

from ..config import Config
from ..debug import dump_stages
from ..stitch import Panorama, StitchMaps, estimate_maps, panorama_image
from .reader import YuvFrame
from .working import shrunk_pair, working_scale


def dump_first_estimate(folder: str | os.PathLike, maps: StitchMaps, frame_l: YuvFrame, frame_r: YuvFrame,
                        cfg: Config) -> list:
    """Write the stage pictures of ``maps``, estimated on ``frame_l`` and ``frame_r``, into ``folder`` (an
    existing folder: an output's temporary); the paths written. ``cfg.device`` resolved."""
    bgr = frame_l.to_bgr(), frame_r.to_bgr()
    scale = working_scale((frame_l.y.shape, frame_r.y.shape), cfg.video_estimate_max_side)
    if scale != 1.0:
        bgr, _ = shrunk_pair(bgr, scale)
        maps = estimate_maps(*bgr, cfg, maps.rig.target, maps.matches)  # its matches are of that pair
    return dump_stages(folder, *bgr, Panorama(panorama_image(*bgr, maps, cfg), maps, maps.seconds), cfg)
