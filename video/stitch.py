"""Stitching two videos with SENA maps: estimate once (or now and then for a moving rig), composite planes.

``stitch_videos`` is the ``sena-warp video`` job: the best of the first frame pairs gives the maps and
fixes the output canvas (``estimate.py``); every frame pair is then composited in YUV 4:2:0 with
those maps (``maps.py``) by the loop in ``loop.py``. With a moving rig the maps are re-estimated
every ``cfg.video_reestimate_s`` seconds on the main thread between frames (simple, deterministic);
implausible estimates are rejected, accepted ones are blended in over ``cfg.video_blend_frames``
frames so the warp and the seam glide rather than jump. Jitter figures measure what remains.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

import numpy as np

from ..composite import Compositor
from ..config import CHOICES, Config
from ..errors import InputError, StitchError
from ..outputs import OutputPlan
from ..report import run_info
from ..stitch import StitchMaps
from sena_warp.kernels.runtime import prewarm, resolve_config
from .estimate import Attempt, best_first_estimate, estimate_pair, rejection_reason
from .loop import VideoOptions, run_video
from .maps import BLACK_UV, BLACK_Y, PlaneMaps, lerp_maps, map_change_px, plane_maps, seam_change_px, target_offset
from .reader import YuvFrame
from .writer import even_size

RIGS = CHOICES["video_rig"]
JITTER_PERCENTILE = 99.0  # "largest map change" = this percentile of |delta M_s| per frame (robust to edge pixels)
LUMA_FILL = (BLACK_Y,)  # output Y where no input is sampled
CHROMA_FILL = (BLACK_UV, BLACK_UV)  # output U, V likewise


@dataclass(frozen=True)
class PlanePass:
    """One of the two compositing passes of :meth:`SenaFrameCompositor.composite_yuv`, on the output grid.

    ``map_src`` / ``map_tgt``: (Hc, Wc, 2) float32 (x, y) sample positions in the source / target
    plane, NaN where nothing may be sampled; ``alpha``: (Hc, Wc) float32 source weight; ``fill``: the
    output value per channel where neither plane is sampled. The luma pass samples the Y planes, the
    chroma pass the U and V planes stacked as two channels (``np.dstack((u, v))``), at half resolution.
    """

    map_src: np.ndarray
    map_tgt: np.ndarray
    alpha: np.ndarray
    fill: tuple[int, ...]


class SenaFrameCompositor:
    """The loop's frame compositor for a SENA stitch (see ``loop.FrameCompositor``).

    Public surface: :meth:`from_videos` (estimate and build), ``output_size`` (width, height),
    :meth:`update` and :meth:`composite_yuv` (what the loop calls), :meth:`source_target` and
    :meth:`passes` (the roles and the maps a frame is composited with, e.g. for a reference
    implementation), :meth:`report`. Inside: one :class:`~sena_warp.composite.Compositor` for the Y
    plane and one for the U/V planes (stacked as two channels), both allocated once; new maps are
    uploaded into them in place. ``update`` re-estimates and blends for a moving rig and records how
    much the maps moved for that frame.
    """

    def __init__(self, first: StitchMaps, first_attempts: list[Attempt], first_pair: int, cfg: Config):
        """From the first estimate ``first`` (made on pair ``first_pair``; ``first_attempts``: every
        pair tried); ``cfg.device`` resolved."""
        self._cfg = cfg
        self._rig = first.rig
        self._reestimate_s = cfg.video_reestimate_s if cfg.video_rig == "moving" else None
        width, height = even_size(first.alpha_input.shape[1], first.alpha_input.shape[0])  # yuv420p: even sides
        shape = (height, width)
        self._offset_tgt = target_offset(first.map_tgt_input)
        self._maps = plane_maps(first, shape, self._offset_tgt)
        self.output_size = (shape[1], shape[0])
        self._luma = Compositor(self._maps.map_src_luma, self._maps.map_tgt_luma, self._maps.alpha_luma, cfg)
        self._chroma = Compositor(self._maps.map_src_chroma, self._maps.map_tgt_chroma, self._maps.alpha_chroma, cfg)
        self._first_inliers = self._maps.inliers
        self._first_info = {"tried": [a.as_dict() for a in first_attempts], "chosen_pair": first_pair,
                            "inliers": self._first_inliers, "seconds": round(sum(first.seconds.values()), 4)}
        self._blend: tuple[PlaneMaps, PlaneMaps, int] | None = None  # (start, goal, frames done)
        self._last_estimate_s: float | None = None
        self._reestimations = {"attempted": 0, "accepted": 0, "rejected": 0, "rejections": []}
        self._seam_jitter_px: list[float] = []
        self._map_change_px: list[float] = []
        self._seconds = {"reestimate": 0.0, "maps_upload": 0.0}

    @classmethod
    def from_videos(cls, left: str | os.PathLike, right: str | os.PathLike, offset_s: float, cfg: Config,
                    reference: str) -> "SenaFrameCompositor":
        """The compositor of two videos: maps from the best of their first frame pairs
        (``estimate.best_first_estimate``); ``offset_s`` as ``VideoOptions.offset_s``, ``reference`` as
        ``stitch_videos``; ``cfg.device`` resolved."""
        maps, pair, attempts = best_first_estimate(left, right, offset_s, cfg, reference)
        return cls(maps, attempts, pair, cfg)

    def source_target(self, item_left, item_right) -> tuple:
        """A (left, right) pair of per-input things (frames, planes, shapes) as (source, target)."""
        return self._rig.pick(item_left, item_right)

    def passes(self) -> tuple[PlanePass, PlanePass]:
        """(luma, chroma): the maps the next :meth:`composite_yuv` composites with."""
        maps = self._maps
        return (PlanePass(maps.map_src_luma, maps.map_tgt_luma, maps.alpha_luma, LUMA_FILL),
                PlanePass(maps.map_src_chroma, maps.map_tgt_chroma, maps.alpha_chroma, CHROMA_FILL))

    def update(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        """Before compositing a pair: maybe re-estimate, advance a blend, and record the maps' change."""
        before = self._maps
        if self._blend is None and self._due(float(frame_l.time_s)):
            self._reestimate(frame_l, frame_r)
        if self._blend is not None:
            self._advance_blend()
        changed = self._maps is not before
        self._seam_jitter_px.append(seam_change_px(before, self._maps) if changed else 0.0)
        self._map_change_px.append(
            map_change_px(before, self._maps, self.source_target(frame_l, frame_r)[0].y.shape, JITTER_PERCENTILE)
            if changed else 0.0)

    def _due(self, time_s: float) -> bool:
        if self._reestimate_s is None:
            return False
        if self._last_estimate_s is None:  # the first estimate was made on the video's first pairs
            self._last_estimate_s = time_s
        return time_s - self._last_estimate_s >= self._reestimate_s

    def _reestimate(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        t0 = time.perf_counter()
        self._last_estimate_s = float(frame_l.time_s)
        self._reestimations["attempted"] += 1
        shape_src, shape_tgt = (f.y.shape for f in self.source_target(frame_l, frame_r))
        try:
            # Same roles as the first estimate: the target stays the unwarped view on the fixed canvas.
            estimate = estimate_pair(frame_l, frame_r, self._cfg, reference=self._rig.target)
            reason = None if estimate.rig.vertical == self._rig.vertical else "rig orientation changed"
            candidate = plane_maps(estimate, self._maps.shape, self._offset_tgt)
            reason = reason or rejection_reason(candidate, self._maps, self._first_inliers, shape_src, shape_tgt,
                                                self._cfg)
        except StitchError as exc:
            reason = str(exc)
        if reason is None:
            self._reestimations["accepted"] += 1
            self._blend = (self._maps, candidate, 0)
        else:
            self._reestimations["rejected"] += 1
            self._reestimations["rejections"].append({"time_s": round(self._last_estimate_s, 4), "reason": reason})
        self._seconds["reestimate"] += time.perf_counter() - t0

    def _advance_blend(self) -> None:
        start, goal, done = self._blend
        done += 1
        frames = max(self._cfg.video_blend_frames, 1)
        self._maps = lerp_maps(start, goal, done / frames)
        self._blend = None if done >= frames else (start, goal, done)
        t0 = time.perf_counter()
        # The target maps never change on the fixed canvas; only the source map and alpha move.
        self._luma.set_maps(map_src_canvas=self._maps.map_src_luma, alpha_canvas=self._maps.alpha_luma)
        self._chroma.set_maps(map_src_canvas=self._maps.map_src_chroma, alpha_canvas=self._maps.alpha_chroma)
        self._seconds["maps_upload"] += time.perf_counter() - t0

    def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Output (y, u, v) planes of ``output_size``; uncovered pixels are black (Y 16, U = V = 128)."""
        y_src, y_tgt = self.source_target(y_l, y_r)
        uv_src, uv_tgt = self.source_target(np.dstack((u_l, v_l)), np.dstack((u_r, v_r)))
        y, _ = self._luma.apply(y_src, y_tgt, fill=LUMA_FILL)
        uv, _ = self._chroma.apply(uv_src, uv_tgt, fill=CHROMA_FILL)
        return y, uv[:, :, 0], uv[:, :, 1]

    def report(self) -> dict:
        """Estimation, re-estimation and jitter figures (px) of the run, JSON-ready."""
        seam = np.asarray(self._seam_jitter_px or [0.0])
        return {
            "rig": {"mode": self._cfg.video_rig, "source": "left" if self._rig.source == "a" else "right",
                    "vertical": self._rig.vertical, "reestimate_s": self._reestimate_s},
            "first_estimate": self._first_info,
            "canvas": {"width": self.output_size[0], "height": self.output_size[1],
                       "offset_tgt": [float(v) for v in self._offset_tgt],
                       "seam_x_working": [None if np.isnan(x) else round(float(x), 2)
                                          for x in self._maps.seam_x_working]},
            "reestimations": self._reestimations,
            "jitter": {
                "seam_jitter_px_mean": round(float(seam.mean()), 4),
                "seam_jitter_px_max": round(float(seam.max()), 4),
                "map_change_p99_px_max": round(max(self._map_change_px, default=0.0), 4),
                "frames": len(self._seam_jitter_px),
            },
            "timing_s": {name: round(seconds, 4) for name, seconds in self._seconds.items()},
        }


def check_rig_settings(cfg: Config) -> None:
    """InputError for a rig mode or re-estimation period that cannot be used (before any work)."""
    if cfg.video_rig not in RIGS:
        raise InputError(f"rig {cfg.video_rig!r} unknown; use one of {', '.join(RIGS)}")
    if not (0 < cfg.video_reestimate_s < math.inf):
        raise InputError(f"re-estimation period {cfg.video_reestimate_s} s must be a positive number of seconds "
                         f"(--reestimate)")


def stitch_videos(left: str | os.PathLike, right: str | os.PathLike, output: str | os.PathLike, cfg: Config,
                  options: VideoOptions, reference: str = "auto", plan: OutputPlan | None = None) -> dict:
    """Stitch two videos into ``output`` with SENA maps; return the run's report.

    ``cfg.video_rig`` "static" estimates once; "moving" re-estimates every ``cfg.video_reestimate_s``.
    ``reference``: input kept unwarped ("a" = left, "b" = right, "auto" = the right/bottom view).
    ``plan``: commit the video with that plan's other outputs (see ``sena_warp.outputs``).
    The report is :func:`loop.run_video`'s plus ``run`` (tool, device, settings) and ``stitch`` (see
    :meth:`SenaFrameCompositor.report`), its times in one ``timing_s`` block (``docs/report.md``).
    The Warp device of ``cfg`` is resolved here, once for the whole video.
    """
    check_rig_settings(cfg)
    cfg = resolve_config(cfg)
    t0 = time.perf_counter()
    prewarm(cfg.device)  # before the run's clock: a first run's kernel compile is not frame time
    load_kernels_s = time.perf_counter() - t0
    built: list[SenaFrameCompositor] = []

    def factory(first_l: YuvFrame, first_r: YuvFrame) -> SenaFrameCompositor:
        built.append(SenaFrameCompositor.from_videos(left, right, options.offset_s, cfg, reference))
        return built[0]

    report = run_video(left, right, output, factory, options, plan)
    stitch = built[0].report()
    report["timing_s"] = {"load_kernels": round(load_kernels_s, 4), **report["timing_s"], **stitch.pop("timing_s")}
    return {"run": run_info(cfg), **report, "stitch": stitch}
