"""Stitching two videos with SENA maps: estimate once, then follow the rig, composite planes.

``stitch_videos`` is the ``sena-warp video`` job: the best of the first frame pairs gives the maps and
fixes the output canvas (``estimate.py``); every frame pair is then composited in YUV 4:2:0 by the
loop in ``loop.py``, which calls :class:`SenaFrameCompositor` once per pair. A frame reads as the
paper's per-frame path, one stage per line (:meth:`SenaFrameCompositor.composite_yuv`):

1. the maps of the frame: the maps timeline (``timeline.py``: the first estimate, a static rig's
   drift and its blends, a moving rig's alignment to every frame and its re-estimates, ``--rig
   auto``'s switches between the two), a value per map set;
2. their plan on the device, made once per map set (``device_frame.Plans``);
3. the frame's gains (``exposure.py``: they follow the cameras' exposure);
4. the pair on the device, and its seam band's difference back (``device_frame.DeviceFrame``): with
   a static plan's object band's over the whole overlap in the same block (``frame_objects.py``);
5. the frame's seam, cut anew in its band (``frame_seam.py``; on a static plan round what is in front,
   each object shown once and whole, the band placed for the next frame where the objects' route
   passes; on a moving rig keeping the two copies of what its warp could not align on one side), and
   the seam blend's offsets: with the gains, the frame's state (``composite.FrameState``);
6. the compositing step, the plan and the state on the pair, and the output planes back;
7. the run log (``RunLog``), which the report reads.

An optional *observer* (``stitch_videos(observer=...)``) is called once per composited frame with a
:class:`CompositedFrame`: what went in, what came out and what it was composited with. The pipeline
only calls it; what it measures lives elsewhere (``sena_warp.evaluation.video_figures``).
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from ..composite import (LEVEL, CompositePlan, FrameState, applied_gains, border_offsets, clipped_seam, fixed_point,
                         seam_weights)
from ..config import CHOICES, Config, require_config
from ..crop import largest_inner_rectangle
from ..errors import InputError, VideoError
from ..outputs import OutputPlan
from ..progress import LOGGER
from ..report import run_info
from ..rig import Rig
from ..stitch import StitchMaps
from sena_warp.kernels import transfer
from sena_warp.kernels.runtime import prewarm, resolve_config
from .debug import dump_first_estimate
from .device_frame import DeviceFrame, FramePlan, Plans, frame_plan
from .estimate import Attempt, best_first_estimate, moving_in_front, paired_frames, spaced_pairs, spaced_span
from .exposure import ExposureTracker
from .frame_seam import BandFrame, FrameSeam, band_half_width, cell_px
from .loop import VideoOptions, run_still, run_video
from .maps import (PlaneMaps, chroma_lines, map_change_px, maps_on_canvas, output_shape, sampled_mask,
                   seam_change_px, seam_on_canvas_lines, seam_per_target_line, target_offset, windowed_lines,
                   windowed_seam)
from .reader import YuvFrame, probe_video
from .align import Seam
from .rig_motion import RigMotion
from .steady import SteadyCanvas, margin_px, steady_crop
from .timeline import Canvas, LastFrame, MapsTimeline, Reestimates, lookahead_frames, watch_frames
from .writer import even_size

RIGS = CHOICES["video_rig"]
STILL_SUFFIXES = (".png", ".jpg", ".jpeg")  # an output of these types is the one stitched frame at the span's start
JITTER_PERCENTILE = 99.0  # "largest map change" = this percentile of |delta M_s| per frame (robust to edge pixels)
JITTER_STRIDE = 8  # ... over every this-th canvas row and column (a 1080p frame's full maps took 0.1 s; a moving rig's
# maps change every frame, and at 4 the figure took 0.7-2 ms of its frame)
FRAME_PATH = ("planes", "band", "seam", "output")  # what a frame itself moves (``kernels/transfer.py``)
PLANE_CHANNELS = (1, 2)  # the frame kernels' channel counts: the Y pass, and U and V stacked


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
    def of(plan: CompositePlan, state: FrameState, map_src: np.ndarray, map_tgt: np.ndarray, cfg: Config
           ) -> "PlanePass":
        """The pass ``plan`` composites with the frame's ``state`` (its seam, gains and offsets, as the
        kernels apply them)."""
        channels = plan.channels
        alpha, lf = seam_weights(state.seam, plan.layout, plan.canvas_shape, cfg)
        offsets = state.offsets if state.offsets is not None else (np.zeros((plan.lines, channels)),) * 2
        rows = plan.layout.lines_are_rows

        def spread(per_line: np.ndarray) -> np.ndarray:
            per_line = fixed_point(per_line).reshape(plan.lines, channels) / LEVEL
            lines = per_line[:, None, :] if rows else per_line[None, :, :]
            return (lf[:, :, None] * lines).astype(np.float32)

        border_src, border_tgt = border_offsets(plan)
        gains = tuple(np.asarray(g, np.float64)[:channels] for g in state.gains)
        return PlanePass(map_src, map_tgt, alpha, gains, plan.knee, spread(offsets[0]) + border_src,
                         spread(offsets[1]) + border_tgt, plan.fill)


@dataclass(frozen=True)
class CompositedFrame:
    """One composited frame as an observer sees it: read-only views, valid during the call only.

    ``index``: output frame number from 0; ``time_s``: the left frame's time (None when
    ``composite_yuv`` was called without ``update``); ``source``: which input is the source, "left"
    or "right" (the other is the target). ``planes_src`` / ``planes_tgt``: the (y, u, v)
    uint8 planes of the source / target input as decoded (``plane[row, col]``); ``planes_out``: the
    output (y, u, v) as shown; ``window``: (x, y, width, height) the output frame on the canvas (x, y
    sub-pixel: a moving rig's steady canvas, ``steady.py``; it may reach off the canvas, where the
    output is black); ``canvas()``: the (y, u, v) composited on the canvas (``planes_out`` where the
    output is the canvas, else the pair composited once more by the canvas's plan: call it only where
    needed). ``maps``: the canvas's :class:`~sena_warp.video.maps.PlaneMaps` (the same object for as
    long as the maps do not change; input-frame (x, y) sample positions per canvas pixel); its
    ``seam_home``: (L,) float32 the estimate's seam, the centre of the band in which the frame's seam
    may move, at most ``seam_reach_px`` from it; ``seam``: (L,) float32 the frame's seam as composited
    on the canvas; a line is
    a canvas row when ``lines_are_rows`` (positions are x; the source lies at smaller x), else a
    column (positions are y). ``gains_luma``: (gain_src, bias_src, gain_tgt, bias_tgt), each (1,)
    float64, the Y pass's affine gains (``out = gain * Y + bias`` up to the knee), ``knee_luma`` their
    highlight knee (knee, white) grey levels (``gains.tone_curve``); ``offsets_luma``: ((L, 1), (L, 1))
    float64 the seam blend's per-line offsets of each side, grey levels at the seam. ``weights()``:
    (alpha, lf) (Hc, Wc) float32 of the Y pass (``composite.seam_weights``: one kernel launch over
    the canvas, so call it only where needed).
    """

    index: int
    time_s: float | None
    source: str
    planes_src: tuple[np.ndarray, np.ndarray, np.ndarray]
    planes_tgt: tuple[np.ndarray, np.ndarray, np.ndarray]
    planes_out: tuple[np.ndarray, np.ndarray, np.ndarray]
    window: tuple[float, float, int, int]
    maps: PlaneMaps
    seam: np.ndarray
    gains_luma: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    knee_luma: tuple[float, float] | None
    offsets_luma: tuple[np.ndarray, np.ndarray]
    weights: Callable[[], tuple[np.ndarray, np.ndarray]]
    canvas: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]]

    @property
    def lines_are_rows(self) -> bool:
        """Whether a seam line is a canvas row (else a column)."""
        return self.maps.seam_luma.lines_are_rows

    @property
    def seam_home(self) -> np.ndarray:
        """(L,) float32 the estimate's seam: the centre of the band the frame's seam may move in."""
        return self.maps.seam_luma.positions

    @property
    def seam_reach_px(self) -> float:
        """How far from ``seam_home`` the frame's seam may go."""
        return float(self.maps.seam_luma.band_px)


FirstEstimateHook = Callable[[StitchMaps, YuvFrame, YuvFrame], None]
"""Shown the first estimate and the (left, right) frames it was made on (``video --debug``)."""

FrameObserver = Callable[[CompositedFrame], None]
"""Called once per composited frame, on the loop's thread, before the frame is encoded; its time is
reported as the stitch's ``timing_s.observer``."""


@dataclass
class RunLog:
    """What a run did, frame by frame, for its report: the maps' change (``seam_jitter_px``, the mean
    change of the estimate's seam; ``map_change_px``, the source map's), the frame's seam motion, each
    frame's transfers (``kernels/transfer.py``: (kind, what) -> count), and seconds per part."""

    seconds: dict[str, float]
    seam_jitter_px: list[float] = field(default_factory=list)
    map_change_px: list[float] = field(default_factory=list)
    seam_motion_px: list[float] = field(default_factory=list)
    transfers: list[Counter] = field(default_factory=list)
    frames: int = 0
    time_s: float | None = None  # the time of the frame last updated to, until it is composited

    @contextmanager
    def clock(self, part: str) -> Iterator[None]:
        t0 = time.perf_counter()
        yield
        self.seconds[part] = self.seconds.get(part, 0.0) + time.perf_counter() - t0

    def transfer_figures(self) -> dict:
        """Per frame, the frame path's uploads, downloads and waits (min and max over the frames, what
        moved, ``FRAME_PATH``), and the run's total of each kind and what, new map sets' included."""
        kinds = transfer.KINDS
        per_frame = [{kind: sum(n for (k, what), n in counts.items() if k == kind and what in FRAME_PATH)
                      for kind in kinds} for counts in self.transfers]
        total = sum(self.transfers, Counter())
        return {"frames": len(per_frame),
                "per_frame_min": {kind: min((f[kind] for f in per_frame), default=0) for kind in kinds},
                "per_frame_max": {kind: max((f[kind] for f in per_frame), default=0) for kind in kinds},
                "total": {kind: {what: n for (k, what), n in sorted(total.items()) if k == kind} for kind in kinds}}


class SenaFrameCompositor:
    """The loop's frame compositor for a SENA stitch (see ``loop.FrameCompositor``).

    Public surface: :meth:`from_pairs` and :meth:`from_videos` (estimate and build), ``output_size``
    (width, height), :meth:`update` and :meth:`composite_yuv` (what the loop calls), :meth:`source_target` and
    :meth:`passes` (what a frame is composited with, for the bench's reference implementation),
    :meth:`report`; ``observer`` (a :data:`FrameObserver` or None) sees every composited frame.
    Inside: the maps ``timeline``, the plans, the per-frame ``seam``, the exposure, the device frame
    and the run log (module docstring).
    """

    def __init__(self, first: StitchMaps, first_attempts: list[Attempt], first_pair: int, fps: float,
                 frame_shapes: tuple[tuple[int, int], tuple[int, int]], cfg: Config,
                 observer: FrameObserver | None = None):
        """From the first estimate ``first`` (made on pair ``first_pair``; ``first_attempts``: every
        pair tried) for inputs at ``fps`` frames per second whose (rows, cols) are ``frame_shapes``
        (left, right); ``cfg.device`` resolved. With ``cfg.video_crop`` the fixed canvas is the largest
        rectangle the first estimate covers and the output that less the steady canvas's margin
        (``steady.py``) with ``--rig moving``. ``observer``: called with every composited frame."""
        self._cfg = cfg
        self._fps = fps
        self.observer = observer
        rig = first.rig
        x0, y0, width, height = fixed_canvas(first, rig.pick(*frame_shapes), cfg.video_crop)
        # The canvas is the fixed canvas, or that canvas made at most video_max_width wide by the maps
        # themselves (``maps.scaled_plane_maps``): each output pixel samples the inputs once. The output
        # is the canvas, or with --crop the canvas less the steady canvas's margin.
        shape = output_shape((height, width), cfg.video_max_width)
        offset_tgt = target_offset(first.map_tgt_input) - np.array([x0, y0], np.float64)
        self._canvas = Canvas((height, width), shape, offset_tgt, band_half_width(shape, cfg), rig)
        shown = (0, 0, shape[1], shape[0])
        if cfg.video_crop:
            shown = steady_crop(*shown, margin_px(cfg))
            sx, sy = self._canvas.scale
            self.crop_xywh = (x0 + round(shown[0] / sx), y0 + round(shown[1] / sy), round(shown[2] / sx),
                              round(shown[3] / sy))
        else:
            self.crop_xywh = None
        self.output_size = (shown[2], shown[3])
        self._steady = SteadyCanvas(shape, (shown[3], shown[2]), self._canvas.scale, cfg)
        # A rig that may be static: its seam may go round what is in front anywhere in the overlap.
        shapes_src_tgt = rig.pick(*frame_shapes)
        # --rig auto on a first estimate that aligned something moving in front of a still background: aligned
        # every frame from the start (``timeline.MapsTimeline``), its band a moving rig's.
        in_front = (cfg.video_rig == "auto" and cfg.video_align_in_front and not cfg.video_still_background
                    and moving_in_front(first_attempts, first_pair, cfg))
        maps = maps_on_canvas(first, self._canvas.stitched_shape, offset_tgt, self._canvas.band_px, shape,
                              shapes_src_tgt, cfg.video_rig != "moving" and not in_front, cfg)
        self._first_info = {"tried": [a.as_dict() for a in first_attempts], "chosen_pair": first_pair,
                            "inliers": maps.inliers, "seconds": round(sum(first.seconds.values()), 4)}
        first_s = next(a.time_s for a in first_attempts if a.pair == first_pair)
        mode = "moving" if cfg.video_rig == "moving" else "static"  # --rig auto starts static and decides
        self._timeline = MapsTimeline(maps, mode, first_s, self._canvas, self._reestimates(maps, fps, frame_shapes),
                                      RigMotion(cfg) if cfg.video_rig == "auto" else None,
                                      watch_frames(fps, pair_mib(frame_shapes), cfg), cfg, in_front)
        if self._timeline.in_front:
            LOGGER.info("rig: aligned every frame (the first estimate's matches lead with something that moves "
                        "in front of a still background)")
        self._plans = Plans((shown[3], shown[2]), offset_tgt, cfg)  # of the canvas's maps, or of a window on them
        cell = max(1, round(cell_px(frame_shapes, cfg) * float(self._canvas.scale.min())))
        self._seam = FrameSeam(maps.seam_luma.positions, self._canvas.band_px, cell, maps.overlap_luma,
                               not self._timeline.aligned, fps, cfg)
        self._exposure: ExposureTracker | None = None  # made on the first frame pair (it needs the planes' shapes)
        self._device: DeviceFrame | None = None  # likewise
        self._last: tuple[FramePlan, FrameState, FrameState] | None = None  # the last frame's plan and states
        self._log = RunLog({"reestimate": 0.0, "maps_upload": 0.0, "frame_seam": 0.0, "exposure": 0.0,
                            **({"observer": 0.0} if observer is not None else {})})

    def _reestimates(self, maps: PlaneMaps, fps: float, frame_shapes) -> Reestimates | None:
        """The re-estimates of a rig that may move, started ahead of their frame by a worker's look-ahead."""
        if self._cfg.video_rig == "static":
            return None
        return Reestimates(self._canvas, maps.inliers, lookahead_frames(fps, pair_mib(frame_shapes), self._cfg),
                           self._cfg)

    @property
    def lookahead_frames(self) -> int:
        """How many pairs ahead the loop shows each pair to :meth:`look_ahead` (0: not at all)."""
        return self._timeline.lookahead_frames

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
        return self._canvas.rig.pick(item_left, item_right)

    @property
    def maps(self) -> PlaneMaps:
        """The maps the next frame is composited with (those of the frame last updated to)."""
        return self._timeline.maps

    @property
    def frame_seam(self) -> FrameSeam:
        """The per-frame seam (its last frame's seam, still lines and band)."""
        return self._seam

    @property
    def rig(self) -> Rig:
        """The rig: which input is the source, and whether it is vertical."""
        return self._canvas.rig

    @property
    def last_frame(self) -> tuple[FramePlan, FrameState, FrameState] | None:
        """(plan, Y state, U/V state) of the last composited frame, on the device frame ``device``."""
        return self._last

    @property
    def device(self) -> DeviceFrame | None:
        """The device frame the last frame was composited in (its pair still loaded)."""
        return self._device

    @property
    def offset_tgt(self) -> np.ndarray:
        """(x, y) the target's offset on the fixed canvas (input frame)."""
        return self._canvas.offset_tgt

    def passes(self) -> tuple[PlanePass, PlanePass]:
        """(luma, chroma): the maps, seam, gains and offsets the last :meth:`composite_yuv` composited with."""
        plan, luma, chroma = self._last
        maps = plan.shown_maps()
        return (PlanePass.of(plan.luma, luma, maps.map_src_luma, maps.map_tgt_luma, self._cfg),
                PlanePass.of(plan.chroma, chroma, maps.map_src_chroma, maps.map_tgt_chroma, self._cfg))

    def _prior_seam_tgt(self) -> np.ndarray:
        """The current seam per working-frame target row, in target pixels: where a re-estimate's seam
        should stay (``stitch.estimate_maps``'s ``prior_seam_tgt``)."""
        canvas = self._canvas
        vertical = canvas.rig.vertical
        lines = canvas.stitched_shape[1] if vertical else canvas.stitched_shape[0]
        seam = seam_on_canvas_lines(self._seam.positions, lines, canvas.scale, not vertical)
        return seam_per_target_line(seam, canvas.offset_tgt[::-1] if vertical else canvas.offset_tgt)

    def look_ahead(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        """A pair ``lookahead_frames`` before it is composited: a re-estimate that is due starts on it."""
        self._timeline.look_ahead(frame_l, frame_r, self._prior_seam_tgt)

    def update(self, frame_l: YuvFrame, frame_r: YuvFrame) -> None:
        """Before compositing a pair: the maps timeline advances to it (``timeline.py``), the seam glides
        or may jump as its rig's plan says; the maps' change is logged."""
        log = self._log
        log.time_s = float(frame_l.time_s)
        before = self._timeline.maps
        y_src, y_tgt = (frame.y for frame in self.source_target(frame_l, frame_r))
        after = self._timeline.advance(frame_l, frame_r, y_src, y_tgt, self._prior_seam_tgt, self._last_frame())
        if self._timeline.mode == "moving":
            self._steady.follow(y_tgt)
        else:
            self._steady.hold()
        self._seam.set_jumps(not self._timeline.aligned)
        changed = after is not before
        log.seam_jitter_px.append(seam_change_px(before, after) if changed else 0.0)
        log.map_change_px.append(map_change_px(before, after, y_src.shape, JITTER_PERCENTILE, stride=JITTER_STRIDE)
                                 if changed else 0.0)

    def _last_frame(self) -> LastFrame:
        """The gains and seam of the frame composited last, for a moving rig's alignment."""
        if self._exposure is None:
            return LastFrame((1.0, 0.0, 1.0, 0.0), None)
        (gain_src, bias_src), (gain_tgt, bias_tgt) = self._exposure.luma
        shown = self._seam.shown
        return LastFrame((float(gain_src[0]), float(bias_src[0]), float(gain_tgt[0]), float(bias_tgt[0])),
                         None if shown is None else Seam(shown, self._timeline.maps.seam_luma.lines_are_rows))

    def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Output (y, u, v) planes of ``output_size``, the steady canvas's window on the composited canvas;
        uncovered pixels are black (Y 16, U = V = 128).

        The exposure follows the frame's overlap, the seam is cut anew in its band on the frame's luma
        difference, and the seam blend's offsets come from the same difference.
        """
        log = self._log
        counted = transfer.tally()
        planes_src, planes_tgt = self.source_target((y_l, u_l, v_l), (y_r, u_r, v_r))
        shapes = (planes_src[0].shape, planes_tgt[0].shape)
        maps = self._timeline.maps
        window = self._steady.window_for(self._timeline.mode)
        with log.clock("maps_upload"):
            plan = self._plans.plan(maps, shapes, window)
            self._seam.reset(maps.seam_luma.positions, maps.overlap_luma)
        with log.clock("exposure"):
            luma_gains, chroma_gains = self._gains(maps, planes_src, planes_tgt)
        device = self._device_for(shapes)
        device.load(planes_src, planes_tgt)
        gains = device.gains(plan, luma_gains, chroma_gains)
        with log.clock("frame_seam"):
            objects = self._seam.objects
            origin = (0, 0) if window is None else tuple(int(v) for v in np.rint(window))
            band, object_band = device.band(plan, self._seam.place, objects.grid if objects is not None else None,
                                            gains[0], origin)
            luma, chroma = self._frame_states(band, object_band, maps, luma_gains, chroma_gains)
            shown_luma, shown_chroma = (luma, chroma) if window is None else windowed_states(luma, chroma, window, plan)
        out = device.composite(plan, shown_luma, shown_chroma, gains, self._seam.place)
        self._last = (plan, shown_luma, shown_chroma)
        if self.observer is not None:
            with log.clock("observer"):
                canvas = self._canvas_of(out, window, maps, shapes, (luma, chroma), gains)
                self.observer(self._composited(planes_src, planes_tgt, out, canvas, maps, luma, gains[0]))
        log.transfers.append(transfer.tally() - counted)
        log.frames += 1
        log.time_s = None
        return out

    def _frame_states(self, band: BandFrame, objects: BandFrame | None, maps: PlaneMaps, luma_gains: tuple,
                      chroma_gains: tuple) -> tuple[FrameState, FrameState]:
        """Each pass's state on the canvas of ``maps`` of the frame whose seam band is ``band`` (and
        object band ``objects``, on a static plan): its seam (``frame_seam``), kept in the band, with the
        seam blend's offsets on the Y pass, and its gains."""
        last = self._seam.positions if self._seam.shown is None else self._seam.shown  # a new array either way
        copies = self._timeline.copies(maps.seam_luma.lines_are_rows)
        positions, offsets_src, offsets_tgt = self._seam.next(band, objects, copies)
        self._log.seam_motion_px.append(float(np.abs(positions - last).max()))
        positions = positions.astype(np.float32)
        return (FrameState(clipped_seam(positions, maps.seam_luma), luma_gains, (offsets_src, offsets_tgt)),
                FrameState(clipped_seam(chroma_lines(positions), maps.seam_chroma), chroma_gains))

    def _canvas_of(self, out: tuple, window: np.ndarray | None, maps: PlaneMaps, shapes: tuple,
                   states: tuple[FrameState, FrameState], gains: tuple) -> Callable[[], tuple]:
        """The frame's canvas planes for an observer, composited on its first call: ``out`` where the output
        is the canvas, else the loaded pair by a plan of the canvas's maps (made for it: an observer's cost)
        with the canvas's ``states``."""
        if window is None:
            return lambda: out
        made: list[tuple] = []

        def canvas() -> tuple:
            if not made:
                made.append(self._device.canvas(frame_plan(maps, shapes, self._cfg), *states, gains))
            return made[0]
        return canvas

    def _gains(self, maps: PlaneMaps, planes_src: tuple, planes_tgt: tuple) -> tuple[tuple, tuple]:
        """The frame's (luma, chroma) gains, (gain_src, bias_src, gain_tgt, bias_tgt) each (``exposure.py``)."""
        if self._exposure is None:
            self._exposure = ExposureTracker(maps, planes_src[0].shape, planes_tgt[0].shape, self._fps, self._cfg)
        (y_src, u_src, v_src), (y_tgt, u_tgt, v_tgt) = planes_src, planes_tgt
        self._exposure.update(maps, y_src, y_tgt, u_src, u_tgt, v_src, v_tgt)
        (gain_src, bias_src), (gain_tgt, bias_tgt) = self._exposure.luma
        (cgain_src, cbias_src), (cgain_tgt, cbias_tgt) = self._exposure.chroma
        return (gain_src, bias_src, gain_tgt, bias_tgt), (cgain_src, cbias_src, cgain_tgt, cbias_tgt)

    def _device_for(self, shapes: tuple[tuple[int, int], tuple[int, int]]) -> DeviceFrame:
        """The device frame of planes of these Y shapes (made on the first frame)."""
        if self._device is None or self._device.shapes != shapes:
            steady = self._steady
            self._device = DeviceFrame(shapes, self._canvas.shape, steady.output_shape, self._seam.grid, self._cfg)
        return self._device

    def _composited(self, planes_src: tuple, planes_tgt: tuple, planes_out: tuple, canvas: Callable[[], tuple],
                    maps: PlaneMaps, luma: FrameState, gains_luma) -> CompositedFrame:
        """The frame just composited, for the observer: its ``maps`` and Y state ``luma`` on the canvas."""
        plan = self._last[0]
        offsets = tuple(fixed_point(v).reshape(-1, 1) / LEVEL for v in luma.offsets)
        return CompositedFrame(
            index=self._log.frames, time_s=self._log.time_s,
            source="left" if self._canvas.rig.source == "a" else "right",
            planes_src=planes_src, planes_tgt=planes_tgt, planes_out=planes_out,
            window=(*(float(v) for v in self._steady.window()), *self.output_size), maps=maps,
            seam=luma.seam.copy(),
            gains_luma=applied_gains(gains_luma, 1),
            knee_luma=plan.luma.knee, offsets_luma=offsets,
            weights=lambda: seam_weights(luma.seam, maps.seam_luma, maps.shape, self._cfg), canvas=canvas)

    def close(self) -> None:
        """Stop the re-estimation worker (a pending estimate is dropped)."""
        self._timeline.close()

    def report(self) -> dict:
        """Estimation, re-estimation, seam and exposure figures of the run, JSON-ready."""
        log, cfg, canvas = self._log, self._cfg, self._canvas
        seam = np.asarray(log.seam_jitter_px or [0.0])
        motion = np.asarray(log.seam_motion_px or [0.0])
        history = self._exposure.history if self._exposure is not None else []
        reestimates = self._timeline.reestimates
        drift = self._timeline.drift
        seconds = {**log.seconds, "reestimate": reestimates.seconds if reestimates is not None else 0.0,
                   **({"align": self._timeline.align_seconds} if reestimates is not None else {})}
        return {
            "rig": {"mode": cfg.video_rig, "source": "left" if canvas.rig.source == "a" else "right",
                    "vertical": canvas.rig.vertical,
                    "reestimate_s": cfg.video_reestimate_s if reestimates is not None else None,
                    "decisions": self._timeline.decisions, "aligned_in_front": self._timeline.in_front,
                    "alignment": self._timeline.alignment_log(),
                    "steady": self._steady.report()},
            "first_estimate": self._first_info,
            "canvas": {"width": self.output_size[0], "height": self.output_size[1],
                       "stitched_width": canvas.stitched_shape[1], "stitched_height": canvas.stitched_shape[0],
                       "crop_xywh": None if self.crop_xywh is None else list(self.crop_xywh),
                       "offset_tgt": [float(v) for v in canvas.offset_tgt],
                       "seam_x_working": [None if np.isnan(x) else round(float(x), 2)
                                          for x in self._timeline.maps.seam_x_working]},
            "reestimations": (reestimates.log if reestimates is not None else
                              {"attempted": 0, "accepted": 0, "rejected": 0, "rejections": [], "applied": []}),
            "drift": (drift.log if drift is not None else
                      {"check_s": None, "threshold_px": cfg.video_drift_px, "checks": 0, "unclear": 0,
                       "applied": []}),
            "jitter": {
                "seam_jitter_px_mean": round(float(seam.mean()), 4),
                "seam_jitter_px_max": round(float(seam.max()), 4),
                "map_change_p99_px_max": round(max(log.map_change_px, default=0.0), 4),
                "frames": len(log.seam_jitter_px),
            },
            "frame_seam": {"band_px": canvas.band_px, "cell_px": self._seam.cell, "line_step": self._seam.step,
                           "motion_px_mean": round(float(motion.mean()), 4),
                           "motion_px_p99": round(float(np.percentile(motion, 99)), 4),
                           "motion_px_max": round(float(motion.max()), 4)},
            "exposure": {"frames": history},
            "transfers": log.transfer_figures(),
            "timing_s": {name: round(seconds, 4) for name, seconds in seconds.items()},
        }


def windowed_states(luma: FrameState, chroma: FrameState, window: np.ndarray, plan: FramePlan
                    ) -> tuple[FrameState, FrameState]:
    """A frame's (luma, chroma) states on the canvas as the states of the output window at ``window`` (x,
    y) whose ``plan`` composites it (``maps.windowed_plane_maps``): the seam and its offsets resampled
    onto the window's lines (``maps.windowed_lines``), the seam kept in the window plan's band."""
    layout = plan.luma.layout
    rows, lines = layout.lines_are_rows, plan.luma.lines
    positions = windowed_seam(luma.seam, window, rows, lines)
    offsets = tuple(windowed_lines(v, window, rows, lines) for v in luma.offsets)
    return (FrameState(clipped_seam(positions, layout), luma.gains, offsets),
            FrameState(clipped_seam(chroma_lines(positions), plan.chroma.layout), chroma.gains))


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
    ``cfg.video_rig`` "static" estimates once; "moving" aligns the maps to every frame and re-estimates
    when the alignment falls behind; "auto" decides from the first second and watches (``timeline.py``).
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
        if cfg.video_opencv_threads > 0:  # from the first estimate on: the frames' OpenCV calls are small
            cv2.setNumThreads(cfg.video_opencv_threads)
        return built[0]

    run = run_still if Path(output).suffix.lower() in STILL_SUFFIXES else run_video
    opencv_threads = cv2.getNumThreads()  # set back when the run ends: the process's, not the run's
    try:
        report = run(left, right, output, factory, options, plan)
        if debug is not None:
            with plan.writing(debug) as folder:
                dump_first_estimate(folder, *first[0], cfg)
    finally:
        for compositor in built:
            compositor.close()
        cv2.setNumThreads(opencv_threads)
    stitch = built[0].report()
    report["timing_s"] = {"load_kernels": round(load_kernels_s, 4), **report["timing_s"], **stitch.pop("timing_s")}
    return {"run": run_info(cfg), **report, "stitch": stitch}
