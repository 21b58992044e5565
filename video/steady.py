"""A moving rig's steady canvas: where the output frame sits on the canvas, following the rig smoothly.

The canvas is the target's frame (``maps.target_offset``), so on a hand-held rig everything on it
shakes with the target camera. As a video stabiliser does, the output is a window on the canvas that
follows the target's *camera path* through a causal low-pass:

1. *Path*: the target's frame-to-frame translation (:func:`frame_shift`: phase correlation of its Y
   plane, made :data:`PATH_SHORT_PX` rows small), summed: where the target's view has gone (output px).
2. *Steady path*: that path through the critically damped alpha-beta filter of the alignment
   (``align.LagBoundedFilter``): ``video_steady_follow`` of each innovation taken at once, a steady pan
   followed without lag, and never more than ``video_steady_max_px`` from the path (the lag bound). It
   starts moving as the rig's first step does (a rig panning from the first frame is not caught up
   from rest).
3. *Window*: the output shows the canvas shifted by (steady path - path), sub-pixel (whole pixels would
   leave half a pixel of shake, as much as a hand-held rig's frame-to-frame jitter). It is composited
   through the window's own maps (``maps.windowed_plane_maps``: the canvas's maps read at the window,
   so each output pixel samples the inputs once, and a frame costs no second pass); where the shifted
   canvas does not reach, the output is black and that band moves as smoothly as the window does.

With ``--crop`` and ``--rig moving`` the output is the first estimate's rectangle less
``video_steady_max_px`` on every side (:func:`steady_crop`): the window never leaves the cropped canvas,
so the rectangle the viewer sees does not change at all. The output's size is fixed before ``--rig
auto`` has judged the rig, and a fixed rig's cropped output must stay what it was: with ``--crop`` under
``auto`` the output is the whole rectangle and it is not stabilised (a moving window would uncover its
edges). A static rig's window is the whole canvas, unshifted (``video_steady_max_px`` 0: the
same for a moving rig); a rig found static after moving glides back there at the filter's pace.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..config import Config
from .align import LagBoundedFilter

PATH_SHORT_PX = 180  # the target's path is measured on its Y plane made about this many rows small
MIN_RESPONSE = 0.05  # a phase correlation peak weaker than this: the frame moved as the last one did
HOME_PX = 0.01  # a static rig's window this close to the centre is the canvas itself


def margin_px(cfg: Config) -> int:
    """Whole, even output px the window may move from the canvas's centre each way (0 unless ``--rig moving``:
    the only mode known to move before the output's size is fixed)."""
    if cfg.video_rig != "moving":
        return 0
    return 2 * int(np.ceil(cfg.video_steady_max_px / 2.0))


def steady_crop(x0: int, y0: int, width: int, height: int, margin: int) -> tuple[int, int, int, int]:
    """A crop rectangle (x0, y0, width, height) less ``margin`` on every side, even-sized; the
    rectangle unchanged where that leaves less than 2 px."""
    if width - 2 * margin < 2 or height - 2 * margin < 2:
        return x0, y0, width, height
    return x0 + margin, y0 + margin, width - 2 * margin, height - 2 * margin


def small_y(y: np.ndarray) -> np.ndarray:
    """A Y plane made about :data:`PATH_SHORT_PX` rows small (area average), float32."""
    factor = max(1, int(round(min(y.shape) / PATH_SHORT_PX)))
    small = y if factor == 1 else cv2.resize(y, (y.shape[1] // factor, y.shape[0] // factor),
                                             interpolation=cv2.INTER_AREA)
    return small.astype(np.float32)


def frame_shift(last_small: np.ndarray, small: np.ndarray, window: np.ndarray) -> tuple[np.ndarray, float]:
    """(dx, dy) small px the view moved from ``last_small`` to ``small`` (both :func:`small_y`, the
    ``window`` a Hanning window of their shape; content at x then is at x + dx now), and the phase
    correlation's peak response."""
    (dx, dy), response = cv2.phaseCorrelate(last_small, small, window)
    return np.array([dx, dy], np.float64), float(response)


class SteadyCanvas:
    """Where each output frame sits on the canvas (module docstring).

    ``canvas_shape`` (H, W) the composited canvas, ``output_shape`` (H, W) the output (the canvas less
    ``2 margin`` each way with ``--crop``), ``scale`` (sx, sy) output px per target px.
    :meth:`follow` takes each frame's target Y plane while the rig moves, :meth:`hold` each frame of a
    static rig; :meth:`window` gives the output's top-left corner on the canvas, :meth:`window_for` the
    same where a frame needs one.
    """

    def __init__(self, canvas_shape: tuple[int, int], output_shape: tuple[int, int], scale: np.ndarray,
                 cfg: Config):
        self.canvas_shape = tuple(canvas_shape)
        self.output_shape = tuple(output_shape)
        self.centre = np.array([(canvas_shape[1] - output_shape[1]) // 2, (canvas_shape[0] - output_shape[0]) // 2],
                               np.float64)
        self.scale = np.asarray(scale, np.float64)
        self.max_px = float(cfg.video_steady_max_px)
        # Whether the output may be a window on the canvas: an output cropped from it, or a rig that may move
        # where nothing was cropped (a window on a crop with no margin would uncover the crop's edges).
        self.windowed = tuple(output_shape) != tuple(canvas_shape) or (
            cfg.video_rig != "static" and self.max_px > 0 and not cfg.video_crop)
        self._filter = LagBoundedFilter(cfg.video_steady_follow, self.max_px)
        self._path = np.zeros(2)
        self._last: np.ndarray | None = None
        self._hann: np.ndarray | None = None
        self._factor = np.ones(2)
        self._step = np.zeros(2)  # the last frame's step of the path (a frame without a clear peak repeats it)
        self._following = 0  # frames followed since the rig was last seen static
        self.shift = np.zeros(2)  # (x, y) output px the canvas is shown shifted by
        self.log = {"frames": 0, "weak": 0, "shift_px_max": 0.0}

    def follow(self, y_tgt: np.ndarray) -> None:
        """A frame of a moving rig: its target Y plane extends the path, the window moves."""
        if self.max_px <= 0 or not self.windowed:
            return
        small = small_y(y_tgt)
        if self._last is None or self._last.shape != small.shape:
            self._hann = cv2.createHanningWindow(small.shape[::-1], cv2.CV_32F)
            self._factor = np.array([y_tgt.shape[1] / small.shape[1], y_tgt.shape[0] / small.shape[0]]) * self.scale
            step = np.zeros(2)
        else:
            moved, response = frame_shift(self._last, small, self._hann)
            weak = response < MIN_RESPONSE
            step = self._step if weak else moved * self._factor
            self.log["weak"] += int(weak)
        self._path = self._path + step
        if self._last is not None and self._following == 1:
            steady = self._filter.value + step  # the rig's motion as first seen: no start from rest
            self._filter.reset(steady, step)
        else:
            steady = self._filter.update(self._path)
        self._last, self._step = small, step
        self._following += 1
        self.shift = steady - self._path
        self.log["frames"] += 1
        self.log["shift_px_max"] = max(self.log["shift_px_max"], float(np.abs(self.shift).max()))

    def hold(self) -> None:
        """A frame of a static rig: the path stands still, so the window glides back to the centre (the
        filter's own pace), and is there once within :data:`HOME_PX`."""
        if self._filter.value is None:
            return
        if self._following:
            self._filter.reset(self._filter.value)  # the path stopped: so does the window, then it glides
        self._last = None
        self._following = 0
        self.shift = self._filter.update(self._path) - self._path
        if np.abs(self.shift).max() < HOME_PX:
            self._filter.reset(self._path)
            self.shift = np.zeros(2)

    @property
    def path(self) -> np.ndarray:
        """(x, y) the target's camera path so far: where its view has gone since the rig began to move (output px)."""
        return self._path.copy()

    def window(self) -> np.ndarray:
        """(x, y) the output's top-left corner on the canvas, output px (sub-pixel; may lie off the canvas)."""
        return self.centre - self.shift

    def window_for(self, mode: str) -> np.ndarray | None:
        """The window of a frame composited with a ``mode`` ("static" or "moving") plan: :meth:`window`, or
        None where the output is the canvas itself (a static rig's, once its window is home)."""
        cropped = self.output_shape != self.canvas_shape
        away = bool(np.abs(self.shift).max() > 0)
        return self.window() if cropped or (self.windowed and (mode == "moving" or away)) else None

    def report(self) -> dict:
        return {"max_px": self.max_px, "frames": self.log["frames"], "weak_frames": self.log["weak"],
                "shift_px_max": round(self.log["shift_px_max"], 3)}

