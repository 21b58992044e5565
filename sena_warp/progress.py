"""A one-line progress display for long work (video frames, evaluation pairs), redrawn in place."""

from __future__ import annotations

import time
from typing import TextIO

REDRAW_INTERVAL_S = 0.5  # redraw the line at most this often


class Progress:
    """``label: done/total unit  rate rate_unit  ETA`` on ``stream``; silent when not ``enabled``.

    ``rate_unit`` defaults to ``unit/s`` ("fps" reads better for frames).
    """

    def __init__(self, total: int, enabled: bool, stream: TextIO, label: str, unit: str, rate_unit: str = ""):
        self.total, self.enabled, self.stream = total, enabled, stream
        self.label, self.unit, self.rate_unit = label, unit, rate_unit or f"{unit}/s"
        self._t0 = time.perf_counter()
        self._last_draw = 0.0

    def update(self, done: int, force: bool = False) -> None:
        now = time.perf_counter()
        if not self.enabled or (now - self._last_draw < REDRAW_INTERVAL_S and not force):
            return
        self._last_draw = now
        elapsed = now - self._t0
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = f"{max(self.total - done, 0) / rate:.0f} s" if rate > 0 else "?"
        self.stream.write(f"\r{self.label}: {done}/{self.total} {self.unit}  {rate:.1f} {self.rate_unit}  ETA {eta} ")
        self.stream.flush()

    def close(self, done: int) -> None:
        """Draw the final count and end the line."""
        self.update(done, force=True)
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
