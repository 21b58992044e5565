"""Which maps each frame of a video is composited with: the maps timeline.

The first estimate gives the maps of the first frames. After that the maps of frame t come from
frame t and earlier ones only:

- a static rig's maps follow a camera that drifts (:class:`DriftCheck`, ``drift.py``): every
  ``video_drift_check_s`` the views are compared with the first estimate's, and a move larger than
  ``video_drift_px`` is blended in (the source side at most ``video_drift_speed_px`` a frame);
- a moving rig's maps are re-estimated every ``video_reestimate_s`` (:class:`Reestimates`), on a worker
  thread with a CUDA stream of its own (on the loop's thread with ``video_estimate_workers`` 0:
  deterministic), a look-ahead ahead so that an estimate lands on its own frame; an implausible one is
  rejected; an accepted one moves the maps ``video_warp_follow`` of the way (an exponential average
  over the estimates, causal), blended in over ``video_blend_frames`` frames at least and slowly
  enough that the seam moves at most ``video_seam_speed_px`` a frame (:class:`Blend`).

:meth:`MapsTimeline.advance` answers for each frame in turn with a :class:`~sena_warp.video.maps.PlaneMaps`
value: the same object for as long as the maps do not change, so whatever is made from it (a
compositing plan) is made once per map set. What happened is logged for the report (``log``).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from ..config import Config
from ..errors import StitchError
from ..rig import Rig
from sena_warp.kernels.transfer import own_stream
from .drift import DriftWatch, overlap_boxes
from .estimate import estimate_pair, rejection_reason
from .maps import MapsBlend, PlaneMaps, drifted_maps, lerp_maps, maps_on_canvas
from .reader import YuvFrame


@dataclass(frozen=True)
class Blend:
    """Maps on their way from the maps of a moment to a goal (``lerp``), ``done`` of ``frames`` frames
    made: each frame takes the next step."""

    lerp: MapsBlend
    done: int
    frames: int

    def step(self) -> tuple[PlaneMaps, "Blend | None"]:
        """The next frame's maps, and the blend left after it (None: the goal is reached)."""
        done = self.done + 1
        return self.lerp.at(done / self.frames), (None if done >= self.frames else replace(self, done=done))


class DriftCheck:
    """A static rig's drift check (``drift.py``), every ``cfg.video_drift_check_s`` from the first
    estimate's pair (at ``from_s``) on: ``base`` (the first estimate's maps) moved by how far the views
    moved. ``log``: what the checks found (the report's ``drift``)."""

    def __init__(self, base: PlaneMaps, from_s: float, cfg: Config):
        self._cfg = cfg
        self._base = base
        self._from_s = from_s
        self._watch: DriftWatch | None = None  # the views as the maps were made, taken on the first check's frame
        self._applied = (np.zeros(2), np.zeros(2))  # the (source, target) moves the maps were last moved by
        self._checked_s = 0.0
        self.log = {"check_s": cfg.video_drift_check_s, "threshold_px": cfg.video_drift_px, "checks": 0,
                    "unclear": 0, "applied": []}

    def moved(self, time_s: float, y_src: np.ndarray, y_tgt: np.ndarray) -> tuple[PlaneMaps, int] | None:
        """At a frame of ``time_s`` with luma planes ``y_src``, ``y_tgt``: the first estimate's maps moved
        by how far the views moved (``drifted_maps``) where that differs from the last move by more than
        ``video_drift_px``, and the frames to blend them in over (the source side moving at most
        ``video_drift_speed_px`` a frame); else None."""
        if self._watch is None:
            if time_s + 1e-6 >= self._from_s:
                boxes = overlap_boxes(self._base, y_src.shape, y_tgt.shape)
                self._watch, self._checked_s = DriftWatch(y_src, y_tgt, boxes), time_s
            return None
        if time_s - self._checked_s < self._cfg.video_drift_check_s - 1e-6:
            return None
        self._checked_s = time_s
        self.log["checks"] += 1
        shifts = self._watch.shifts(y_src, y_tgt)
        if shifts is None:
            self.log["unclear"] += 1
            return None
        change = max(float(np.hypot(*(now - last))) for now, last in zip(shifts, self._applied))
        if change <= self._cfg.video_drift_px:
            return None
        self._applied = shifts
        self.log["applied"].append({"time_s": round(time_s, 4), "source_px": np.round(shifts[0], 2).tolist(),
                                    "target_px": np.round(shifts[1], 2).tolist()})
        frames = int(np.ceil(change / self._cfg.video_drift_speed_px))
        return drifted_maps(self._base, *shifts), frames


@dataclass(frozen=True)
class Canvas:
    """The video's fixed canvas as estimates are expressed on it: (H, W) ``shape``, the target's offset
    ``offset_tgt`` (x, y) on it, the per-frame seam's ``band_px``, and the ``rig`` (roles, orientation)."""

    shape: tuple[int, int]
    offset_tgt: np.ndarray
    band_px: int
    rig: Rig


class Reestimates:
    """A moving rig's re-estimates: one is due every ``cfg.video_reestimate_s``; it runs on a worker
    thread (on the loop's with ``video_estimate_workers`` 0) and is collected once the loop reaches the
    frame it was made on. ``log``: the report's ``reestimations``; ``seconds``: their time."""

    def __init__(self, canvas: Canvas, first_inliers: int, lookahead_frames: int, cfg: Config):
        self._cfg = cfg
        self._canvas = canvas
        self._first_inliers = first_inliers
        self._workers = ThreadPoolExecutor(cfg.video_estimate_workers, thread_name_prefix="estimate") \
            if cfg.video_estimate_workers > 0 else None
        self.lookahead_frames = lookahead_frames if self._workers else 0
        self._pending: deque[tuple[float, Future]] = deque()  # started re-estimates (frame time, job), oldest first
        self._last_s: float | None = None  # the time of the frame the last one was made on
        self.seconds = 0.0
        # "applied": per accepted estimate, the time of the frame it was made on and of the frame whose
        # compositing it started to blend into (the same with a timely look-ahead).
        self.log = {"attempted": 0, "accepted": 0, "rejected": 0, "rejections": [], "applied": []}

    def due(self, time_s: float) -> bool:
        if self._last_s is None:  # the first estimate was made on the video's first pairs
            self._last_s = time_s
        return time_s - self._last_s >= self._cfg.video_reestimate_s

    def idle(self) -> bool:
        """No re-estimate is running (those done may still wait for their frame)."""
        return all(job.done() for _, job in self._pending)

    def waiting(self) -> bool:
        return bool(self._pending)

    def reached(self, time_s: float) -> bool:
        """Whether the oldest re-estimate is done and its frame (at or before ``time_s``) reached."""
        return bool(self._pending) and self._pending[0][1].done() and self._pending[0][0] <= time_s + 1e-6

    def submit(self, frame_l: YuvFrame, frame_r: YuvFrame, current: Callable[[], PlaneMaps],
               prior_seam_tgt: np.ndarray) -> None:
        """Start a re-estimate on a pair; ``current``: the maps in use when it is judged; ``prior_seam_tgt``:
        the seam it should stay near (``stitch.estimate_maps``'s ``prior_seam_tgt``)."""
        self._last_s = float(frame_l.time_s)
        self.log["attempted"] += 1
        if self._workers is not None:
            job = self._workers.submit(self._estimate, frame_l, frame_r, current, prior_seam_tgt)
        else:  # no worker: on the loop's thread, a frame waits for it (reproducible, for tests and batch runs)
            job = Future()
            job.set_result(self._estimate(frame_l, frame_r, current, prior_seam_tgt))
        self._pending.append((self._last_s, job))

    def _estimate(self, frame_l: YuvFrame, frame_r: YuvFrame, current: Callable[[], PlaneMaps],
                  prior: np.ndarray) -> tuple[PlaneMaps | None, str | None]:
        """On a worker thread (its own stream): a re-estimate on the fixed canvas, or why it is rejected.
        Same roles as the first estimate: the target stays the unwarped view on the fixed canvas."""
        t0 = time.perf_counter()
        canvas, cfg = self._canvas, self._cfg
        shape_src, shape_tgt = (f.y.shape for f in canvas.rig.pick(frame_l, frame_r))
        try:
            with own_stream(cfg.device):
                estimate = estimate_pair(frame_l, frame_r, cfg, canvas.rig.target, prior_seam_tgt=prior)
            if estimate.rig.vertical != canvas.rig.vertical:
                return None, "rig orientation changed"
            candidate = maps_on_canvas(estimate, canvas.shape, canvas.offset_tgt, canvas.band_px)
            reason = rejection_reason(candidate, current(), self._first_inliers, shape_src, shape_tgt, cfg)
            return (candidate, None) if reason is None else (None, reason)
        except StitchError as exc:
            return None, str(exc)
        finally:
            self.seconds += time.perf_counter() - t0

    def collect(self, time_s: float) -> tuple[float, PlaneMaps | None]:
        """The oldest re-estimate, whose frame is reached at the frame of ``time_s``: (the time of the
        frame it was made on, its maps, or None where it is rejected)."""
        made_s, job = self._pending.popleft()
        candidate, reason = job.result()
        if reason is not None:
            self.log["rejected"] += 1
            self.log["rejections"].append({"time_s": round(made_s, 4), "reason": reason})
            return made_s, None
        self.log["accepted"] += 1
        self.log["applied"].append({"made_on_s": round(made_s, 4), "at_s": round(time_s, 4)})
        return made_s, candidate

    def close(self) -> None:
        """Stop the worker (a pending estimate is dropped)."""
        if self._workers is not None:
            self._workers.shutdown(wait=True, cancel_futures=True)


class MapsTimeline:
    """The maps of each frame in turn (module docstring): ``maps`` those of the frame last advanced to;
    ``drift`` (a static rig's, or None) and ``reestimates`` (a moving rig's, or None) say when they move."""

    def __init__(self, first: PlaneMaps, drift: DriftCheck | None, reestimates: Reestimates | None, cfg: Config):
        self._cfg = cfg
        self.maps = first
        self.drift = drift
        self.reestimates = reestimates
        self._blend: Blend | None = None

    @property
    def lookahead_frames(self) -> int:
        return self.reestimates.lookahead_frames if self.reestimates is not None else 0

    def look_ahead(self, frame_l: YuvFrame, frame_r: YuvFrame, prior_seam_tgt: Callable[[], np.ndarray]) -> None:
        """A pair ``lookahead_frames`` before it is composited: a re-estimate that is due starts on it,
        so that it is ready when the loop reaches that frame (the maps of a frame still come from that
        frame and earlier ones only)."""
        estimates = self.reestimates
        if self.lookahead_frames and estimates.idle() and estimates.due(float(frame_l.time_s)):
            estimates.submit(frame_l, frame_r, lambda: self.maps, prior_seam_tgt())

    def advance(self, frame_l: YuvFrame, frame_r: YuvFrame, y_src: np.ndarray, y_tgt: np.ndarray,
                prior_seam_tgt: Callable[[], np.ndarray]) -> PlaneMaps:
        """The maps of the next frame pair (``y_src``, ``y_tgt``: its luma planes as source and target):
        start, collect or blend in a re-estimate, or a drift move. A re-estimate made on a later frame
        (``look_ahead``) waits for the loop to reach that frame; one that is reached while the last is
        still being blended in takes over from the maps of the moment (else a rig that keeps moving falls
        further behind with every long blend). ``prior_seam_tgt``: the seam a re-estimate should stay
        near, asked for when one starts."""
        time_s = float(frame_l.time_s)
        estimates = self.reestimates
        if estimates is not None and estimates.reached(time_s):
            _, candidate = estimates.collect(time_s)
            if candidate is not None:  # an accepted one starts its blend on this frame
                self._blend_in(candidate)
                return self.maps
        if self._blend is not None:
            self._step()
        elif self.drift is not None and (moved := self.drift.moved(time_s, y_src, y_tgt)) is not None:
            self._blend_to(*moved)
        elif estimates is not None and not self.lookahead_frames and not estimates.waiting() and estimates.due(time_s):
            estimates.submit(frame_l, frame_r, lambda: self.maps, prior_seam_tgt())
        return self.maps

    def _blend_in(self, candidate: PlaneMaps) -> None:
        """An accepted re-estimate: blended in towards ``video_warp_follow`` of the way to it."""
        cfg = self._cfg
        # The target maps are the fixed canvas's own, the same values in every estimate: shared, a blend
        # keeps them as they are instead of mixing equal arrays.
        candidate = replace(candidate, map_tgt_luma=self.maps.map_tgt_luma, map_tgt_chroma=self.maps.map_tgt_chroma)
        # The rig's own geometry changes slowly; what differs from one estimate to the next is mostly
        # estimation noise, which an exponential average over the accepted estimates takes out.
        goal = lerp_maps(self.maps, candidate, cfg.video_warp_follow)
        # Over video_blend_frames at least, and slowly enough that the seam moves at most
        # video_seam_speed_px a frame.
        seam_move = float(np.nanmax(np.abs(goal.seam_luma.positions - self.maps.seam_luma.positions)))
        self._blend_to(goal, max(cfg.video_blend_frames, int(np.ceil(seam_move / cfg.video_seam_speed_px))))

    def _blend_to(self, goal: PlaneMaps, frames: int) -> None:
        """Start blending from the maps of the moment to ``goal`` over ``frames`` frames (at least one)."""
        self._blend = None  # the blend under way, if any, let go before the next one holds its differences
        self._blend = Blend(MapsBlend(self.maps, goal), 0, max(1, frames))
        self._step()

    def _step(self) -> None:
        self.maps, self._blend = self._blend.step()

    def close(self) -> None:
        if self.reestimates is not None:
            self.reestimates.close()


def lookahead_frames(fps: float, pair_mib: float, cfg: Config) -> int:
    """How many frames ahead a worker's re-estimates start: ``video_estimate_lookahead_s``, within
    ``video_estimate_lookahead_mib`` of held pairs of ``pair_mib`` each."""
    held_pairs = int(cfg.video_estimate_lookahead_mib / pair_mib)
    return min(int(math.ceil(cfg.video_estimate_lookahead_s * fps)), held_pairs)
