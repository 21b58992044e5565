"""Estimating a video's maps: the best of the first frame pairs, and checks on later re-estimates.

The first estimate fixes the output canvas for the whole video, so it is taken from the pair with
the most global-affine inliers among a few of the first pairs (a blurred or dark first frame is
common). Re-estimates of a moving rig are judged against the maps in use before they are blended in.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from fractions import Fraction
from itertools import chain
from operator import attrgetter

import numpy as np

from ..config import Config
from ..errors import InputError, StitchError, VideoError
from ..features import Matches, match_images
from ..global_affine import fit_global_affine
from ..rig import detect_rig, matches_to_working
from ..stitch import StitchMaps, estimate_maps
from ..xfeat import working_size
from .maps import PlaneMaps, map_change_px
from .pairing import pair_by_time
from .reader import FrameReader, YuvFrame, probe_video, span_of
from .still_matches import judged_models, models_in_turn, without_models
from .working import prior_to_small, scaled_up, shrunk_pair, small_matches, working_scale

MEDIAN_PERCENTILE = 50.0  # the rejection test compares the median map change
FAILED_SCREENING = -1  # the rank of a pair whose screening failed: after every screened one


@dataclass(frozen=True)
class Attempt:
    """One estimation try: its pair index and left time, and inliers or the error's message."""

    pair: int
    time_s: float
    inliers: int | None
    error: str | None
    moving_left_out: int = 0  # matches on something that moved, left out (``still_matches.py``)
    leading_recur: float | None = None  # the share of step 1's inliers found again in the other pairs (``PairModels``)
    background: bool = False  # a still background found among its matches (``PairModels``)

    def as_dict(self) -> dict:
        return {"pair": self.pair, "time_s": round(self.time_s, 4), "inliers": self.inliers, "error": self.error,
                "moving_left_out": self.moving_left_out,
                "leading_recur": None if self.leading_recur is None else round(self.leading_recur, 3),
                "background": self.background}


def moving_in_front(attempts: list[Attempt], pair: int, cfg: Config) -> bool:
    """Whether the estimate of ``pair`` aligned something that moves in front of a still background: its
    step 1's inliers are not found again (at most ``video_moving_recur`` of them, as a moving model's),
    while the first pairs show a still background (``still_matches.py``); a rig that moves has none."""
    chosen = next((a for a in attempts if a.pair == pair), None)
    return (chosen is not None and chosen.leading_recur is not None and chosen.leading_recur <= cfg.video_moving_recur
            and any(a.background for a in attempts))


def spaced_span(cfg: Config) -> int:
    """How many pairs :func:`spaced_pairs` takes, at most."""
    return (cfg.video_estimate_pairs - 1) * cfg.video_estimate_spacing + 1


def spaced_pairs(pairs: Iterable[tuple[YuvFrame, YuvFrame]], cfg: Config) -> Iterator[tuple[int, YuvFrame, YuvFrame]]:
    """Pairs 0, s, 2s, ... of ``pairs`` (``cfg.video_estimate_pairs`` of them, s =
    ``cfg.video_estimate_spacing``), as (pair index, left, right); each as soon as it is there, so the
    caller works on one while the decoders go on to the next. The pairs in between are taken too, and
    no pair after the last one yielded (:func:`spaced_span` in all)."""
    for i, (frame_l, frame_r) in zip(range(spaced_span(cfg)), pairs):  # the range ends first
        if i % cfg.video_estimate_spacing == 0:
            yield i, frame_l, frame_r


@contextmanager
def paired_frames(left: str | os.PathLike, right: str | os.PathLike, offset_s: float, cfg: Config
                  ) -> Iterator[Iterator[tuple[YuvFrame, YuvFrame]]]:
    """Two videos' frames, decoded and paired by time exactly as the main loop pairs them (over the span
    ``cfg.video_start_s`` to ``video_end_s``), on decoders of their own (closed on leaving)."""
    right_period_s = 1 / probe_video(right).fps
    with FrameReader(left, Fraction(0), cfg.video_queue_frames, cfg.cpu_threads,
                     span_s=span_of(cfg.video_start_s, cfg.video_end_s)) as reader_l, \
            FrameReader(right, Fraction(str(offset_s)), cfg.video_queue_frames, cfg.cpu_threads,
                        span_s=span_of(cfg.video_start_s, cfg.video_end_s, right_period_s)) as reader_r:
        yield pair_by_time(reader_l, reader_r, right_period_s, attrgetter("time_s"))


def first_pairs(left: str | os.PathLike, right: str | os.PathLike, offset_s: float, cfg: Config
                ) -> Iterator[tuple[int, YuvFrame, YuvFrame]]:
    """:func:`spaced_pairs` of two videos' :func:`paired_frames` (a frame loop hands its own pairs to
    :func:`spaced_pairs` instead, and composites them after)."""
    with paired_frames(left, right, offset_s, cfg) as pairs:
        yield from spaced_pairs(pairs, cfg)


def estimate_pair(frame_l: YuvFrame, frame_r: YuvFrame, cfg: Config, reference: str,
                  matches: Matches | None = None, prior_seam_tgt=None) -> StitchMaps:
    """SENA maps for one frame pair (left = input a); the BGR conversion happens only here, not per frame.
    Frames larger than ``cfg.video_estimate_max_side`` are estimated made that small, and the maps
    scaled up to them (``working.py``). ``matches`` of the full frames; ``prior_seam_tgt``: the seam
    to stay near (``stitch.estimate_maps``), full target pixels."""
    bgr = frame_l.to_bgr(), frame_r.to_bgr()
    scale = working_scale((frame_l.y.shape, frame_r.y.shape), cfg.video_estimate_max_side)
    if scale == 1.0:
        return estimate_maps(*bgr, cfg, reference, matches, prior_seam_tgt)
    small, scales = shrunk_pair(bgr, scale)
    maps = estimate_maps(*small, cfg, reference, small_matches(matches, *scales), prior_to_small(prior_seam_tgt, scale))
    scale_src, scale_tgt = maps.rig.pick(*scales)
    return scaled_up(maps, scale_src, scale_tgt, maps.rig.pick(*bgr)[1].shape[:2], cfg)


def screening_config(cfg: Config, shapes: tuple[tuple[int, int], ...]) -> Config:
    """The settings frames of (rows, cols) ``shapes`` are screened with: XFeat at a long side of
    ``cfg.video_screen_max_side`` at most, where XFeat can take them that small. The ranking needs inlier
    counts, not the estimate's precision; at 1080p it costs two thirds as much."""
    if cfg.features != "xfeat":
        return cfg
    side = min(cfg.xfeat_max_side, cfg.video_screen_max_side)
    try:
        for shape in shapes:
            working_size(shape, side)
    except InputError:
        return cfg
    return replace(cfg, xfeat_max_side=side)


def screened_at_full_resolution(frame_l: YuvFrame, frame_r: YuvFrame, cfg: Config) -> bool:
    """Whether screening ``frame_l``, ``frame_r`` sees them as the full estimate does (its matches serve it)."""
    shapes = (frame_l.y.shape, frame_r.y.shape)
    side = screening_config(cfg, shapes).xfeat_max_side
    return cfg.features != "xfeat" or all(working_size(shape, side) == working_size(shape, cfg.xfeat_max_side)
                                          for shape in shapes)


def screen_pair(frame_l: YuvFrame, frame_r: YuvFrame, cfg: Config, reference: str) -> tuple[Matches, int]:
    """Steps 0-1 only, with :func:`screening_config`: the pair's matches and its global-affine inlier
    count (raises StitchError)."""
    screen = screening_config(cfg, (frame_l.y.shape, frame_r.y.shape))
    matches = match_images(frame_l.to_bgr(), frame_r.to_bgr(), screen)
    return matches, inlier_count(matches, frame_l.y.shape, screen, reference)


def inlier_count(matches: Matches, shape_l: tuple[int, int], cfg: Config, reference: str) -> int:
    """The global-affine inlier count of a pair's ``matches`` (left frame of (rows, cols) ``shape_l``)."""
    rig = detect_rig(matches.pts_a, matches.pts_b, shape_l, reference)
    pts_src, pts_tgt = matches_to_working(matches.pts_a, matches.pts_b, rig)
    return fit_global_affine(pts_src, pts_tgt, cfg).n_inliers


def screening_px(frame_l: YuvFrame, frame_r: YuvFrame, cfg: Config) -> float:
    """How many input pixels one pixel of the screening's XFeat covers (1 at full resolution)."""
    shapes = (frame_l.y.shape, frame_r.y.shape)
    side = screening_config(cfg, shapes).xfeat_max_side
    return max(1.0, max(max(shape) for shape in shapes) / side)


@dataclass(frozen=True)
class PairModels:
    """What moves among a first pair's matches (``still_matches.py``): ``moving`` the models that move and
    lead a still background (empty where none do, or none follows), whether that ``background`` was
    found, and ``leading_recur``, the share of step 1's model's inliers found again in the other pairs
    (None: no model)."""

    moving: list[np.ndarray]
    background: bool
    leading_recur: float | None


def pair_models(screened: list[tuple[int, int, YuvFrame, YuvFrame, Matches | None]], cfg: Config
                ) -> list[PairModels]:
    """Per screened pair (inliers, index, left, right, matches): its :class:`PairModels`, against the
    other pairs' matches."""
    all_matches = [s[4] for s in screened if s[4] is not None]
    found = []
    for _, _, frame_l, frame_r, matches in screened:
        if matches is None:
            found.append(PairModels([], False, None))
            continue
        tol_px = cfg.video_recur_px * screening_px(frame_l, frame_r, cfg)
        turns = models_in_turn(matches, [m for m in all_matches if m is not matches], tol_px, cfg)
        leading = next(turns, None)
        moving, background = judged_models(chain([leading], turns) if leading is not None else [], cfg)
        found.append(PairModels(moving, background, None if leading is None else leading[1]))
    return found


def without_moving(screened: list[tuple[int, int, YuvFrame, YuvFrame, Matches | None]], judged: list[PairModels],
                   cfg: Config, reference: str
                   ) -> tuple[list[tuple[int, int, YuvFrame, YuvFrame, Matches | None]], dict[int, list[np.ndarray]],
                              set[int]]:
    """The screened pairs (inliers, index, left, right, matches) with the matches on what moves left out
    where a still background follows them (``judged``: their :func:`pair_models`), their inliers
    counted again; per pair index the moving models left out (a -> b affines, input pixels); and the
    pairs whose background was found (first or after what moves)."""
    kept, moving, background = [], {}, set()
    for (inliers, index, frame_l, frame_r, matches), models_of in zip(screened, judged):
        px = screening_px(frame_l, frame_r, cfg)
        models, found = models_of.moving, models_of.background
        if models:
            still = without_models(matches, models, cfg.ransac_reproj_px * px)
            try:
                inliers = inlier_count(still, frame_l.y.shape, cfg, reference)
                matches, moving[index] = still, models
            except StitchError:  # the background alone is too little to stitch from: as it was
                found = False
        if found:
            background.add(index)
        kept.append((inliers, index, frame_l, frame_r, matches))
    return kept, moving, background


def best_first_estimate(first: Iterable[tuple[int, YuvFrame, YuvFrame]], cfg: Config,
                        reference: str) -> tuple[StitchMaps, int, list[Attempt]]:
    """The estimate with the most inliers among ``first`` (:func:`spaced_pairs`: pair index, left,
    right); (maps, its pair index, all attempts).

    Every pair is screened by steps 0-1 (:func:`screen_pair`: the inlier count is what ranks them); the
    full estimate, ten times dearer (the gate and the seam work over the whole canvas), runs on the best
    pair only, or on the next best if that one fails later on; pairs whose screening at a lower
    resolution failed come last (the full resolution may find the matches it lacked: a video whose
    first pairs all fail so pays for a full try of each before its error). When all fail, the last
    failure is raised. Each attempt gives its screening's inliers, or its full estimate's where that
    was all it had.
    """
    attempts: list[Attempt] = []
    screened: list[tuple[int, int, YuvFrame, YuvFrame, Matches | None]] = []
    last_error: StitchError | None = None
    tried = []
    for index, frame_l, frame_r in first:  # screened while the next decodes
        tried.append((index, frame_l, frame_r))
        try:
            matches, inliers = screen_pair(frame_l, frame_r, cfg, reference)
        except StitchError as exc:
            last_error = exc
            attempts.append(Attempt(index, float(frame_l.time_s), None, str(exc)))
            if not screened_at_full_resolution(frame_l, frame_r, cfg):
                screened.append((FAILED_SCREENING, index, frame_l, frame_r, None))
            continue
        screened.append((inliers, index, frame_l, frame_r, matches))
    judged = pair_models(screened, cfg)
    still, moving, background = without_moving(screened, judged, cfg, reference) if cfg.video_still_background else (
        screened, {}, set())
    attempts += [Attempt(index, float(frame_l.time_s), inliers, None, len(before[4]) - len(matches),
                         models_of.leading_recur, models_of.background)
                 for before, (inliers, index, frame_l, _, matches), models_of in zip(screened, still, judged)
                 if matches is not None]
    attempts.sort(key=attrgetter("pair"))
    # Most inliers first; among equals the earliest pair. Where something moved in front of a still
    # background, the pairs whose inliers are that background come first.
    for inliers, index, frame_l, frame_r, matches in sorted(still, key=lambda s: (bool(moving) and s[1] not in background,
                                                                                   -s[0], s[1])):
        if not screened_at_full_resolution(frame_l, frame_r, cfg):
            matches = None if index not in moving else without_models(
                match_images(frame_l.to_bgr(), frame_r.to_bgr(), cfg), moving[index],
                cfg.ransac_reproj_px * screening_px(frame_l, frame_r, cfg))
        try:
            maps = estimate_pair(frame_l, frame_r, cfg, reference, matches)
            if inliers == FAILED_SCREENING:  # what the report gives is the full estimate's
                attempts = [replace(a, inliers=maps.warp.glob.n_inliers, error=None) if a.pair == index else a
                            for a in attempts]
            return maps, index, attempts
        except StitchError as exc:
            last_error = exc
            attempts = [replace(a, error=str(exc)) if a.pair == index else a for a in attempts]
    if last_error is None:
        raise VideoError("no frame pairs to estimate the stitch from")
    raise type(last_error)(no_estimate_message(tried, last_error, cfg)) from last_error


def no_estimate_message(tried: list[tuple[int, YuvFrame, YuvFrame]], error: StitchError, cfg: Config) -> str:
    """Why none of the ``tried`` (pair index, left, right) frame pairs gave a stitch, in one line: which
    times were tried, inputs whose frames there are blank or whose resolutions differ, the last error."""
    times = ", ".join(f"{float(fl.time_s):.2f}" for _, fl, _ in tried)
    parts = [f"no stitch found on the first frame pairs (left frames at {times} s)"]
    for side, frames in (("left", [fl for _, fl, _ in tried]), ("right", [fr for _, _, fr in tried])):
        if all(float(f.y.std()) < cfg.video_blank_max_std for f in frames):
            parts.append(f"the {side} frames there are blank (black or flat): trim the blank start of that video")
    size_l, size_r = (f"{f.y.shape[1]}x{f.y.shape[0]}" for f in tried[0][1:])
    if size_l != size_r:
        parts.append(f"the inputs' resolutions differ (left {size_l}, right {size_r}): check that they are the "
                     f"two views of one rig")
    return "; ".join(parts) + f"; the last try said: {error}"


def rejection_reason(candidate: PlaneMaps, current: PlaneMaps, first_inliers: int,
                     shape_src: tuple[int, int], shape_tgt: tuple[int, int], cfg: Config) -> str | None:
    """Why a re-estimate is implausible, or None to accept it.

    Too few inliers against the first estimate, or a median source-map change over the overlap
    (pixels sampling both planes, ``shape_*`` = (rows, cols) of the Y planes) above the threshold:
    a rig moves little between two re-estimations, a wrong match set moves the map a lot.
    """
    if candidate.inliers < cfg.video_min_inlier_ratio * first_inliers:
        return f"{candidate.inliers} inliers < {cfg.video_min_inlier_ratio} x {first_inliers} of the first estimate"
    median_px = map_change_px(current, candidate, shape_src, MEDIAN_PERCENTILE, shape_tgt)
    if median_px > cfg.video_max_median_change_px:
        return f"median map change {median_px:.1f} px > {cfg.video_max_median_change_px} px"
    return None
