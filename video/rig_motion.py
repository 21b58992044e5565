"""Is the rig moving? ``--rig auto``: decided from the first second, then watched for the whole video.

A fixed camera's view holds still, but for what moves in front of it (people, a person right at the
lens) and a slow creep of its mount; a hand-held camera's whole view moves. So each view is judged by
its stillest part: every :data:`CHECK_S` the corners of a small grey copy of the view
(:data:`THUMB_WIDTH_PX` wide) are tracked from the last check to this one (every :data:`MOVING_CHECK_S`
once the rig moves) (pyramidal Lucas-Kanade,
kept where the backward track returns within :data:`RETURN_PX`), and the view's still-part move is the
mean move of its :data:`STILL_SHARE` least-moving corners (at least :data:`MIN_STILL` of them). Over the
last :data:`WINDOW_S` those moves add up to the view's *drift*, as a share of its width per second.
On the shared recordings (``docs/benchmarks.md``) the fixed rigs drift 0.01-0.26 %/s in their first
second (the floodlit pitch's mount creeping and rocking: 0.26) and up to 0.84 %/s later; the hand-held
ones 0.55 %/s (two phones held as still as hands can at a window) to 27 %/s (walking, turning).

* *First second*: the rig is "moving" when either view drifted by ``video_rig_moving_share`` or more
  in the first :data:`WINDOW_S`, else "static".
* *Then*, a "static" rig becomes "moving" when a view drifts by ``video_rig_switch_share`` or more over
  a window (a move no fixed mount makes), and a "moving" rig becomes "static" when both views drifted
  less than ``video_rig_still_share`` (as still as a fixed camera: the fixed rigs' office and lecture
  hall 0.00-0.07 %/s) over every window for ``video_rig_still_s``.

A check that tracks too few corners (:data:`MIN_TRACKED`: the view is dark, blurred, or changed
completely) says nothing about its view; a window needs checks covering most of it
(:data:`MIN_COVERED`) to count.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from ..config import Config

CHECK_S = 0.2  # views are compared this often (seconds of video) ...
MOVING_CHECK_S = 0.8  # ... and this often once the rig moves: what is watched for then (both views still for
# video_rig_still_s) takes seconds to show, a check costs as much as a hand-held frame's alignment, and one
# check still covers MIN_COVERED of a window
WINDOW_S = 1.0  # drifts add up the checks over this much video
THUMB_WIDTH_PX = 320  # views are compared at this width at most
CORNERS = 200  # corners tracked per check ...
CORNER_QUALITY = 0.01  # ... at least this x the strongest corner's response
CORNER_SPACING_PX = 6  # ... this far apart (thumbnail px)
LK_WINDOW_PX = 15  # Lucas-Kanade window (thumbnail px) ...
LK_LEVELS = 4  # ... and pyramid levels: a move of up to about a fifth of the width between checks
RETURN_PX = 0.5  # a corner counts where its backward track returns within this (thumbnail px)
MIN_TRACKED = 20  # a check with fewer tracked corners says nothing
STILL_SHARE = 0.1  # a view's move is the mean move of this share of its least-moving corners ...
MIN_STILL = 5  # ... at least this many
MIN_COVERED = 0.7  # a window counts when its checks span at least this share of it


@dataclass(frozen=True)
class RigDecision:
    """A decision of :class:`RigMotion`: the mode ("static" / "moving"), the time it was taken at (s), and
    why, in words (the drifts it rests on)."""

    mode: str
    time_s: float
    reason: str

    def as_dict(self) -> dict:
        return {"mode": self.mode, "time_s": round(self.time_s, 4), "reason": self.reason}


def thumbnail(y: np.ndarray) -> tuple[np.ndarray, float]:
    """A view's luma (H, W) uint8 at most :data:`THUMB_WIDTH_PX` wide (area average), and the input px per
    thumbnail px."""
    height, width = y.shape
    scale = max(1.0, width / THUMB_WIDTH_PX)
    size = (max(1, int(round(width / scale))), max(1, int(round(height / scale))))
    return (cv2.resize(y, size, interpolation=cv2.INTER_AREA) if scale > 1.0 else y.copy()), scale


def still_move(before: np.ndarray, after: np.ndarray) -> np.ndarray | None:
    """(x, y) thumbnail px: how far the stillest part of a view moved from thumbnail ``before`` to
    ``after`` (module docstring); None when too few corners track."""
    corners = cv2.goodFeaturesToTrack(before, CORNERS, CORNER_QUALITY, CORNER_SPACING_PX)
    if corners is None or len(corners) < MIN_TRACKED:
        return None
    window, criteria = (LK_WINDOW_PX, LK_WINDOW_PX), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01)
    moved, found, _ = cv2.calcOpticalFlowPyrLK(before, after, corners, None, winSize=window, maxLevel=LK_LEVELS,
                                               criteria=criteria)
    back, returned, _ = cv2.calcOpticalFlowPyrLK(after, before, moved, None, winSize=window, maxLevel=LK_LEVELS,
                                                 criteria=criteria)
    kept = (found[:, 0] == 1) & (returned[:, 0] == 1) & (np.hypot(*(back - corners).reshape(-1, 2).T) <= RETURN_PX)
    if kept.sum() < MIN_TRACKED:
        return None
    moves = (moved - corners).reshape(-1, 2)[kept].astype(np.float64)
    still = np.argsort(np.hypot(*moves.T))[:max(MIN_STILL, int(round(STILL_SHARE * len(moves))))]
    return moves[still].mean(axis=0)


class ViewDrift:
    """One view's still-part moves, check by check (input px, with the time each check ends)."""

    def __init__(self) -> None:
        self._thumb: np.ndarray | None = None
        self._scale = 1.0
        self.width = 0
        self.moves: deque[tuple[float, float, np.ndarray | None]] = deque()  # (from s, to s, move or None)

    def check(self, time_s: float, y: np.ndarray, last_s: float | None) -> None:
        """Compare the view ``y`` at ``time_s`` with its last check's (at ``last_s``)."""
        thumb, self._scale = thumbnail(y)
        self.width = y.shape[1]
        if self._thumb is not None and last_s is not None:
            move = still_move(self._thumb, thumb)
            self.moves.append((last_s, time_s, None if move is None else move * self._scale))
        self._thumb = thumb

    def drift_share_per_s(self, end_s: float, window_s: float) -> float | None:
        """The view's drift over the ``window_s`` before ``end_s``: |sum of the moves| / width / seconds
        covered; None when the known checks cover less than :data:`MIN_COVERED` of the window."""
        start = end_s - window_s
        known = [(t0, t1, move) for t0, t1, move in self.moves if t0 >= start - 1e-6 and t1 <= end_s + 1e-6
                 and move is not None]
        covered = sum(t1 - t0 for t0, t1, _ in known)
        if covered < MIN_COVERED * window_s or not self.width:
            return None
        total = np.sum([move for _, _, move in known], axis=0)
        return float(np.hypot(*total)) / self.width / covered

    def forget_before(self, time_s: float) -> None:
        while self.moves and self.moves[0][0] < time_s - 1e-6:
            self.moves.popleft()


class RigMotion:
    """Watches both views of a video and decides whether its rig moves (module docstring).

    Call :meth:`observe` with every frame pair's Y planes (left, right) and time; it returns a
    :class:`RigDecision` when it decides the first time or changes its mind, else None. ``mode`` is None
    until the first decision; ``decisions`` lists them all; ``drifts`` the last window's (left, right)
    drifts (share of the width per second, None where unknown).
    """

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.views = (ViewDrift(), ViewDrift())
        self.mode: str | None = None
        self.decisions: list[RigDecision] = []
        self.drifts: tuple[float | None, float | None] = (None, None)
        self._first_s: float | None = None
        self._last_check_s: float | None = None
        self._still_since_s: float | None = None

    def observe(self, time_s: float, y_left: np.ndarray, y_right: np.ndarray) -> RigDecision | None:
        if self._first_s is None:
            self._first_s = time_s
        every_s = MOVING_CHECK_S if self.mode == "moving" else CHECK_S
        if self._last_check_s is not None and time_s - self._last_check_s < every_s - 1e-6:
            return None
        for view, y in zip(self.views, (y_left, y_right)):
            view.check(time_s, y, self._last_check_s)
            view.forget_before(time_s - self.cfg.video_rig_still_s - WINDOW_S)
        self._last_check_s = time_s
        if time_s - self._first_s < WINDOW_S - 1e-6:
            return None
        self.drifts = tuple(view.drift_share_per_s(time_s, WINDOW_S) for view in self.views)
        decision = self._decide(time_s)
        if decision is not None:
            self.mode = decision.mode
            self.decisions.append(decision)
        return decision

    def _decide(self, time_s: float) -> RigDecision | None:
        cfg = self.cfg
        known = [(side, d) for side, d in zip(("left", "right"), self.drifts) if d is not None]
        fastest = max(known, key=lambda kd: kd[1], default=None)
        if self.mode is None:
            if fastest is not None and fastest[1] >= cfg.video_rig_moving_share:
                return RigDecision("moving", time_s, f"the {self._said(fastest)} in the first {WINDOW_S:g} s")
            said = " and ".join(self._said(kd) for kd in known) or "neither view could be tracked"
            return RigDecision("static", time_s, f"{said} in the first {WINDOW_S:g} s")
        if self.mode == "static":
            if fastest is not None and fastest[1] >= cfg.video_rig_switch_share:
                return RigDecision("moving", time_s, f"the {self._said(fastest)} over {WINDOW_S:g} s")
            return None
        if len(known) == 2 and fastest[1] < cfg.video_rig_still_share:
            self._still_since_s = time_s if self._still_since_s is None else self._still_since_s
            if time_s - self._still_since_s >= cfg.video_rig_still_s - 1e-6:
                self._still_since_s = None
                return RigDecision("static", time_s, f"both views drifted less than {100 * cfg.video_rig_still_share:g} "
                                                     f"% of their width a second for {cfg.video_rig_still_s:g} s")
        else:
            self._still_since_s = None
        return None

    @staticmethod
    def _said(side_drift: tuple[str, float]) -> str:
        side, drift = side_drift
        return f"{side} view drifted {100 * drift:.2f} % of its width a second"
