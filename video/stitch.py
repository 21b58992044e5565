"""Stitching two videos with SENA maps: estimate once (or now and then for a moving rig), composite planes.

``stitch_videos`` is the ``sena-warp video`` job: the best of the first frame pairs gives the maps and
fixes the output canvas (``estimate.py``); every frame pair is then composited in YUV 4:2:0 with
those maps (``maps.py``) by the loop in ``loop.py``. A static rig's maps move with a camera that
drifts (``drift.py``: each view's shift since the estimate). With a moving rig the maps are
re-estimated every ``cfg.video_reestimate_s`` seconds on a worker thread (on the loop's with
``video_estimate_workers`` 0: deterministic); implausible estimates are rejected; the maps move
``cfg.video_warp_follow`` of the way to an accepted one (an exponential average over the estimates,
causal), blended in over ``cfg.video_blend_frames`` frames at least, so the warp and the seam glide
rather than jump. Jitter figures measure what remains.

An optional *observer* (``stitch_videos(observer=...)``) is called once per composited frame with a
:class:`CompositedFrame`: what went in, what came out and what it was composited with. The pipeline
only calls it; what it measures lives elsewhere (``sena_warp.evaluation.video_figures``).
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..composite import Compositor
from ..config import CHOICES, Config, require_config
from ..crop import largest_inner_rectangle
from ..errors import InputError, StitchError, VideoError
from ..outputs import OutputPlan
from ..report import run_info
from ..stitch import StitchMaps
from sena_warp.kernels.runtime import prewarm, resolve_config
from .debug import dump_first_estimate
from .drift import DriftWatch, overlap_boxes
from .estimate import (Attempt, best_first_estimate, estimate_pair, paired_frames, rejection_reason, spaced_pairs,
                       spaced_span)
from .exposure import ExposureTracker
from .frame_seam import FrameSeam, band_half_width, cell_px
from .loop import VideoOptions, run_still, run_video
from .maps import (BLACK_UV, BLACK_Y, WHITE_Y, MapsBlend, PlaneMaps, canvas_scale, chroma_lines, drifted_maps,
                   lerp_maps, map_change_px, output_shape, plane_maps, sampled_mask, scaled_plane_maps,
                   seam_change_px, seam_on_canvas_lines, seam_per_target_line, target_offset)
from .reader import YuvFrame, probe_video
from .writer import even_size

RIGS = CHOICES["video_rig"]
STILL_SUFFIXES = (".png", ".jpg", ".jpeg")  # an output of these types is the one stitched frame at the span's start
JITTER_PERCENTILE = 99.0  # "largest map change" = this percentile of |delta M_s| per frame (robust to edge pixels)
JITTER_STRIDE = 4  # ... over every this-th canvas row and column (a 1080p frame's full maps took 0.1 s)
PLANE_CHANNELS = (1, 2)  # the frame kernels' channel counts: the Y pass, and U and V stacked
LUMA_FILL = (BLACK_Y,)  # output Y where no input is sampled
CHROMA_FILL = (BLACK_UV, BLACK_UV)  # output U, V likewise


@dataclass(frozen=True)
class PlanePass:
    """One of the two compositing passes of :meth:`SenaFrameCompositor.composite_yuv`, on the output grid,
    as the last frame was composited.

    ``map_src`` / ``map_tgt``: (Hc, Wc, 2) float32 (x, y) sample positions in the source / target
    plane, NaN where nothing may be sampled; ``alpha``: (Hc, Wc) float32 source weight where both are
    sampled; ``gains``: (gain_src, bias_src, gain_tgt, bias_tgt), each (C,), with ``knee`` (knee, white)
    grey levels of their highlight knee or None (``gains.tone_curve``); ``offsets_src`` /
    ``offsets_tgt``: (Hc, Wc, C) float32 the seam blend's offsets per pixel (along the seam and the borders); ``fill``: the output value
    per channel where neither plane is sampled. The luma pass samples the Y planes, the chroma pass
    the U and V planes stacked as two channels (``np.dstack((u, v))``), at half resolution.
    """

    map_src: np.ndarray
    map_tgt: np.ndarray
    alpha: np.ndarray
    gains: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    knee: tuple[float, float] | None
    offsets_src: np.ndarray
    offsets_tgt: np.ndarray
    fill: tuple[int, ...]

    @staticmethod
    def of(compositor: Compositor, map_src: np.ndarray, map_tgt: np.ndarray, fill: tuple[int, ...]) -> "PlanePass":
        """The pass ``compositor`` makes with its current seam, gains and offsets."""
        channels = len(fill)
        alpha, lf = compositor.seam_weights()
        per_line_src, per_line_tgt = compositor.offsets(channels)
        rows = compositor.layout.lines_are_rows

        def spread(per_line: np.ndarray) -> np.ndarray:
            lines = per_line[:, None, :] if rows else per_line[None, :, :]
            return (lf[:, :, None] * lines).astype(np.float32)

        border_src, border_tgt = compositor.border_offsets(channels)
        return PlanePass(map_src, map_tgt, alpha, compositor.gains(channels), compositor.knee(),
                         spread(per_line_src) + border_src, spread(per_line_tgt) + border_tgt, fill)


@dataclass(frozen=True)
class CompositedFrame:
    """One composited frame as an observer sees it: read-only views, valid during the call only.

    ``index``: output frame number from 0; ``time_s``: the left frame's time (None when
    ``composite_yuv`` was called without ``update``); ``source``: which input is the source, "left"
    or "right" (the other is the target). ``planes_src`` / ``planes_tgt``: the (y, u, v)
    uint8 planes of the source / target input as decoded (``plane[row, col]``); ``planes_out``: the
    output's (y, u, v) on the canvas. ``maps``: the :class:`~sena_warp.video.maps.PlaneMaps` composited
    with (the same object for as long as the maps do not change; input-frame (x, y) sample positions
    per canvas pixel). ``seam_home``: (L,) float32 the estimate's seam, the centre of the band in
    which the frame's seam may move, at most ``seam_reach_px`` from it; ``seam``: (L,) float32 the
    frame's seam as composited; a line is
    a canvas row when ``lines_are_rows`` (positions are x; the source lies at smaller x), else a
    column (positions are y). ``gains_luma``: (gain_src, bias_src, gain_tgt, bias_tgt), each (1,)
    float64, the Y pass's affine gains (``out = gain * Y + bias`` up to the knee), ``knee_luma`` their
    highlight knee (knee, white) grey levels (``gains.tone_curve``); ``offsets_luma``: ((L, 1), (L, 1))
    float64 the seam blend's per-line offsets of each side, grey levels at the seam. ``weights()``:
    (alpha, lf) (Hc, Wc) float32 of the Y pass (``Compositor.seam_weights``: one kernel launch over
    the canvas, so call it only where needed).
    """

    index: int
    time_s: float | None
    source: str
    planes_src: tuple[np.ndarray, np.ndarray, np.ndarray]
    planes_tgt: tuple[np.ndarray, np.ndarray, np.ndarray]
    planes_out: tuple[np.ndarray, np.ndarray, np.ndarray]
    maps: PlaneMaps
    seam_home: np.ndarray
    seam_reach_px: float
    seam: np.ndarray
    lines_are_rows: bool
    gains_luma: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    knee_luma: tuple[float, float] | None
    offsets_luma: tuple[np.ndarray, np.ndarray]
    weights: Callable[[], tuple[np.ndarray, np.ndarray]]


FirstEstimateHook = Callable[[StitchMaps, YuvFrame, YuvFrame], None]
"""Shown the first estimate and the (left, right) frames it was made on (``video --debug``)."""

FrameObserver = Callable[[CompositedFrame], None]
"""Called once per composited frame, on the loop's thread, before the frame is encoded; its time is
reported as the stitch's ``timing_s.observer``."""


class SenaFrameCompositor:
    """The loop's frame compositor for a SENA stitch (see ``loop.FrameCompositor``).

    Public surface: :meth:`from_pairs` and :meth:`from_videos` (estimate and build), ``output_size``
    (width, height), :meth:`update` and :meth:`composite_yuv` (what the loop calls), :meth:`source_target` and
    :meth:`passes` (what a frame is composited with, for the bench's reference implementation),
    :meth:`report`; ``observer`` (a :data:`FrameObserver` or None) sees every composited frame. Inside: one :class:`~sena_warp.composite.Compositor` for the Y plane and one for
    the U/V planes (stacked as two channels), both allocated once; every frame the seam is cut anew
    in its band (``frame_seam``) and the gains follow the cameras' exposure (``exposure``). A static
    rig's maps follow a drifting camera (``_drifted``). A moving rig's re-estimates run on a worker
    thread while frames keep flowing on the current maps; an accepted one is blended in slowly enough
    that the seam moves at most ``video_seam_speed_px`` per frame.
    """

    def __init__(self, first: StitchMaps, first_attempts: list[Attempt], first_pair: int, fps: float,
                 frame_shapes: tuple[tuple[int, int], tuple[int, int]], cfg: Config,
                 observer: FrameObserver | None = None):
        """From the first estimate ``first`` (made on pair ``first_pair``; ``first_attempts``: every
        pair tried) for inputs at ``fps`` frames per second whose (rows, cols) are ``frame_shapes``
        (left, right); ``cfg.device`` resolved. With ``cfg.video_crop`` the fixed canvas is the largest
        rectangle the first estimate covers. ``observer``: called with every composited frame."""
        self._cfg = cfg
        self.observer = observer
        self._frames = 0
        self._time_s: float | None = None
        self._rig = first.rig
        self._reestimate_s = cfg.video_reestimate_s if cfg.video_rig == "moving" else None
        # A static rig's views are checked for drift this often (``drift.py``); None: not checked.
        self._drift_s = cfg.video_drift_check_s if cfg.video_rig == "static" and cfg.video_drift_check_s > 0 else None
        x0, y0, width, height = fixed_canvas(first, self._rig.pick(*frame_shapes), cfg.video_crop)
        self.crop_xywh = (x0, y0, width, height) if cfg.video_crop else None
        # The output is the fixed canvas, or that canvas made at most video_max_width wide by the maps
        # themselves (``maps.scaled_plane_maps``): each output pixel samples the inputs once.
        self._canvas_shape = (height, width)
        shape = self._shape_out = output_shape(self._canvas_shape, cfg.video_max_width)
        self._scale = canvas_scale(self._canvas_shape, shape)
        self._band = band_half_width(shape, cfg)
        self._offset_tgt = target_offset(first.map_tgt_input) - np.array([x0, y0], np.float64)
        self._maps = self._on_canvas(first)
        self.output_size = (shape[1], shape[0])
        self._luma = Compositor(self._maps.map_src_luma, self._maps.map_tgt_luma, self._maps.seam_luma, cfg, WHITE_Y)
        self._chroma = Compositor(self._maps.map_src_chroma, self._maps.map_tgt_chroma, self._maps.seam_chroma, cfg,
                                  None)
        self._border_set = None  # the border offsets last uploaded
        self._set_border()
        cell = max(1, round(cell_px(frame_shapes, cfg) * float(self._scale.min())))
        self._seam = FrameSeam(self._maps.seam_luma.positions, self._band, cell, self._reestimate_s is None, fps, cfg)
        self._fps = fps
        self._exposure: ExposureTracker | None = None  # made on the first frame pair (it needs the planes' shapes)
        self._plane_shapes: tuple[tuple[int, int], tuple[int, int]] | None = None
        self._first_inliers = self._maps.inliers
        self._first_info = {"tried": [a.as_dict() for a in first_attempts], "chosen_pair": first_pair,
                            "inliers": self._first_inliers, "seconds": round(sum(first.seconds.values()), 4)}
        self._blend: tuple[MapsBlend, int, int] | None = None  # (start to goal, frames done, frames)
        self._workers = ThreadPoolExecutor(cfg.video_estimate_workers, thread_name_prefix="estimate") \
            if self._reestimate_s is not None and cfg.video_estimate_workers > 0 else None
        # With a worker, re-estimates start this many frames ahead (``look_ahead``) and land on their frame.
        held_pairs = int(cfg.video_estimate_lookahead_mib / pair_mib(frame_shapes))
        self.lookahead_frames = (min(int(math.ceil(cfg.video_estimate_lookahead_s * fps)), held_pairs)
                                 if self._workers else 0)
        # A static rig's drift: the camera views its maps were made on (taken on the first estimate's
        # pair), those maps, the views' moves (source, target) they were last moved by, the time of the
        # last check, and what the checks found.
        self._drift: DriftWatch | None = None
        self._drift_base = self._maps
        self._drift_applied = (np.zeros(2), np.zeros(2))
        self._drift_from_s = next(a.time_s for a in first_attempts if a.pair == first_pair)
        self._drift_checked_s = 0.0
        self._drift_log = {"check_s": self._drift_s, "threshold_px": cfg.video_drift_px, "checks": 0, "unclear": 0,
                           "applied": []}
        self._pending: deque[tuple[float, Future]] = deque()  # started re-estimates (frame time, job), oldest first
        self._last_estimate_s: float | None = None
        # "applied": per accepted estimate, the time of the frame it was made on and of the frame whose
        # compositing it started to blend into (the same with a timely look-ahead).
        self._reestimations = {"attempted": 0, "accepted": 0, "rejected": 0, "rejections": [], "applied": []}
        self._seam_jitter_px: list[float] = []
        self._map_change_px: list[float] = []
        self._seam_motion_px: list[float] = []
        self._seconds = {"reestimate": 0.0, "maps_upload": 0.0, "frame_seam": 0.0, "exposure": 0.0}
        if observer is not None:
            self._seconds["observer"] = 0.0

    def _set_border(self) -> None:
        """The current maps' border blend on the Y pass (grey offsets: U and V have none to carry);
        uploaded once per estimate, not on every frame of a blend (its steps share the goal's)."""
        border = self._maps.border_luma
        if border is not None and border is not self._border_set:
            self._luma.set_border_offsets(*border)
            self._border_set = border

    def _on_canvas(self, maps: StitchMaps) -> PlaneMaps:
        """An estimate on the fixed canvas, scaled to the output, its plan band wide enough for the
        per-frame seam."""
        plane = scaled_plane_maps(plane_maps(maps, self._canvas_shape, self._offset_tgt), self._shape_out)
        reach = self._band + plane.seam_luma.band_px
        return replace(plane, seam_luma=replace(plane.seam_luma, band_px=reach),
                       seam_chroma=replace(plane.seam_chroma, band_px=0.5 * reach))

    @classmethod
    def from_pairs(cls, pairs: Iterator[tuple[YuvFrame, YuvFrame]], left: str | os.PathLike,
                   right: str | os.PathLike, cfg: Config, reference: str, observer: FrameObserver | None = None,
                   on_first: FirstEstimateHook | None = None) -> "SenaFrameCompositor":
        """The compositor of two videos ``left`` and ``right``: maps from the best of their first frame
        ``pairs`` (``estimate.best_first_estimate``; it takes pairs up to the last it tries);
        ``reference`` as ``stitch_videos``; ``cfg.device`` resolved. ``on_first``: shown the first
        estimate and the pair it was made on."""
        tried: dict[int, tuple[YuvFrame, YuvFrame]] = {}

        def remembered(spaced: Iterator[tuple[int, YuvFrame, YuvFrame]]) -> Iterator[tuple[int, YuvFrame, YuvFrame]]:
            for index, frame_l, frame_r in spaced:
                if on_first is not None:
                    tried[index] = (frame_l, frame_r)
                yield index, frame_l, frame_r

        maps, pair, attempts = best_first_estimate(remembered(spaced_pairs(pairs, cfg)), cfg, reference)
        if on_first is not None:
            on_first(maps, *tried[pair])
        return cls(maps, attempts, pair, float(probe_video(left).fps), video_shapes(left, right), cfg, observer)

    @classmethod
    def from_videos(cls, left: str | os.PathLike, right: str | os.PathLike, offset_s: float, cfg: Config,
                    reference: str, observer: FrameObserver | None = None,
                    on_first: FirstEstimateHook | None = None) -> "SenaFrameCompositor":
        """:meth:`from_pairs` on decoders of its own (``offset_s`` as ``VideoOptions.offset_s``), for a
        compositor made apart from a frame loop."""
        with paired_frames(left, right, offset_s, cfg) as pairs:
            return cls.from_pairs(pairs, left, right, cfg, reference, observer, on_first)

    def source_target(self, item_left, item_right) -> tuple:
        """A (left, right) pair of per-input things (frames, planes, shapes) as (source, target)."""
        return self._rig.pick(item_left, item_right)

    def passes(self) -> tuple[PlanePass, PlanePass]:
        """(luma, chroma): the maps, seam, gains and offsets the last :meth:`composite_yuv` composited with."""
        maps = self._maps
        return (PlanePass.of(self._luma, maps.map_src_luma, maps.map_tgt_luma, LUMA_FILL),
                PlanePass.of(self._chroma, maps.map_src_chroma, maps.map_tgt_chroma, CHROMA_FILL))

    def look_ahead(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        """A pair ``lookahead_frames`` before it is composited: a re-estimate that is due starts on it,
        so that it is ready when the loop reaches that frame (the maps of a frame still come from that
        frame and earlier ones only)."""
        if self.lookahead_frames and self._worker_idle() and self._due(float(frame_l.time_s)):
            self._submit(frame_l, frame_r)

    def _worker_idle(self) -> bool:
        """No re-estimate is running (those done may still wait for their frame)."""
        return all(job.done() for _, job in self._pending)

    def update(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        """Before compositing a pair: start, collect or blend in a re-estimate, and record the maps' change.
        A re-estimate made on a later frame (``look_ahead``) waits for the loop to reach that frame; one
        that is reached while the last is still being blended in takes over from the maps of the moment
        (else a rig that keeps moving falls further behind with every long blend)."""
        self._time_s = float(frame_l.time_s)
        before = self._maps
        reached = bool(self._pending) and self._pending[0][1].done() and self._pending[0][0] <= self._time_s + 1e-6
        if not (reached and self._collect(frame_l, frame_r)):  # an accepted one starts its blend on this frame
            if self._blend is not None:
                self._advance_blend()
            elif (drifted := self._drifted(frame_l, frame_r)) is not None:
                self._blend_to(*drifted)
            elif not self.lookahead_frames and not self._pending and self._due(self._time_s):
                self._submit(frame_l, frame_r)
        changed = self._maps is not before
        self._seam_jitter_px.append(seam_change_px(before, self._maps) if changed else 0.0)
        self._map_change_px.append(
            map_change_px(before, self._maps, self.source_target(frame_l, frame_r)[0].y.shape, JITTER_PERCENTILE,
                          stride=JITTER_STRIDE) if changed else 0.0)

    def _due(self, time_s: float) -> bool:
        if self._reestimate_s is None:
            return False
        if self._last_estimate_s is None:  # the first estimate was made on the video's first pairs
            self._last_estimate_s = time_s
        return time_s - self._last_estimate_s >= self._reestimate_s

    def _drifted(self, frame_l: YuvFrame, frame_r: YuvFrame) -> tuple[PlaneMaps, int] | None:
        """A static rig's drift check, every ``video_drift_check_s`` from the first estimate's pair on:
        the first estimate's maps moved by how far the views moved (``drifted_maps``) where that
        differs from the last move by more than ``video_drift_px``, and the frames to blend them in
        over (the source side moving at most ``video_drift_speed_px`` a frame); else None."""
        if self._drift_s is None:
            return None
        time_s = self._time_s
        y_src, y_tgt = (frame.y for frame in self.source_target(frame_l, frame_r))
        if self._drift is None:
            if time_s + 1e-6 >= self._drift_from_s:
                boxes = overlap_boxes(self._drift_base, y_src.shape, y_tgt.shape)
                self._drift, self._drift_checked_s = DriftWatch(y_src, y_tgt, boxes), time_s
            return None
        if time_s - self._drift_checked_s < self._drift_s - 1e-6:
            return None
        self._drift_checked_s = time_s
        self._drift_log["checks"] += 1
        shifts = self._drift.shifts(y_src, y_tgt)
        if shifts is None:
            self._drift_log["unclear"] += 1
            return None
        change = max(float(np.hypot(*(now - last))) for now, last in zip(shifts, self._drift_applied))
        if change <= self._cfg.video_drift_px:
            return None
        self._drift_applied = shifts
        self._drift_log["applied"].append({"time_s": round(time_s, 4), "source_px": np.round(shifts[0], 2).tolist(),
                                           "target_px": np.round(shifts[1], 2).tolist()})
        frames = int(np.ceil(change / self._cfg.video_drift_speed_px))
        return drifted_maps(self._drift_base, *shifts, self._scale), frames

    def _prior_seam_tgt(self) -> np.ndarray:
        """The current seam per working-frame target row, in target pixels: where a re-estimate's seam
        should stay (``stitch.estimate_maps``'s ``prior_seam_tgt``)."""
        offset = self._offset_tgt[::-1] if self._rig.vertical else self._offset_tgt
        lines = self._canvas_shape[1] if self._rig.vertical else self._canvas_shape[0]
        seam = seam_on_canvas_lines(self._seam.positions, lines, self._scale, not self._rig.vertical)
        return seam_per_target_line(seam, offset)

    def _submit(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        self._last_estimate_s = float(frame_l.time_s)
        self._reestimations["attempted"] += 1
        # Same roles as the first estimate: the target stays the unwarped view on the fixed canvas.
        if self._workers is not None:
            job = self._workers.submit(self._estimate, frame_l, frame_r, self._prior_seam_tgt())
        else:  # no worker: on the loop's thread, a frame waits for it (reproducible, for tests and batch runs)
            job = Future()
            job.set_result(self._estimate(frame_l, frame_r, self._prior_seam_tgt()))
        self._pending.append((self._last_estimate_s, job))

    def _estimate(self, frame_l: YuvFrame, frame_r: YuvFrame, prior: np.ndarray) -> tuple[PlaneMaps | None, str | None]:
        """On a worker thread: a re-estimate on the fixed canvas, or why it is rejected."""
        t0 = time.perf_counter()
        shape_src, shape_tgt = (f.y.shape for f in self.source_target(frame_l, frame_r))
        try:
            estimate = estimate_pair(frame_l, frame_r, self._cfg, self._rig.target, prior_seam_tgt=prior)
            if estimate.rig.vertical != self._rig.vertical:
                return None, "rig orientation changed"
            candidate = self._on_canvas(estimate)
            reason = rejection_reason(candidate, self._maps, self._first_inliers, shape_src, shape_tgt, self._cfg)
            return (candidate, None) if reason is None else (None, reason)
        except StitchError as exc:
            return None, str(exc)
        finally:
            self._seconds["reestimate"] += time.perf_counter() - t0

    def _collect(self, frame_l: YuvFrame, frame_r: YuvFrame) -> bool:
        """The oldest re-estimate, whose frame is reached: blended in from this frame on (True) or rejected."""
        time_s, job = self._pending.popleft()
        candidate, reason = job.result()
        if reason is not None:
            self._reestimations["rejected"] += 1
            self._reestimations["rejections"].append({"time_s": round(time_s, 4), "reason": reason})
            return False
        self._reestimations["accepted"] += 1
        self._reestimations["applied"].append({"made_on_s": round(time_s, 4), "at_s": round(float(frame_l.time_s), 4)})
        # The target maps are the fixed canvas's own, the same values in every estimate: shared, a blend
        # keeps them as they are instead of mixing equal arrays.
        candidate = replace(candidate, map_tgt_luma=self._maps.map_tgt_luma, map_tgt_chroma=self._maps.map_tgt_chroma)
        # The rig's own geometry changes slowly; what differs from one estimate to the next is mostly
        # estimation noise, which an exponential average over the accepted estimates takes out.
        goal = lerp_maps(self._maps, candidate, self._cfg.video_warp_follow)
        # Over video_blend_frames at least, and slowly enough that the seam moves at most
        # video_seam_speed_px a frame.
        seam_move = float(np.nanmax(np.abs(goal.seam_luma.positions - self._maps.seam_luma.positions)))
        self._blend_to(goal, max(self._cfg.video_blend_frames, int(np.ceil(seam_move / self._cfg.video_seam_speed_px))))
        return True

    def _blend_to(self, goal: PlaneMaps, frames: int) -> None:
        """Start blending from the maps of the moment to ``goal`` over ``frames`` frames (at least one)."""
        self._blend = None  # the blend under way, if any, let go before the next one holds its differences
        self._blend = (MapsBlend(self._maps, goal), 0, max(1, frames))
        self._advance_blend()

    def _advance_blend(self) -> None:
        blend, done, frames = self._blend
        done += 1
        self._maps = blend.at(done / frames)
        self._blend = None if done >= frames else (blend, done, frames)
        t0 = time.perf_counter()
        # The target maps never change on the fixed canvas; only the source map and the seam move.
        self._luma.set_maps(self._maps.map_src_luma, self._maps.seam_luma.positions)
        self._chroma.set_maps(self._maps.map_src_chroma, self._maps.seam_chroma.positions)
        self._set_border()
        self._seam.reset(self._maps.seam_luma.positions)
        if self._exposure is not None:
            self._exposure.set_maps(self._maps, *self._plane_shapes)
        self._seconds["maps_upload"] += time.perf_counter() - t0

    def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Output (y, u, v) planes of ``output_size``; uncovered pixels are black (Y 16, U = V = 128).

        The exposure follows the frame's overlap, the seam is cut anew in its band on the frame's luma
        difference, and the seam blend's offsets come from the same difference.
        """
        y_src, y_tgt = self.source_target(y_l, y_r)
        u_src, u_tgt = self.source_target(u_l, u_r)
        v_src, v_tgt = self.source_target(v_l, v_r)
        t0 = time.perf_counter()
        if self._exposure is None:
            self._plane_shapes = (y_src.shape, y_tgt.shape)
            self._exposure = ExposureTracker(self._maps, y_src.shape, y_tgt.shape, self._fps, self._cfg)
        self._exposure.update(y_src, y_tgt, u_src, u_tgt, v_src, v_tgt)
        (gain_src, bias_src), (gain_tgt, bias_tgt) = self._exposure.luma
        self._luma.set_gains(1, gain_src, bias_src, gain_tgt, bias_tgt)
        (cgain_src, cbias_src), (cgain_tgt, cbias_tgt) = self._exposure.chroma
        self._chroma.set_gains(2, cgain_src, cbias_src, cgain_tgt, cbias_tgt)
        t1 = time.perf_counter()
        self._luma.load(y_src, y_tgt)
        last = self._seam.positions if self._seam.shown is None else self._seam.shown  # a new array either way
        positions, offsets_src, offsets_tgt = self._seam.next(self._luma)
        self._seam_motion_px.append(float(np.abs(positions - last).max()))
        self._luma.set_seam(positions.astype(np.float32))
        self._chroma.set_seam(chroma_lines(positions.astype(np.float32)))
        self._luma.set_offsets(offsets_src, offsets_tgt)
        t2 = time.perf_counter()
        self._seconds["exposure"] += t1 - t0
        self._seconds["frame_seam"] += t2 - t1
        y = self._luma.composite(LUMA_FILL).copy()
        self._chroma.load_planes((u_src, v_src), (u_tgt, v_tgt))
        uv = self._chroma.composite(CHROMA_FILL)
        out = (y, uv[:, :, 0].copy(), uv[:, :, 1].copy())
        if self.observer is not None:
            t3 = time.perf_counter()
            self.observer(self._composited((y_src, u_src, v_src), (y_tgt, u_tgt, v_tgt), out))
            self._seconds["observer"] += time.perf_counter() - t3
        self._frames += 1
        self._time_s = None
        return out

    def _composited(self, planes_src: tuple, planes_tgt: tuple, planes_out: tuple) -> CompositedFrame:
        """The frame just composited, for the observer (copies of the small per-line state only)."""
        return CompositedFrame(
            index=self._frames, time_s=self._time_s, source="left" if self._rig.source == "a" else "right",
            planes_src=planes_src, planes_tgt=planes_tgt,
            planes_out=planes_out, maps=self._maps, seam_home=self._maps.seam_luma.positions,
            seam_reach_px=float(self._maps.seam_luma.band_px), seam=self._luma.seam_positions(), lines_are_rows=self._maps.seam_luma.lines_are_rows,
            gains_luma=self._luma.gains(1), knee_luma=self._luma.knee(), offsets_luma=self._luma.offsets(1), weights=self._luma.seam_weights)

    def close(self) -> None:
        """Stop the re-estimation worker (a pending estimate is dropped)."""
        if self._workers is not None:
            self._workers.shutdown(wait=True, cancel_futures=True)

    def report(self) -> dict:
        """Estimation, re-estimation, seam and exposure figures of the run, JSON-ready."""
        seam = np.asarray(self._seam_jitter_px or [0.0])
        motion = np.asarray(self._seam_motion_px or [0.0])
        history = self._exposure.history if self._exposure is not None else []
        return {
            "rig": {"mode": self._cfg.video_rig, "source": "left" if self._rig.source == "a" else "right",
                    "vertical": self._rig.vertical, "reestimate_s": self._reestimate_s},
            "first_estimate": self._first_info,
            "canvas": {"width": self.output_size[0], "height": self.output_size[1],
                       "stitched_width": self._canvas_shape[1], "stitched_height": self._canvas_shape[0],
                       "crop_xywh": None if self.crop_xywh is None else list(self.crop_xywh),
                       "offset_tgt": [float(v) for v in self._offset_tgt],
                       "seam_x_working": [None if np.isnan(x) else round(float(x), 2)
                                          for x in self._maps.seam_x_working]},
            "reestimations": self._reestimations,
            "drift": self._drift_log,
            "jitter": {
                "seam_jitter_px_mean": round(float(seam.mean()), 4),
                "seam_jitter_px_max": round(float(seam.max()), 4),
                "map_change_p99_px_max": round(max(self._map_change_px, default=0.0), 4),
                "frames": len(self._seam_jitter_px),
            },
            "frame_seam": {"band_px": self._band, "cell_px": self._seam.cell, "line_step": self._seam.step,
                           "motion_px_mean": round(float(motion.mean()), 4),
                           "motion_px_p99": round(float(np.percentile(motion, 99)), 4),
                           "motion_px_max": round(float(motion.max()), 4)},
            "exposure": {"frames": history},
            "timing_s": {name: round(seconds, 4) for name, seconds in self._seconds.items()},
        }


def fixed_canvas(first: StitchMaps, shapes_src_tgt: tuple[tuple[int, int], tuple[int, int]], crop: bool
                 ) -> tuple[int, int, int, int]:
    """(x0, y0, width, height) of the video's canvas on the first estimate's, even-sized (yuv420p):
    all of it, or with ``crop`` the largest rectangle where a view is sampled (``crop.py``)."""
    if not crop:
        return (0, 0, *even_size(first.alpha_input.shape[1], first.alpha_input.shape[0]))
    shape_src, shape_tgt = shapes_src_tgt
    covered = sampled_mask(first.map_src_input, shape_src) | sampled_mask(first.map_tgt_input, shape_tgt)
    x, y, width, height = largest_inner_rectangle(covered)
    x0, y0 = x + x % 2, y + y % 2
    width, height = even_size(width - (x0 - x), height - (y0 - y))
    if width < 2 or height < 2:
        raise VideoError("--crop: the first estimate covers no rectangle to crop to; stitch without --crop")
    return x0, y0, width, height


def video_shapes(left: str | os.PathLike, right: str | os.PathLike) -> tuple[tuple[int, int], tuple[int, int]]:
    """(rows, cols) of the left and the right video's frames, upright."""
    info_l, info_r = probe_video(left), probe_video(right)
    return (info_l.height, info_l.width), (info_r.height, info_r.width)


def pair_mib(shapes: tuple[tuple[int, int], ...]) -> float:
    """MiB of one decoded pair of frames of (rows, cols) ``shapes``: YUV 4:2:0, both views."""
    return sum(rows * cols * 1.5 for rows, cols in shapes) / 2**20


def check_rig_settings(cfg: Config) -> None:
    """InputError for a rig mode or re-estimation period that cannot be used (before any work)."""
    if cfg.video_rig not in RIGS:
        raise InputError(f"rig {cfg.video_rig!r} unknown; use one of {', '.join(RIGS)}")
    if not (0 < cfg.video_reestimate_s < math.inf):
        raise InputError(f"re-estimation period {cfg.video_reestimate_s} s must be a positive number of seconds "
                         f"(--reestimate)")


def stitch_videos(left: str | os.PathLike, right: str | os.PathLike, output: str | os.PathLike, cfg: Config,
                  options: VideoOptions | None = None, reference: str = "auto", plan: OutputPlan | None = None,
                  observer: FrameObserver | None = None, debug: str | os.PathLike | None = None,
                  overwrite: bool = False) -> dict:
    """Stitch two videos into ``output`` with SENA maps; return the run's report.

    An ``output`` of a ``STILL_SUFFIXES`` type gets the stitched frame at the span's start and nothing
    more (:func:`loop.run_still`), a video file every frame of the span (:func:`loop.run_video`).
    ``cfg.video_rig`` "static" estimates once; "moving" re-estimates every ``cfg.video_reestimate_s``.
    ``options``: offset, encoder and limits (None: ``VideoOptions.from_config(cfg)``).
    ``reference``: input kept unwarped ("a" = left, "b" = right, "auto" = the right/bottom view).
    An existing ``output`` is refused (OutputError, before any work) unless ``overwrite`` is True, as
    the CLI's ``-y``; the output appears only once complete. ``plan``: commit the video with that
    plan's other outputs (see ``sena_warp.outputs``), under that plan's rule for existing outputs.
    The report is :func:`loop.run_video`'s plus ``run`` (tool, device, settings) and ``stitch`` (see
    :meth:`SenaFrameCompositor.report`), its times in one ``timing_s`` block (``docs/report.md``).
    ``observer``: called with every composited frame (:class:`CompositedFrame`). ``debug``: a folder for
    the first estimate's stage pictures (``debug.py``), written with ``plan``'s outputs.
    The Warp device of ``cfg`` is resolved here, once for the whole video.
    """
    options = VideoOptions.from_config(require_config(cfg, "stitch_videos")) if options is None else options
    if not isinstance(options, VideoOptions):
        raise InputError(f"stitch_videos: options must be a VideoOptions or None, got {type(options).__name__}")
    if plan is not None:
        return _stitch_videos(left, right, output, cfg, options, reference, plan, observer, debug)
    own = OutputPlan((left, right), overwrite="overwrite" if overwrite else "refuse")
    own.add(output, "the output")
    if debug is not None:
        own.add(debug, "debug", folder=True)
    own.check()
    with own:
        return _stitch_videos(left, right, output, cfg, options, reference, own, observer, debug)


def _stitch_videos(left, right, output, cfg: Config, options: VideoOptions, reference: str, plan: OutputPlan,
                   observer: FrameObserver | None, debug: str | os.PathLike | None) -> dict:
    check_rig_settings(cfg)
    cfg = resolve_config(cfg)
    t0 = time.perf_counter()
    # Shipped builds load at once; what must be compiled is, in the background, the estimate's modules
    # first: a launch waits for its own module only. The planes are composited with 1 (Y) and 2 (UV) channels.
    prewarm(cfg.device, channels=PLANE_CHANNELS, wait=False)
    load_kernels_s = time.perf_counter() - t0
    built: list[SenaFrameCompositor] = []
    first: list[tuple[StitchMaps, YuvFrame, YuvFrame]] = []  # kept for the debug pictures

    def keep_first(maps: StitchMaps, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        first.append((maps, frame_l, frame_r))

    hook = keep_first if debug is not None else None

    def factory(pairs: Iterator[tuple[YuvFrame, YuvFrame]]) -> SenaFrameCompositor:
        if spaced_span(cfg) * pair_mib(video_shapes(left, right)) <= cfg.video_estimate_lookahead_mib:
            built.append(SenaFrameCompositor.from_pairs(pairs, left, right, cfg, reference, observer, hook))
        else:  # too large to hold that many pairs for the loop: the estimate decodes its own
            built.append(SenaFrameCompositor.from_videos(left, right, options.offset_s, cfg, reference, observer,
                                                         hook))
        return built[0]

    run = run_still if Path(output).suffix.lower() in STILL_SUFFIXES else run_video
    try:
        report = run(left, right, output, factory, options, plan)
        if debug is not None:
            with plan.writing(debug) as folder:
                dump_first_estimate(folder, *first[0], cfg)
    finally:
        for compositor in built:
            compositor.close()
    stitch = built[0].report()
    report["timing_s"] = {"load_kernels": round(load_kernels_s, 4), **report["timing_s"], **stitch.pop("timing_s")}
    return {"run": run_info(cfg), **report, "stitch": stitch}
