"""What a run is doing, for people and for machines: stage names, counts, warnings.

The pipeline reports through the standard :mod:`logging` module, on the ``sena_warp`` logger, so a
library user sees nothing until they configure logging and can route it like any other library's.
Three kinds of record:

- a stage starting, :func:`stage` ("estimating maps" at INFO; the steps inside it, "features",
  "local_affines", at DEBUG);
- a count advancing, :class:`Count` (frames, pairs, jobs: done / total, rate, ETA);
- a message: a warning or a fallback is ``LOGGER.warning(text)``, one line each (a newline or
  another control character in it, say from a file name, is shown escaped: ``\\n``).

The CLI shows them with :class:`ConsoleHandler`: "bar" redraws one tqdm-style line on a terminal,
"plain" writes whole lines (no escape codes, for logs), "json" one JSON object per line.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from typing import TextIO

from .errors import OutputError

LOGGER = logging.getLogger("sena_warp")
LOGGER.addHandler(logging.NullHandler())  # a library stays silent until its user configures logging

MODES = ("bar", "plain", "json")
REDRAW_INTERVAL_S = {"bar": 0.2, "plain": 5.0, "json": 1.0}  # a count is shown at most this often (and at its end)
BAR_WIDTH = 20  # characters of the bar in "bar" mode
PREFIX = "sena-warp"


def stage(name: str, step: bool = False) -> None:
    """Announce that stage ``name`` starts; ``step``: a step inside a stage (shown with -v, or on the bar)."""
    LOGGER.log(logging.DEBUG if step else logging.INFO, name, extra={"stage": name})


class Count:
    """Work done out of a known total, e.g. ``Count("frames", 300, "fps")``; rate and ETA from its start."""

    def __init__(self, name: str, total: int, rate_unit: str = ""):
        self.name, self.total = name, total
        self.rate_unit = rate_unit or f"{name}/s"
        self.t0 = time.perf_counter()

    def update(self, done: int, final: bool = False) -> None:
        if LOGGER.isEnabledFor(logging.INFO):
            LOGGER.info("%s %d/%d", self.name, done, self.total, extra={"count": self, "done": done, "final": final})

    def close(self, done: int) -> None:
        """The last update: always shown, whatever the redraw interval."""
        self.update(done, final=True)

    def figures(self, done: int) -> dict:
        """done, total, elapsed_s, rate (per second) and eta_s (None until a rate is known)."""
        elapsed = time.perf_counter() - self.t0
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = max(self.total - done, 0) / rate if rate > 0 else None
        return {"done": done, "total": self.total, "elapsed_s": round(elapsed, 3), "rate": round(rate, 2),
                "eta_s": None if eta is None else round(eta, 1)}


def echo(line: str) -> None:
    """Print a result line on stdout (unless quiet), keeping a console's redrawn line out of its way."""
    if not LOGGER.isEnabledFor(logging.INFO):
        return
    consoles = [h for h in LOGGER.handlers if isinstance(h, ConsoleHandler)]
    for console in consoles:
        console.clear_line()
    write_stdout(line + "\n")
    for console in consoles:
        console.redraw()


def write_stdout(text: str = "") -> None:
    """Write ``text`` on stdout and flush it; OutputError (one line, exit 6) when stdout cannot take it
    (a full disk, a pipe whose reader left), after pointing stdout at /dev/null so that the
    interpreter's own last flush does not fail again with a traceback. Nothing when stdout was closed."""
    if sys.stdout is None:
        return
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except OSError as exc:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
        raise OutputError(f"stdout: cannot write the results ({exc.strerror or exc})") from exc


def one_line(text: str) -> str:
    """``text`` with its control characters escaped (``\\n``, ``\\t``, ``\\x1b``): one line on a terminal or in a log."""
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape").decode("ascii") for ch in text)


class ConsoleHandler(logging.Handler):
    """Shows the records of :data:`LOGGER` on ``stream`` in one of :data:`MODES`.

    Messages are one line each: ``sena-warp: warning: ...`` (or ``{"event": "warning", ...}`` in json);
    a record's ``label`` extra replaces the ``warning: `` part. ``verbose`` also shows DEBUG records (the
    steps inside a stage and their times).
    """

    def __init__(self, stream: TextIO, mode: str, verbose: bool):
        super().__init__(logging.DEBUG)
        if mode not in MODES:
            raise ValueError(f"mode {mode!r}; one of {MODES}")
        self.stream, self.mode, self.verbose = stream, mode, verbose
        self.t0 = time.perf_counter()
        self._stage = ""  # "bar": what the line shows
        self._step = ""
        self._line = ""
        self._shown: dict[int, tuple[float, int]] = {}  # id(Count) -> when it was last shown, and its done then

    def emit(self, record: logging.LogRecord) -> None:
        try:
            stage_name, count = getattr(record, "stage", None), getattr(record, "count", None)
            if record.levelno < logging.INFO and not self.verbose and not (self.mode == "bar" and stage_name):
                return
            if count is not None:
                self._count(count, record.done, record.final)
            elif stage_name is not None:
                self._stage_starts(stage_name, record.levelno < logging.INFO)
            else:
                self._message(record)
        except Exception:
            self.handleError(record)

    def _write(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()

    def _json(self, event: str, **fields) -> None:
        self._write(json.dumps({"event": event, "time_s": round(time.perf_counter() - self.t0, 3), **fields}) + "\n")

    def _stage_starts(self, name: str, step: bool) -> None:
        if self.mode == "json":
            self._json("stage", stage=name, step=step)
        elif self.mode == "plain":
            if not step:  # a step's line comes when it ends, with its time (-v): one line per step in a log
                self._write(f"{PREFIX}: {name}\n")
        else:
            if step:
                self._step = name
            else:
                self._stage, self._step = name, ""
            self._draw(f"{PREFIX}: {self._stage}{': ' + self._step if self._step else ''}")

    def _count(self, count: Count, done: int, final: bool) -> None:
        now = time.perf_counter()
        shown_at, shown_done = self._shown.get(id(count), (-float("inf"), None))
        if not final and now - shown_at < REDRAW_INTERVAL_S[self.mode]:
            return
        if final and done == shown_done and self.mode != "bar":  # the last update said it already: once is enough
            return
        self._shown[id(count)] = (now, done)
        fig = count.figures(done)
        if self.mode == "json":
            self._json("progress", name=count.name, rate_unit=count.rate_unit, **fig)
            return
        eta = "?" if fig["eta_s"] is None else f"{fig['eta_s']:.0f} s"
        share = done / count.total if count.total > 0 else 0.0
        figures = f"{done}/{count.total} {count.name}  {fig['rate']:.1f} {count.rate_unit}  ETA {eta}"
        if self.mode == "plain":
            self._write(f"{PREFIX}: {figures}\n")
            return
        filled = min(round(share * BAR_WIDTH), BAR_WIDTH)
        self._draw(f"{PREFIX}: {self._stage} {share:4.0%} |{'#' * filled}{'-' * (BAR_WIDTH - filled)}| {figures}")
        if final:  # a finished count stays on screen, as tqdm leaves it
            self._write("\n")
            self._line = ""

    def _message(self, record: logging.LogRecord) -> None:
        level, text = record.levelname.lower(), one_line(record.getMessage())
        if self.mode == "json":
            self._json(level, message=text)
            return
        label = getattr(record, "label", "" if record.levelno < logging.WARNING else f"{level}: ")
        self.clear_line()
        self._write(f"{PREFIX}: {label}{text}\n")
        self.redraw()

    def _draw(self, line: str) -> None:
        self._line = line
        self._write(f"\r\x1b[K{line}")

    def clear_line(self) -> None:
        """Remove the redrawn line ("bar" mode) so a whole line can be written."""
        if self.mode == "bar" and self._line:
            self._write("\r\x1b[K")

    def redraw(self) -> None:
        """Draw the redrawn line again after :meth:`clear_line`."""
        if self.mode == "bar" and self._line:
            self._write(self._line)

    def close(self) -> None:
        """Leave the terminal on a fresh line."""
        self.clear_line()
        self._line = ""
        super().close()
