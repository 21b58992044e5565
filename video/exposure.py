"""Exposure over time: both views' gains re-measured on the frames and smoothed.

Cameras adjust their exposure while they record (and settle in their first half second), so a video
cannot keep the first estimate's gains. Every ``video_gain_period_s`` the overlap of the current frame
pair is sampled (every ``video_gain_stride_px`` canvas pixels, nearest taps, the pixels where both
views agree, ``gains.agreeing_pixels``): the Y planes give Brown & Lowe gains of ``Y - 16`` for each
view (``gains.brown_lowe_gains``), the U and V planes an offset each, split between the views. The
gains applied follow those measurements with a time constant of ``video_gain_settle_s``, but never
change the picture by more than ``video_gain_step_grey`` per frame (at the overlap's mean level), so
exposure changes glide instead of flickering, and a camera's jump settles within about a second.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Config
from ..gains import agreeing_pixels, brown_lowe_gains
from .maps import BLACK_Y, PlaneMaps, sampled_mask


def nearest_taps(map_canvas: np.ndarray, mask: np.ndarray, plane_shape: tuple[int, int]) -> np.ndarray:
    """Flat indices into a plane of ``plane_shape`` of the nearest tap of each masked canvas pixel."""
    xy = np.rint(map_canvas[mask]).astype(np.int64)
    xy[:, 0] = np.clip(xy[:, 0], 0, plane_shape[1] - 1)
    xy[:, 1] = np.clip(xy[:, 1], 0, plane_shape[0] - 1)
    return xy[:, 1] * plane_shape[1] + xy[:, 0]


def overlap_taps(maps: PlaneMaps, shape_src: tuple[int, int], shape_tgt: tuple[int, int], stride: int
                 ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Flat indices of the nearest taps, in the source's and the target's Y planes of (rows, cols)
    ``shape_src`` / ``shape_tgt``, of every ``stride``-th canvas pixel where ``maps`` sample both; and
    in their U/V planes, every ``stride // 2``-th pixel of the chroma canvas."""
    chroma_src = ((shape_src[0] + 1) // 2, (shape_src[1] + 1) // 2)
    chroma_tgt = ((shape_tgt[0] + 1) // 2, (shape_tgt[1] + 1) // 2)
    luma_src, luma_tgt = maps.map_src_luma[::stride, ::stride], maps.map_tgt_luma[::stride, ::stride]
    both = sampled_mask(luma_src, shape_src) & sampled_mask(luma_tgt, shape_tgt)
    half = max(1, stride // 2)
    uv_src, uv_tgt = maps.map_src_chroma[::half, ::half], maps.map_tgt_chroma[::half, ::half]
    both_uv = sampled_mask(uv_src, chroma_src) & sampled_mask(uv_tgt, chroma_tgt)
    return ((nearest_taps(luma_src, both, shape_src), nearest_taps(luma_tgt, both, shape_tgt)),
            (nearest_taps(uv_src, both_uv, chroma_src), nearest_taps(uv_tgt, both_uv, chroma_tgt)))


class ExposureTracker:
    """Smoothed per-plane gains of the two views of one fixed canvas, made with the first frame's maps.

    ``luma`` ((gain, bias) of the source, of the target) for the compositor's Y pass, ``chroma`` the
    same for the U/V pass (gain 1, offsets); ``history`` one dict per frame of what was applied.
    """

    def __init__(self, maps: PlaneMaps, shape_src: tuple[int, int], shape_tgt: tuple[int, int], fps: float,
                 cfg: Config):
        self.cfg = cfg
        self.period_frames = max(1, int(round(cfg.video_gain_period_s * fps)))
        self.follow = 1.0 - math.exp(-1.0 / max(cfg.video_gain_settle_s * fps, 1e-6))
        self.history: list[dict] = []
        self._frame = 0
        self._state: np.ndarray | None = None  # (g_src, g_tgt, u_src, u_tgt, v_src, v_tgt)
        self._target: np.ndarray | None = None
        self._level = 100.0  # mean Y - 16 of the overlap at the last measurement: the scale of a gain's effect
        self._maps_shapes = (maps, shape_src, shape_tgt)  # the maps and the planes' (rows, cols) to sample
        self._taps: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None

    def _follow(self, maps: PlaneMaps) -> None:
        """The maps of the frame (a re-estimate, a blend step: another object); the gains themselves carry
        on. Their sample positions are worked out when the next measurement needs them: a blend changes
        the maps on every frame, and a measurement comes every ``period_frames``."""
        if maps is not self._maps_shapes[0]:
            self._maps_shapes = (maps, *self._maps_shapes[1:])
            self._taps = None

    def _current_taps(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """((luma source, luma target), (chroma source, chroma target)) flat plane indices of the
        overlap's samples under the current maps (made once per maps)."""
        if self._taps is None:
            self._taps = overlap_taps(*self._maps_shapes, max(1, self.cfg.video_gain_stride_px))
        return self._taps

    def measure(self, y_src, y_tgt, u_src, u_tgt, v_src, v_tgt) -> np.ndarray | None:
        """(g_src, g_tgt, u_src, u_tgt, v_src, v_tgt) measured on one frame pair, or None (too few pixels)."""
        (luma_src, luma_tgt), (cs, ct) = self._current_taps()
        ys, yt = y_src.ravel()[luma_src], y_tgt.ravel()[luma_tgt]
        keep = agreeing_pixels(ys[:, None], yt[:, None], self.cfg)
        if keep.sum() < self.cfg.gain_min_pixels // 4:
            return None
        (g_src,), (g_tgt,) = brown_lowe_gains(np.array([ys[keep].mean() - BLACK_Y]),
                                             np.array([yt[keep].mean() - BLACK_Y]), self.cfg)
        du = float(u_src.ravel()[cs].astype(np.float64).mean() - u_tgt.ravel()[ct].mean()) if cs.size else 0.0
        dv = float(v_src.ravel()[cs].astype(np.float64).mean() - v_tgt.ravel()[ct].mean()) if cs.size else 0.0
        self._level = float(ys[keep].mean() - BLACK_Y)
        return np.array([g_src, g_tgt, -0.5 * du, 0.5 * du, -0.5 * dv, 0.5 * dv])

    def update(self, maps: PlaneMaps, y_src, y_tgt, u_src, u_tgt, v_src, v_tgt) -> None:
        """Before compositing a frame pair with ``maps``: measure on schedule, then move the applied gains."""
        self._follow(maps)
        if self._frame % self.period_frames == 0:
            measured = self.measure(y_src, y_tgt, u_src, u_tgt, v_src, v_tgt)
            if measured is not None:
                self._target = measured
                if self._state is None:
                    self._state = measured.copy()
        self._frame += 1
        if self._state is None:
            return
        step = self.follow * (self._target - self._state)
        # The picture moves by (delta g) x the mean level for a gain, by the offset itself for chroma.
        level = max(self._level, 1.0)
        limit = np.array([level, level, 1.0, 1.0, 1.0, 1.0])
        step = np.clip(step * limit, -self.cfg.video_gain_step_grey, self.cfg.video_gain_step_grey) / limit
        self._state = self._state + step
        g_src, g_tgt, u_src_off, u_tgt_off, v_src_off, v_tgt_off = self._state
        self.history.append({"gain_src": round(float(g_src), 5), "gain_tgt": round(float(g_tgt), 5),
                             "chroma_src": [round(float(u_src_off), 3), round(float(v_src_off), 3)],
                             "chroma_tgt": [round(float(u_tgt_off), 3), round(float(v_tgt_off), 3)]})

    @property
    def luma(self) -> tuple[tuple, tuple]:
        g_src, g_tgt = (1.0, 1.0) if self._state is None else self._state[:2]
        return ([g_src], [BLACK_Y * (1.0 - g_src)]), ([g_tgt], [BLACK_Y * (1.0 - g_tgt)])

    @property
    def chroma(self) -> tuple[tuple, tuple]:
        offsets = np.zeros(4) if self._state is None else self._state[2:]
        return ([1.0, 1.0], [offsets[0], offsets[2]]), ([1.0, 1.0], [offsets[1], offsets[3]])
