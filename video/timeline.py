"""Which maps each frame of a video is composited with: the maps timeline.

The first estimate gives the maps of the first frames. After that the maps of frame t come from
frame t and earlier ones only, by the plan of the moment (``mode``):

- a static rig's maps follow a camera that drifts (:class:`DriftCheck`, ``drift.py``): every
  ``video_drift_check_s`` the views are compared with the first estimate's, and a move larger than
  ``video_drift_px`` is blended in (the source side at most ``video_drift_speed_px`` a frame,
  :class:`Blend`);
- a moving rig's source map is aligned to every frame (``moving.py``, ``align.py``), and so is a
  fixed rig's whose first estimate aligned something moving in front of a still background (a person
  close to both cameras holds most matches: the seam runs through him, and only an alignment made on
  each frame keeps him whole there; ``video_align_in_front``, off: the room beside him then moves with
  him, docs/evaluation.md): the key
  estimate's plus a correction measured on the frame. When the alignment falls behind, a full
  re-estimate is made, at most every ``video_reestimate_s`` (:class:`Reestimates`), on a worker thread
  with a CUDA stream of its own (on the loop's thread with ``video_estimate_workers`` 0:
  deterministic), a look-ahead ahead so that an estimate lands on its own frame; an implausible one
  is rejected; an accepted one becomes the key without a jump.

With ``--rig auto`` (:class:`~sena_warp.video.rig_motion.RigMotion`) the rig's motion is watched on the
looked-ahead pairs from the first second on; each decision takes effect on its frame (the first on
the first frame), is said in one line on stderr (hidden by ``-q``) and logged (``decisions``).

:meth:`MapsTimeline.advance` answers for each frame in turn with a :class:`~sena_warp.video.maps.PlaneMaps`
value: the same object for as long as the maps do not change, so whatever is made from it (a
compositing plan) is made once per map set. What happened is logged for the report (``log``).
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from ..config import Config
from ..errors import StitchError, VideoError
from ..progress import LOGGER
from ..rig import Rig
from sena_warp.kernels.transfer import own_stream
from .align import Seam
from .drift import DriftWatch, overlap_boxes
from .estimate import estimate_pair, rejection_reason
from .maps import MapsBlend, PlaneMaps, canvas_scale, drifted_maps, maps_on_canvas
from .moving import MovingRig
from .reader import YuvFrame
from .rig_motion import WINDOW_S, RigDecision, RigMotion


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
    estimate's pair (at ``from_s``) on: ``base`` (the first estimate's maps, on an output ``scale``
    (x, y) output pixels per canvas pixel) moved by how far the views moved. ``log``: what the checks
    found (the report's ``drift``)."""

    def __init__(self, base: PlaneMaps, from_s: float, scale: np.ndarray, cfg: Config):
        self._cfg = cfg
        self._base = base
        self._scale = scale
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
        return drifted_maps(self._base, *shifts, self._scale), frames


@dataclass(frozen=True)
class Canvas:
    """The video's fixed canvas as estimates are expressed on it: (H, W) ``stitched_shape``, the target's
    offset ``offset_tgt`` (x, y) on it, and the ``rig`` (roles, orientation); the output it is scaled
    to, (H, W) ``shape`` (``video_max_width``: the maps themselves are scaled, ``maps.scaled_plane_maps``),
    and the per-frame seam's ``band_px`` there."""

    stitched_shape: tuple[int, int]
    shape: tuple[int, int]
    offset_tgt: np.ndarray
    band_px: int
    rig: Rig

    @property
    def scale(self) -> np.ndarray:
        """(sx, sy): output pixels per canvas pixel."""
        return canvas_scale(self.stitched_shape, self.shape)


class Reestimates:
    """A moving rig's re-estimates: one may be due every ``cfg.video_reestimate_s``; it runs on a worker
    thread (on the loop's with ``video_estimate_workers`` 0) and is collected once the loop reaches the
    frame it was made on. ``log``: the report's ``reestimations``; ``seconds``: their time."""

    def __init__(self, canvas: Canvas, first_inliers: int, lookahead_frames: int, cfg: Config):
        self._cfg = cfg
        self._canvas = canvas
        self._first_inliers = first_inliers
        self._workers = ThreadPoolExecutor(cfg.video_estimate_workers, thread_name_prefix="estimate") \
            if cfg.video_estimate_workers > 0 else None
        self.lookahead_frames = lookahead_frames if self._workers else 0
        # Beside the frame loop a re-estimate takes one thread (XFeat's, the kernels' bands): the loop has the
        # others, and more threads on the same cores cost more CPU than they save; its look-ahead waits for it.
        self._estimate_cfg = cfg.replace(cpu_threads=1) if self._workers else cfg
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

    def restart(self, time_s: float) -> None:
        """The rig starts moving at ``time_s``: estimates under way are not waited for, and the period
        counts from now."""
        self._pending.clear()
        self._last_s = time_s

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
        canvas, cfg = self._canvas, self._estimate_cfg
        shape_src, shape_tgt = (f.y.shape for f in canvas.rig.pick(frame_l, frame_r))
        try:
            with own_stream(cfg.device):
                estimate = estimate_pair(frame_l, frame_r, cfg, canvas.rig.target, prior_seam_tgt=prior)
            if estimate.rig.vertical != canvas.rig.vertical:
                return None, "rig orientation changed"
            # Under --rig auto the key may be kept by a static plan later: its overlap is kept too.
            candidate = maps_on_canvas(estimate, canvas.stitched_shape, canvas.offset_tgt, canvas.band_px, canvas.shape,
                                       (shape_src, shape_tgt), cfg.video_rig == "auto", cfg)
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


@dataclass(frozen=True)
class LastFrame:
    """What a moving rig's alignment takes from the frame composited last: its luma ``gains`` (gain, bias
    of the source; of the target) and its ``seam`` (None before the first frame)."""

    gains: tuple[float, float, float, float]
    seam: Seam | None


class MapsTimeline:
    """The maps of each frame in turn (module docstring): ``maps`` those of the frame last advanced to;
    ``mode`` ("static" / "moving") the plan they follow; ``drift`` (a static rig's, or None),
    ``reestimates`` (a rig that may move, or None) and ``moving`` (the alignment of a moving rig, or of
    a rig aligned ``in_front``, made on its first frame) say how they move; ``watch``: ``--rig auto``'s,
    or None. ``first_s``: the time of the first estimate's pair (a static rig's drift is measured from
    there). ``in_front``: the first estimate aligned something that moves in front of a still
    background (``estimate.moving_in_front``, ``video_align_in_front``): its maps are aligned to every
    frame as a moving rig's are, whatever the rig does, its canvas held while the rig is static."""

    def __init__(self, first: PlaneMaps, mode: str, first_s: float, canvas: Canvas,
                 reestimates: Reestimates | None, watch: RigMotion | None, watch_frames: int, cfg: Config,
                 in_front: bool = False):
        self._cfg = cfg
        self._canvas = canvas
        self.maps = first
        self.mode = mode
        self.reestimates = reestimates
        self.moving: MovingRig | None = None
        self.watch = watch
        self._watch_frames = watch_frames if watch is not None else 0
        self._decisions: deque[RigDecision] = deque()  # the watch's decisions not yet applied, oldest first
        self.decisions: list[dict] = []  # each applied, with the time of the frame it took effect on
        if mode == "moving" and not self._aligns:
            raise VideoError("--rig moving aligns every frame at the stitched size; drop --max-width "
                             f"(the stitched video is {canvas.stitched_shape[1]} px wide) or use --rig static")
        self.in_front = in_front and self._aligns and reestimates is not None
        self.drift = self._drift_check(first, first_s) if mode == "static" and not self.in_front else None
        self._alignments: list[dict] = []  # the alignment logs of the moving stretches that ended
        self._blend: Blend | None = None
        self.align_seconds = 0.0

    @property
    def _aligns(self) -> bool:
        """Whether frames can be aligned: the alignment works on the stitched canvas, the target pasted 1:1,
        not on an output scaled down."""
        return bool(np.allclose(self._canvas.scale, 1.0))

    @property
    def aligned(self) -> bool:
        """Whether the maps are aligned to every frame (a moving rig, or one aligned ``in_front``)."""
        return self.mode == "moving" or self.in_front

    def _drift_check(self, base: PlaneMaps, from_s: float) -> DriftCheck | None:
        return DriftCheck(base, from_s, self._canvas.scale, self._cfg) if self._cfg.video_drift_check_s > 0 else None

    @property
    def lookahead_frames(self) -> int:
        """How far ahead pairs are shown to :meth:`look_ahead`: a worker's re-estimates', the watch's."""
        estimates = self.reestimates.lookahead_frames if self.reestimates is not None else 0
        return max(estimates, self._watch_frames)

    def _due(self, time_s: float) -> bool:
        """A re-estimate is due: a moving rig whose alignment asks for one, ``video_reestimate_s`` after the last."""
        return (self.aligned and self.moving is not None and self.moving.wants_estimate()
                and self.reestimates.due(time_s))

    def look_ahead(self, frame_l: YuvFrame, frame_r: YuvFrame, prior_seam_tgt: Callable[[], np.ndarray]) -> None:
        """A pair ``lookahead_frames`` before it is composited: the watch sees it, and a re-estimate that
        is due starts on it, so that it is ready when the loop reaches that frame (the maps of a frame
        still come from that frame and earlier ones only)."""
        time_s = float(frame_l.time_s)
        if self.watch is not None and (decision := self.watch.observe(time_s, frame_l.y, frame_r.y)) is not None:
            self._decisions.append(decision)
        estimates = self.reestimates
        if estimates is not None and estimates.lookahead_frames and estimates.idle() and self._due(time_s):
            estimates.submit(frame_l, frame_r, lambda: self.maps, prior_seam_tgt())

    def advance(self, frame_l: YuvFrame, frame_r: YuvFrame, y_src: np.ndarray, y_tgt: np.ndarray,
                prior_seam_tgt: Callable[[], np.ndarray], last: LastFrame) -> PlaneMaps:
        """The maps of the next frame pair (``y_src``, ``y_tgt``: its luma planes as source and target):
        the watch's decisions that are due take effect; a static rig blends in a drift move; a moving
        rig's maps are aligned to the pair (``last``: the gains and seam of the frame before), after an
        accepted re-estimate became its key. A re-estimate made on a later frame (``look_ahead``) waits
        for the loop to reach that frame. ``prior_seam_tgt``: the seam a re-estimate should stay near,
        asked for when one starts."""
        time_s = float(frame_l.time_s)
        while self._decisions and (not self.decisions or self._decisions[0].time_s <= time_s + 1e-6):
            self._become(self._decisions.popleft(), time_s)
        if self.aligned:
            return self._align(frame_l, frame_r, y_src, y_tgt, prior_seam_tgt, last)
        if self._blend is not None:
            self._step()
        elif self.drift is not None and (moved := self.drift.moved(time_s, y_src, y_tgt)) is not None:
            self._blend_to(*moved)
        return self.maps

    def _align(self, frame_l: YuvFrame, frame_r: YuvFrame, y_src: np.ndarray, y_tgt: np.ndarray,
               prior_seam_tgt: Callable[[], np.ndarray], last: LastFrame) -> PlaneMaps:
        """The maps of the pair aligned to it: a re-estimate collected (an accepted one its new key) or
        started (without a look-ahead), then the key aligned to the pair."""
        time_s = float(frame_l.time_s)
        if self.moving is None:
            self.moving = MovingRig(self.maps, self._canvas.offset_tgt, (y_src.shape, y_tgt.shape), self._cfg)
        estimates = self.reestimates
        if estimates.reached(time_s):
            _, candidate = estimates.collect(time_s)
            if candidate is not None:  # the target maps are the fixed canvas's own, the same in every estimate
                self.moving.rekey(replace(candidate, map_tgt_luma=self.maps.map_tgt_luma,
                                          map_tgt_chroma=self.maps.map_tgt_chroma))
        elif not estimates.lookahead_frames and not estimates.waiting() and self._due(time_s):
            estimates.submit(frame_l, frame_r, lambda: self.maps, prior_seam_tgt())
        t0 = time.perf_counter()
        self.maps = self.moving.frame_maps(y_src, y_tgt, last.gains, last.seam)
        self.align_seconds += time.perf_counter() - t0
        return self.maps

    def _become(self, decision: RigDecision, time_s: float) -> None:
        """``--rig auto``'s ``decision`` takes effect on the frame of ``time_s`` (said in one line, logged):
        a moving rig's maps are aligned from the maps of the moment on; a static rig keeps the maps of
        the moment, moved with the cameras' drift from now on."""
        kept = decision.mode == "moving" and not self._aligns
        said = decision.reason + ("; not aligned every frame at --max-width: the static plan is kept" if kept else "")
        self.decisions.append({**decision.as_dict(), "reason": said, "from_s": round(time_s, 4)})
        # A decision is news, not a fault (-q hides it); a plan that cannot follow the rig is a warning.
        LOGGER.log(logging.WARNING if kept else logging.INFO, "rig: %s%s (%s)", decision.mode,
                   f" from {time_s:.2f} s" if len(self.decisions) > 1 else "", said)
        if decision.mode == self.mode or kept:
            return
        self.mode = decision.mode
        self._blend = None  # a drift's blend stops where it is
        if self.mode == "moving" or self.in_front:  # aligned on: what is in front still moves
            self.drift = None
            self.reestimates.restart(time_s)
            return
        self._alignments.append(self.moving.log)
        self.moving = None
        self.reestimates.restart(time_s)
        self.drift = self._drift_check(self.maps, time_s)

    def copies(self, lines_are_rows: bool) -> tuple[np.ndarray, np.ndarray] | None:
        """An aligned frame: the two copies of each point its warp leaves apart (``MovingRig.copies``);
        None where the maps are not aligned to the frames."""
        return self.moving.copies(lines_are_rows) if self.moving is not None else None

    def alignment_log(self) -> dict | None:
        """The moving stretches' alignment (``MovingRig.log``), all of them together; None if none."""
        logs = self._alignments + ([self.moving.log] if self.moving is not None else [])
        if not logs:
            return None
        frames = sum(log["frames"] for log in logs)
        merged = {"frames": frames, "keys": sum(log["keys"] for log in logs),
                  "seeded": sum(log["seeded"] for log in logs)}
        for name in ("points_mean", "followed_share_mean"):
            merged[name] = round(sum(log[name] * log["frames"] for log in logs) / max(frames, 1), 4)
        return merged

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


def watch_frames(fps: float, pair_mib: float, cfg: Config) -> int:
    """How many frames ahead ``--rig auto``'s watch sees the pairs: its first window, within
    ``video_estimate_lookahead_mib`` of held pairs of ``pair_mib`` each."""
    return min(int(math.ceil(WINDOW_S * fps)), int(cfg.video_estimate_lookahead_mib / pair_mib))


def lookahead_frames(fps: float, pair_mib: float, cfg: Config) -> int:
    """How many frames ahead a worker's re-estimates start: ``video_estimate_lookahead_s``, within
    ``video_estimate_lookahead_mib`` of held pairs of ``pair_mib`` each."""
    held_pairs = int(cfg.video_estimate_lookahead_mib / pair_mib)
    return min(int(math.ceil(cfg.video_estimate_lookahead_s * fps)), held_pairs)
