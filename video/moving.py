"""A moving rig's maps, frame by frame: the key estimate's, aligned to every frame (``align.py``).

The first estimate is the first *key*. Every frame the source map is the key's plus the frame's
correction (:class:`~sena_warp.video.align.FrameAlignment`); the target map never changes (the canvas is
the target's). A new full estimate (made when the alignment asks for one, :meth:`MovingRig.wants_estimate`)
becomes the key without a jump: its correction is refitted so that key plus correction is the map of the
moment, up to what the coarse lattice cannot say, and that remainder fades out over
``video_blend_frames`` frames at least; the seam's home (the band the per-frame seam moves in) moves
from the old key's to the new one's over as many frames, slowly enough that it moves by at most
``video_seam_speed_px`` a frame. Where the new key covers the canvas differently, what it adds is
uncovered from the old coverage outwards and what it drops is let go from the outside in over the same
frames (:class:`CoverFade`): the uncovered area does not jump. The border blend is the key's.

Where the warp cannot follow a point (something near, whose parallax its surroundings do not share),
the point's two copies are apart on the canvas; :meth:`MovingRig.copies` gives them as (line, position)
pairs for the per-frame seam, which keeps them on one side (``frame_seam.separation_band_cost``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from ..config import Config
from .align import Alignment, FrameAlignment, Seam, copies_apart, sample_map
from .maps import PlaneMaps

KEY_GRID_PX = 16  # a new key's correction is fitted to the map of the moment on a grid this fine (canvas px)
POOR_SHARE = 0.5  # the alignment is poor on a frame where fewer of its points than this follow the warp ...
POOR_FRAMES = 10  # ... and asks for a new estimate after this many such frames in a row


@dataclass(frozen=True)
class CoverFade:
    """Where a new key covers the canvas differently from the map of the moment, the change spread over
    its fade instead of shown in one frame: pixels the new key covers first (``appear``) are shown from
    the old coverage outwards, those it no longer covers (``vanish``) keep the map of the moment (less
    the key's correction, ``held``) and are let go from the outside in, each by its distance
    (``appear_px``, ``vanish_px``) to what stays. Each set is held as its flat pixel indices in the order
    of that distance (nearest first), so that a frame's share of it is a slice."""

    appear: np.ndarray
    appear_px: np.ndarray
    vanish: np.ndarray
    vanish_px: np.ndarray
    held: np.ndarray

    @staticmethod
    def of(now: np.ndarray, key: np.ndarray, correction: np.ndarray) -> "CoverFade":
        """For source maps ``now`` and ``key`` (H, W, 2) (NaN: not covered) and the correction (H, W, 2)
        the new key starts with."""
        now_nan, key_nan = np.isnan(now[..., 0]), np.isnan(key[..., 0])

        def by_distance(pixels: np.ndarray, outside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            distance = cv2.distanceTransform(outside.astype(np.uint8), cv2.DIST_L2, 3).ravel()
            index = np.flatnonzero(pixels)
            order = np.argsort(distance[index], kind="stable")
            return index[order], distance[index[order]]

        appear, appear_px = by_distance(now_nan & ~key_nan, now_nan)
        vanish, vanish_px = by_distance(~now_nan & key_nan, key_nan)
        held = (now - correction).astype(np.float32).reshape(-1, 2)[vanish]
        return CoverFade(appear, appear_px, vanish, vanish_px, held)

    def apply(self, map_src: np.ndarray, weight: float) -> None:
        """``map_src`` (H, W, 2), the key's with ``weight`` (1 at the fade's start, 0 at its end) of the
        remainder, in place: what appears is hidden beyond ``1 - weight`` of its reach, what vanishes is
        held within ``weight`` of its reach (C-ordered: changed through its flat view)."""
        if not map_src.flags.c_contiguous:
            raise ValueError("CoverFade.apply changes a C-ordered map in place")
        flat = map_src.reshape(-1, 2)
        if self.appear.size:
            flat[self.appear[np.searchsorted(self.appear_px, (1.0 - weight) * self.appear_px[-1], "right"):]] = np.nan
        if self.vanish.size:
            held = np.searchsorted(self.vanish_px, weight * self.vanish_px[-1], "right")
            flat[self.vanish[:held]] = self.held[:held]


def home_fade(now: PlaneMaps, key: PlaneMaps, frames: int, cfg: Config
              ) -> tuple[np.ndarray, np.ndarray, int, int] | None:
    """The seam home's fade from ``now``'s to ``key``'s: (luma, chroma remainders, frames, frames left), over
    ``frames`` frames at least and slowly enough that the home moves at most ``video_seam_speed_px`` a
    frame; None where there is nothing to fade."""
    seam_luma = (now.seam_luma.positions - key.seam_luma.positions).astype(np.float32)
    seam_chroma = (now.seam_chroma.positions - key.seam_chroma.positions).astype(np.float32)
    frames = max(frames, int(np.ceil(float(np.abs(np.nan_to_num(seam_luma)).max(initial=0.0)) / cfg.video_seam_speed_px)))
    return (seam_luma, seam_chroma, frames, frames) if frames > 0 else None


class MovingRig:
    """The maps of a moving rig's frames (module docstring).

    ``key``: the key estimate's :class:`PlaneMaps` on the fixed canvas, with its seam's home
    (``maps.maps_on_canvas``); ``offset_tgt`` (x, y) whole px the
    target's canvas offset; ``shapes``: (rows, cols) of the source's and the target's Y planes. Each
    frame, :meth:`frame_maps` gives the maps to composite it with; ``alignment`` is its
    :class:`~sena_warp.video.align.Alignment`.
    """

    def __init__(self, key: PlaneMaps, offset_tgt: np.ndarray, shapes: tuple[tuple[int, int], tuple[int, int]],
                 cfg: Config):
        self.cfg = cfg
        self.shapes = shapes
        self.key = key
        self.aligner = FrameAlignment(key.map_src_luma, offset_tgt, shapes, cfg)
        self.alignment: Alignment | None = None
        self.maps = key
        self._chroma_key = key.map_src_chroma
        # A new key's fade: (luma, chroma map remainders, frames, frames left) ...
        self._fade: tuple[np.ndarray, np.ndarray, int, int] | None = None
        self._cover: tuple[CoverFade, CoverFade] | None = None  # ... its coverage's (luma, chroma) ...
        # ... and its seam home's: (luma, chroma remainders, frames, frames left); the first key's from the seam
        # of the maps of the moment (the estimate's) to its own home.
        self._home_fade = home_fade(key, self.key, 0, cfg)
        self._poor_frames = 0
        self.log = {"frames": 0, "keys": 0, "points_mean": 0.0, "followed_share_mean": 0.0, "seeded": 0}

    def frame_maps(self, y_src: np.ndarray, y_tgt: np.ndarray, gains: tuple[float, float, float, float],
                   seam: Seam | None = None) -> PlaneMaps:
        """The maps to composite the frame pair ``y_src``, ``y_tgt`` (Y planes) with; ``gains``: (gain,
        bias) of the source's and the target's luma as composited; ``seam``: the last frame's, where
        the alignment matters most (``FrameAlignment.step``)."""
        key_luma, key_chroma, seam_luma, seam_chroma = self._keys_now()
        self.aligner.key_map = key_luma
        alignment = self.aligner.step(y_src, y_tgt, gains, seam)
        self.alignment = alignment
        chroma_shape = key_chroma.shape[:2]
        # The chroma map of a luma map is its 2x2 block means, halved (``maps.chroma_positions``): the
        # correction's block means are the lattice sampled at the chroma pixels' centres.
        map_chroma = cv2.scaleAdd(self.aligner.correction_field(alignment.lattice, chroma_shape), 0.5, key_chroma)
        self.maps = replace(self.key, map_src_luma=self.aligner.map_src, map_src_chroma=map_chroma,
                            seam_luma=replace(self.key.seam_luma, positions=seam_luma),
                            seam_chroma=replace(self.key.seam_chroma, positions=seam_chroma))
        share = alignment.inlier_share
        self._poor_frames = self._poor_frames + 1 if share < POOR_SHARE else 0
        log = self.log
        log["frames"] += 1
        log["points_mean"] += (len(alignment.pts_canvas) - log["points_mean"]) / log["frames"]
        log["followed_share_mean"] += (share - log["followed_share_mean"]) / log["frames"]
        log["seeded"] += alignment.seeded
        return self.maps

    def _keys_now(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(luma, chroma) key maps and seam homes of this frame: the key's, plus what is left of a new
        key's remainders."""
        key = self.key
        home_luma, home_chroma = key.seam_luma.positions, key.seam_chroma.positions
        if self._home_fade is not None:
            seam_luma, seam_chroma, frames, left = self._home_fade
            weight = np.float32(left / (frames + 1))
            self._home_fade = None if left <= 1 else (*self._home_fade[:3], left - 1)
            home_luma, home_chroma = home_luma + weight * seam_luma, home_chroma + weight * seam_chroma
        if self._fade is None:
            return key.map_src_luma, self._chroma_key, home_luma, home_chroma
        map_luma, map_chroma, frames, left = self._fade
        weight = np.float32(left / (frames + 1))
        self._fade = None if left <= 1 else (*self._fade[:3], left - 1)
        luma, chroma = cv2.scaleAdd(map_luma, weight, key.map_src_luma), cv2.scaleAdd(map_chroma, weight, self._chroma_key)
        for cover, plane in zip(self._cover, (luma, chroma)):
            cover.apply(plane, float(weight))
        if self._fade is None:
            self._cover = None
        return luma, chroma, home_luma, home_chroma

    def wants_estimate(self) -> bool:
        """Whether the alignment has been poor for :data:`POOR_FRAMES` frames in a row (too few of its
        points follow the warp: the scene's depth changed more than the lattice can say)."""
        return self._poor_frames >= POOR_FRAMES

    def rekey(self, key: PlaneMaps) -> None:
        """Make ``key`` (a new estimate on the fixed canvas with its seam's home, its target maps the
        canvas's) the key, from the next frame on, without a jump (module docstring)."""
        now = self.maps
        height, width = key.shape
        rows, cols = np.mgrid[KEY_GRID_PX // 2:height:KEY_GRID_PX, KEY_GRID_PX // 2:width:KEY_GRID_PX]
        pts = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
        difference = sample_map(now.map_src_luma, pts) - sample_map(key.map_src_luma, pts)
        known = np.isfinite(difference).all(axis=1)
        fit = self.aligner.fit
        lattice, _, _ = fit.fit(pts[known], difference[known], np.asarray(self.aligner.filter.value))
        self.aligner.filter.reset(lattice)
        correction = self.aligner.correction_field(lattice)
        remainder = np.nan_to_num(now.map_src_luma - key.map_src_luma - correction).astype(np.float32)
        correction_chroma = 0.5 * self.aligner.correction_field(lattice, key.map_src_chroma.shape[:2])
        chroma = np.nan_to_num(now.map_src_chroma - key.map_src_chroma - correction_chroma)
        self._cover = (CoverFade.of(now.map_src_luma, key.map_src_luma, correction),
                       CoverFade.of(now.map_src_chroma, key.map_src_chroma, correction_chroma))
        self._home_fade = home_fade(now, key, self.cfg.video_blend_frames, self.cfg)
        frames = self.cfg.video_blend_frames if self._home_fade is None else self._home_fade[2]
        self._fade = (remainder, chroma.astype(np.float32), frames, frames)
        self.key, self._chroma_key = key, key.map_src_chroma
        self._poor_frames = 0
        self.log["keys"] += 1

    def copies(self, lines_are_rows: bool) -> tuple[np.ndarray, np.ndarray]:
        """The two copies of each point the frame's warp leaves apart: (the target's (M, 2), the source's
        (M, 2)) as (line, position along it) on the canvas (lines: rows, or columns when
        ``lines_are_rows`` is False)."""
        if self.alignment is None:
            return np.zeros((0, 2)), np.zeros((0, 2))
        tgt, src = copies_apart(self.alignment, self.maps.map_src_luma, self.cfg.seam_separation_min_px)
        if lines_are_rows:
            return tgt[:, ::-1], src[:, ::-1]
        return tgt, src

    def report(self) -> dict:
        return {name: round(value, 4) if isinstance(value, float) else value for name, value in self.log.items()}
