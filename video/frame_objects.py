"""What stands in front of the background on the per-frame seam's band, in each view, and where the
seam must keep off so that each object is shown once and whole, from one view.

An object nearer than the background lies at two places on the canvas, one copy per view, its
parallax apart (the warp aligns the background, not it). A seam between the copies shows neither
copy's middle (the strip between them is lost, or all of a narrow object), and a seam through both
shows a part of each, a parallax apart: the object is torn. Only a seam clear of both copies shows it
whole, from the view on the other side. So, on the band's cells (solved seam lines x cells along
them, as ``composite.band_difference`` fills them):

1. *Foreground in each view* (:class:`ViewBackground`): each view's luma against its own background
   model (``kernels/frame_objects.py``), beyond the view's whole-band gain and offset (an exposure
   step, a flickering light) and the cell's usual change from one frame to the next (leaves in the
   wind; learnt more slowly where the view is off, ``video_seam_spread_learn``: a textured object
   walking past changes its cells every frame, and is no background); cells off it in most of a box
   are the view's foreground (:func:`solid`), its connected parts the view's blobs (:func:`blobs`).
   Where most of a view is off, the camera or the light changed: no objects then.
2. *Copies* (:func:`pair_copies`): a source blob and a target blob on the same lines, of a like
   size, within the band of each other, the source's to the right (nearer than the background) are
   one object's two copies; their displacement along the lines is its parallax. A blob without a
   partner is an object whose other copy is off the band.
3. *Strips to keep off* (:func:`keep_off_cells`): per object, the lines its copies cover and the
   cells from the first copy's start to the second's end, widened by the seam's transition; where
   that reaches to within the same margin of the band's end of the overlap, on to the band's end: an
   object cut by a view's border is shown from the other view, where it is whole. An object that so
   closes both ends of a line (wider than the overlap allows) is passed at the end where its copies
   have more room from their borders, on all its lines.
4. *The route* (:class:`ObjectBand`): the cheapest path over the whole overlap with the strips at
   ``video_seam_object_cost`` and ``video_seam_home_cost`` per px from the estimate's seam; it replaces
   the last route only where that saves ``video_seam_margin`` per line, so the seam passes each object
   on the side it passed it before, until that side is closed (the object reached the view's border)
   or much further from home: then it jumps round the object once, never through it. The per-frame
   seam's band is centred on the route (``FrameSeam``), which is the estimate's seam where nothing is
   in the way.

All of it runs on the object band (:class:`ObjectGrid`): the overlap on cells :data:`COARSE_CELLS` x
the per-frame seam's, solved on every such cell's line; an object is found when it covers a few of
them. Its difference and sum come from the frame's device in one small block
(``device_frame.DeviceFrame.objects``); the rest runs on the host (Warp's CPU device, numpy, OpenCV).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import warp as wp

from ..config import Config
from ..seam_path import BandPath
from sena_warp.kernels import runtime
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.kernels.frame_objects import CellGrid, ViewModels, view_background_kernel
from sena_warp.kernels.frame_seam import DEVICE
from sena_warp.kernels.transfer import host_array

FIT_STRIDE = 4  # each view's whole-band gain and offset are fitted on every this-th line and cell
SPREAD_FACTOR = 3.0  # a cell is off its background beyond this x its mean absolute deviation there

PAIR_OVERLAP = 0.5  # two blobs are copies when they share this much of the shorter one's lines
PAIR_AREA = 0.3  # ... and the smaller has this share of the larger's area at least (a copy cut by a border)
PAIR_BEHIND = 2  # ... and the source's copy lies at most this many cells left of the target's (noise)
COARSE_CELLS = 4  # the object band's cells are this many of the per-frame seam's cells wide
FOREGROUND_MOST = 0.8  # a view off its background on more of the band: the camera or the light changed (a person
# close to both cameras covers two thirds of it)
MOST_STRIPS = 8  # strips kept off per line at most
SETTLE_S = 0.25  # nothing is in front while the models have learnt from less than this much video
NO_EXTENT = np.iinfo(np.int64).max // 4  # a line's extent where a copy has none (start past any end)
OBJECT_BOXES = 2  # an object covers this x this of an object's boxes at least (smaller things only cost motion)


@dataclass(frozen=True)
class Blob:
    """A connected part of one view's foreground on the band: ``first_line`` its first solved line,
    ``starts`` / ``ends`` (n,) int32 its first cell and one past its last on each of its n lines (an
    empty line has start = end = 0), ``area`` in cells, ``centre`` its mean cell."""

    first_line: int
    starts: np.ndarray
    ends: np.ndarray
    area: int
    centre: float

    @property
    def last_line(self) -> int:
        return self.first_line + len(self.starts) - 1

    def behind(self, other: "Blob") -> float:
        """How far (cells) this blob lies right of ``other`` on the lines both cover: the smaller of the
        medians of their starts' and their ends' differences (negative: left of it; 0 without a line)."""
        first, last = max(self.first_line, other.first_line), min(self.last_line, other.last_line)
        if last < first:
            return 0.0
        mine = slice(first - self.first_line, last - self.first_line + 1)
        theirs = slice(first - other.first_line, last - other.first_line + 1)
        starts, ends = [], []  # on a blob's few lines, Python lists cost a third of numpy's calls
        for start, end, start_other, end_other in zip(self.starts[mine].tolist(), self.ends[mine].tolist(),
                                                      other.starts[theirs].tolist(), other.ends[theirs].tolist()):
            if end > start and end_other > start_other:
                starts.append(start - start_other)
                ends.append(end - end_other)
        if not starts:
            return 0.0
        return min(median(starts), median(ends))

    def shared_lines(self, other: "Blob") -> float:
        """The share of the shorter blob's lines that both cover."""
        shared = min(self.last_line, other.last_line) - max(self.first_line, other.first_line) + 1
        shorter = min(len(self.starts), len(other.starts))
        return max(shared, 0) / shorter


def median(values: list[int]) -> float:
    """The median of ``values`` (not empty) as ``np.median`` gives it: the mean of the two middle values
    where there are an even number."""
    ordered = sorted(values)
    n = len(ordered)
    return float(ordered[n // 2]) if n % 2 else (float(ordered[n // 2 - 1]) + float(ordered[n // 2])) / 2.0


class ViewBackground:
    """Each view's background model over a band of ``shape`` (K solved lines, cells) (module
    docstring, 1), learnt with time constant ``video_seam_background_s`` at ``fps`` (``video_seam_foreground_learn``
    x as fast where the view is off it); on Warp's CPU device, on the host."""

    def __init__(self, shape: tuple[int, int], fps: float, cfg: Config):
        self.cfg = cfg
        self.noise = np.float32(2.0 * cfg.video_seam_noise)
        self._learn = 1.0 / max(1.0, fps * cfg.video_seam_background_s)
        self._settle = max(2, int(np.ceil(SETTLE_S * fps)))  # frames
        self._arrays = (np.zeros((2, *shape), np.float32), np.zeros((2, *shape), np.float32),
                        np.zeros((2, *shape), np.float32), np.zeros((2, *shape), np.uint8))  # background, spread, last, off
        models = ViewModels()
        models.background, models.spread, models.last = (host_array(a, float) for a in self._arrays[:3])
        models.off = host_array(self._arrays[3], wp.uint8)
        models.noise, models.spread_factor = float(self.noise), SPREAD_FACTOR
        self._models = models
        self._crowded = False  # whether most of a view was off its model in the last frame
        self._band: tuple | None = None  # the last band's (diff, total) and their Warp views (a video's are the same arrays)
        self.frames = 0  # frames the models have learnt from

    def update(self, diff: np.ndarray, total: np.ndarray) -> np.ndarray:
        """(2, K, cells) uint8: 1 where the source (index 0) or the target (1) is off its background in
        the frame whose band has difference ``diff`` and sum ``total`` ((K, cells) float32, as
        ``band_difference`` fills them); none on the first frame (the models start from it). Learns: over
        the first frames at least as fast as their running mean (a webcam's exposure settles over its
        first frames; a model that kept the first frame saw the whole scene in front for seconds), then
        at the model's rate; ``video_seam_foreground_learn`` x as fast where the view is off, but where
        most of a view was off in the last frame (:data:`FOREGROUND_MOST`). Nothing is off them over the first :data:`SETTLE_S` of video (a camera
        settling)."""
        background, spread, last, off = self._arrays
        if diff.shape != background.shape[1:] or total.shape != background.shape[1:]:
            raise ValueError(f"band of {diff.shape} / {total.shape} cells for models of {background.shape[1:]}")
        both = diff < 0.5 * NOT_BOTH
        self.frames += 1
        if self.frames == 1:
            views = np.stack([0.5 * (total + diff), 0.5 * (total - diff)])
            np.copyto(background, np.where(both, views, 0.0))
            np.copyto(last, background)
            spread.fill(float(self.noise / SPREAD_FACTOR))
            off.fill(0)
            return off
        learn = max(self._learn, 1.0 / self.frames)  # at least the running mean's rate
        self._models.learn = float(np.float32(learn))
        # Where a view is off, slower in proportion, from the first frames on (a slow walker's cells are
        # off for seconds while the running mean's rate is high: learnt at it, they would leave a ghost of
        # him behind); as fast where most of a view was off (the camera or the light changed).
        self._models.learn_off = float(np.float32(learn if self._crowded else learn * self.cfg.video_seam_foreground_learn))
        # The spread, slower where a view is off once the cameras have settled (a textured object walking
        # past changes its cells every frame: learnt at full rate, it would soon count as their usual
        # change and no longer be in front); while they settle, their swings are what it learns.
        settled = self.frames >= self._settle and not self._crowded
        self._models.spread_off = float(np.float32(learn * self.cfg.video_seam_spread_learn if settled else learn))
        fit = (slice(None, None, FIT_STRIDE),) * 2
        diff_fit, total_fit, both_fit = diff[fit], total[fit], both[fit]
        explained = []
        for view in range(2):  # on the cells that were on the background last frame: an object is no exposure step
            luma = 0.5 * (total_fit + diff_fit) if view == 0 else 0.5 * (total_fit - diff_fit)
            gain, offset = whole_band_fit(background[view][fit], luma, both_fit & (off[view][fit] == 0),
                                          float(self.noise))
            explained += [np.float32(gain - 1.0), np.float32(offset)]
        if self._band is None or self._band[0] is not diff or self._band[1] is not total:
            self._band = diff, total, host_array(diff, float), host_array(total, float)
        runtime.launch_row_loops(view_background_kernel, diff.shape[0], diff.shape[1], [
            *self._band[2:], wp.vec4(*explained), self._models], DEVICE, runtime.BAND_THREADS)
        self._crowded = most_off(off, both) > FOREGROUND_MOST
        if self.frames < self._settle:
            off.fill(0)
        return off


def most_off(views, both: np.ndarray) -> float:
    """The larger share of the cells in ``both`` (K, cells) bool that either of ``views`` (two (K, cells)
    uint8 0/1 masks) flags: 0 without such cells."""
    count = np.count_nonzero(both)
    return max(np.count_nonzero(view & both) for view in views) / count if count else 0.0


def whole_band_fit(background: np.ndarray, total: np.ndarray, both: np.ndarray, noise: float) -> tuple[float, float]:
    """(gain, offset): how ``total`` changed from ``background`` over the whole band (a camera's exposure
    step, a flickering light): their least-squares fit on the cells in ``both`` (the caller takes every
    :data:`FIT_STRIDE`-th line and cell), fitted again without the cells more than ``noise`` (and twice
    the median residual) off the first fit (an object in front). ``(gain - 1) x background + offset``
    is the change they explain."""
    x = background[both].astype(np.float64)
    y = total[both].astype(np.float64)
    gain, offset = _gain_offset(x, y)
    residual = np.abs(y - gain * x - offset)
    kept = residual <= max(noise, 2.0 * array_median(residual)) if residual.size else residual > 0
    return _gain_offset(x[kept], y[kept])


def array_median(values: np.ndarray) -> float:
    """``np.median`` of the 1-D ``values`` (not empty, no NaN), from a partial sort of its one or two
    middle values: the same number at a fifth of its cost on the band's few hundred cells."""
    half = values.size // 2
    if values.size % 2:
        return float(np.partition(values, half)[half])
    middle = np.partition(values, (half - 1, half))
    return (float(middle[half - 1]) + float(middle[half])) / 2.0


def _gain_offset(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least squares y = gain x + offset; gain 1 where x does not vary, (1, 0) without points."""
    if x.size == 0:
        return 1.0, 0.0
    x_mean, y_mean = x.sum() / x.size, y.sum() / y.size
    dx = x - x_mean
    x_var = float(dx @ dx) / x.size
    if x.size < 2 or x_var <= 1e-6:
        return 1.0, float(y_mean - x_mean)
    gain = float(dx @ (y - y_mean)) / x.size / x_var
    return gain, float(y_mean - gain * x_mean)


def solid(off: np.ndarray, box: int) -> np.ndarray:
    """(K, cells) uint8: 1 on the cells most of whose ``box`` x ``box`` neighbourhood is ``off``
    (K, cells) uint8 0/1: an object, not the thin edges a flickering light or a leaf leaves."""
    return (cv2.blur(off, (box, box)) > 0).view(np.uint8)


def blobs(foreground: np.ndarray, least: int) -> list[Blob]:
    """The connected parts (8-neighbours) of ``foreground`` (K, cells) uint8 of at least ``least`` cells."""
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(foreground, connectivity=8)
    found = []
    for label in (np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= least) + 1).tolist():  # label 0: the background
        x, y, w, h, area = stats[label].tolist()
        part = labels[y:y + h, x:x + w] == label  # a connected part has a cell on every line of its box
        starts = (x + np.argmax(part, axis=1)).astype(np.int32)
        ends = (x + w - np.argmax(part[:, ::-1], axis=1)).astype(np.int32)
        found.append(Blob(y, starts, ends, area, float(centroids[label, 0])))
    return found


def pair_copies(blobs_src: list[Blob], blobs_tgt: list[Blob], reach: float) -> list[tuple[Blob | None, Blob | None]]:
    """Each object's (source copy, target copy), one of them None where its other copy was not found:
    source and target blobs sharing :data:`PAIR_OVERLAP` of the shorter one's lines, the smaller
    :data:`PAIR_AREA` of the larger's area, their centres at most ``reach`` cells apart, the source's
    copy not left of the target's on the lines they share (:data:`PAIR_BEHIND` cells at most, in the
    median: :meth:`Blob.behind`), paired best first (the most lines shared, the likest size).

    An object nearer than the background lies further right in the source (the left view) than in
    the target once the background is aligned: the source's copy starts and ends right of the
    target's, where neither is cut by its view's border (a cut end lies at the overlap's border, which
    keeps the order: the target's at its left end, the source's at its right end). A source blob left
    of a target blob is another thing (what a model learnt while someone stood there, a second person)."""
    candidates = []
    for i, src in enumerate(blobs_src):
        for j, tgt in enumerate(blobs_tgt):  # the cheap tests first: most pairs of blobs fail one
            shared = src.shared_lines(tgt)
            likeness = min(src.area, tgt.area) / max(src.area, tgt.area)
            if shared >= PAIR_OVERLAP and likeness >= PAIR_AREA and abs(src.centre - tgt.centre) <= reach \
                    and src.behind(tgt) >= -PAIR_BEHIND:
                candidates.append((shared * likeness, i, j))
    pairs, used_src, used_tgt = [], set(), set()
    for _, i, j in sorted(candidates, reverse=True):
        if i not in used_src and j not in used_tgt:
            pairs.append((blobs_src[i], blobs_tgt[j]))
            used_src.add(i)
            used_tgt.add(j)
    pairs += [(blob, None) for i, blob in enumerate(blobs_src) if i not in used_src]
    pairs += [(None, blob) for j, blob in enumerate(blobs_tgt) if j not in used_tgt]
    return pairs


def keep_off_cells(pairs: list[tuple[Blob | None, Blob | None]], both: np.ndarray, first_cell: np.ndarray,
                   margin_cells: int, margin_lines: int, most: int, out: np.ndarray) -> np.ndarray:
    """``out`` (K, cells) uint8 filled with 1 on the cells the seam must keep off, 0 elsewhere: per
    solved line the strips the objects ``pairs`` (:func:`pair_copies`) span, on a band whose cells hold
    both views where ``both`` (K, cells) bool and whose line k begins at the line's cell
    ``first_cell[k]`` (K,) int (its position / the cell width: the band follows the estimate's seam):
    on each line, from the first position either copy covers within ``margin_lines`` lines to the
    last, widened by ``margin_cells``.

    A copy the overlap's border cuts (within ``margin_cells`` of the first cell holding both views,
    where the target begins, or of the last, where the source ends) is not whole in its view: the
    strip goes on to the band's end there, so that the seam passes on the other side and shows the
    object from the other view. A lone copy near either border: its other copy lies beyond it. An
    object cut so on both ends of one of its lines (wider than the overlap allows) is passed at the end
    where its copies have more room from their views' borders, on all its lines: there its strip stops
    at the copy, leaving at least the end cell holding both views (shown from the view where it is
    whole, or most nearly). Overlapping strips merge; a line with more than ``most`` has its narrowest
    gaps closed (:func:`merge_strips`)."""
    lines, cells = both.shape
    first_cell = np.asarray(first_cell, np.int64)
    has_both = both.any(axis=1)
    first_both = np.where(has_both, np.argmax(both, axis=1), cells) + first_cell
    last_both = np.where(has_both, cells - 1 - np.argmax(both[:, ::-1], axis=1), -1) + first_cell
    edges = np.zeros((lines, cells + 1), np.int32)  # +1 where a strip starts, -1 where it ends
    if pairs:
        # Per object (rows) and line: each copy's extent (a lone copy's partner: none), and the lines the
        # strip may take, its copies' within ``margin_lines``.
        (src_start, src_end), (tgt_start, tgt_end) = (
            copy_extents([pair[view] for pair in pairs], first_cell, lines, margin_lines) for view in (0, 1))
        tops = [max(min(b.first_line for b in pair if b is not None) - margin_lines, 0) for pair in pairs]
        bottoms = [min(max(b.last_line for b in pair if b is not None) + margin_lines, lines - 1) for pair in pairs]
        start = np.minimum(src_start, tgt_start) - margin_cells
        end = np.maximum(src_end, tgt_end) + margin_cells
        # The target's copy decides the left end, the source's the right one (a lone copy: both).
        lone_src = np.array([tgt is None for _, tgt in pairs])[:, None]
        lone_tgt = np.array([src is None for src, _ in pairs])[:, None]
        left = np.where(lone_src, src_start, tgt_start)
        right = np.where(lone_tgt, tgt_end, src_end)
        line = np.arange(lines)[None, :]
        spans = (line >= np.array(tops)[:, None]) & (line <= np.array(bottoms)[:, None])
        obj, k = np.nonzero(spans & (end > start + 2 * margin_cells))
        left, right = left[obj, k], right[obj, k]
        cut_left = left - margin_cells <= first_both[k]
        cut_right = right + margin_cells > last_both[k]
        lo = np.where(cut_left, 0, np.minimum(np.maximum(start[obj, k] - first_cell[k], 0), cells))
        hi = np.where(cut_right, cells, np.minimum(np.maximum(end[obj, k] - first_cell[k], 0), cells))
        # An object that leaves the seam no room on either side of one of its lines: passed on all its
        # lines at the overlap's end where its copies have the more room from their views' borders (the
        # target's copy at the first cell holding both views, the source's at the last), so that the
        # seam need not cross it from line to line.
        wide = np.bincount(obj[cut_left & cut_right], minlength=len(pairs))[obj] > 0
        if wide.any():
            room = np.bincount(obj, left - first_both[k] - (last_both[k] - right), len(pairs))[obj]
            at_first, at_last = wide & cut_left & (room >= 0.0), wide & cut_right & (room < 0.0)
            lo = np.where(at_first, np.minimum(np.maximum(left, first_both[k] + 1) - first_cell[k], cells), lo)
            hi = np.where(at_last, np.maximum(np.minimum(right, last_both[k]) - first_cell[k], 0), hi)
        np.add.at(edges, (k, lo), 1)
        np.add.at(edges, (k, hi), -1)
    inside = np.cumsum(edges[:, :cells], axis=1, dtype=edges.dtype) > 0
    np.copyto(out, inside, casting="unsafe")
    opens = inside.copy()
    opens[:, 1:] &= ~inside[:, :-1]
    # Rare: a crowd on one line (looked for only where all the lines together open more than ``most``).
    crowded = np.flatnonzero(opens.sum(axis=1) > most) if np.count_nonzero(opens) > most else ()
    for k in crowded:
        runs = np.flatnonzero(np.diff(np.concatenate([[0], out[k], [0]]).astype(np.int8)))
        out[k] = 0
        for lo, hi in merge_strips(list(zip(runs[::2], runs[1::2])), most):
            out[k, lo:hi] = 1
    return out


def copy_extents(copies: list[Blob | None], first_cell: np.ndarray, lines: int, reach: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(first position, one past the last) (C, lines) int64, in cells along the line from the line's own
    origin (band line k begins at ``first_cell[k]``), of each of ``copies`` on each of the band's
    ``lines`` lines, each line taking its neighbours' within ``reach`` lines too; an empty extent
    (start > end) where none, and everywhere for a copy that is None."""
    start = np.full((len(copies), lines + 2 * reach), NO_EXTENT, np.int64)  # ``reach`` lines of padding each side
    end = np.full((len(copies), lines + 2 * reach), -NO_EXTENT, np.int64)
    present = [(row, blob) for row, blob in enumerate(copies) if blob is not None]
    if present:  # every copy's lines at once
        rows = np.concatenate([np.full(len(blob.starts), row) for row, blob in present])
        at = np.concatenate([np.arange(blob.first_line, blob.last_line + 1) for _, blob in present])
        starts = np.concatenate([blob.starts for _, blob in present])
        ends = np.concatenate([blob.ends for _, blob in present])
        on = ends > starts
        rows, at = rows[on], at[on]
        start[rows, at + reach] = starts[on] + first_cell[at]
        end[rows, at + reach] = ends[on] + first_cell[at]
    first, last = start[:, :lines].copy(), end[:, :lines].copy()
    for shift in range(1, 2 * reach + 1):  # the lines within reach: a few shifts of the padded extents
        np.minimum(first, start[:, shift:shift + lines], out=first)
        np.maximum(last, end[:, shift:shift + lines], out=last)
    return first, last


def merge_strips(strips: list[tuple[int, int]], most: int) -> list[tuple[int, int]]:
    """``strips`` [(start, end)] merged where they overlap or touch, at most ``most`` of them (the
    gaps between the last ones closed when there are more)."""
    merged: list[list[int]] = []
    for lo, hi in sorted(strips):
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    while len(merged) > most:  # close the narrowest gap
        gap = int(np.argmin([merged[m + 1][0] - merged[m][1] for m in range(len(merged) - 1)]))
        merged[gap][1] = merged.pop(gap + 1)[1]
    return [(lo, hi) for lo, hi in merged]


def route_cost(kept_off: np.ndarray, both: np.ndarray, home_term: np.ndarray, cfg: Config, out: np.ndarray
               ) -> np.ndarray:
    """``out`` (K, cells) float32: what each cell of the object band costs the seam's route: its cost of
    leaving the estimate's seam ``home_term`` (K, cells) float32 (``video_seam_home_cost`` per px), plus
    ``video_seam_object_cost`` on the strips kept off (``kept_off`` (K, cells) uint8) and
    ``video_seam_blocked_cost`` where the cell lacks a view (not ``both``)."""
    np.multiply(kept_off, np.float32(cfg.video_seam_object_cost), out=out)
    np.add(home_term, out, out=out)
    np.add(out, np.float32(cfg.video_seam_blocked_cost), out=out, where=~both)
    return out


@dataclass(frozen=True)
class ObjectGrid:
    """The object band's cells over the whole overlap of a static rig, fixed for an estimate's seam:
    ``lines`` (Kc,) int32 the seam lines it is solved on (every ``cell``-th, and the last), line k's first
    cell at ``x0[k]`` px, ``width`` cells of ``cell`` px (:data:`COARSE_CELLS` x the per-frame seam's);
    ``home`` (Kc,) float64 the estimate's seam on its lines; ``kernel`` the same as the host kernels take
    it (``CellGrid``)."""

    lines: np.ndarray
    x0: np.ndarray
    width: int
    cell: int
    home: np.ndarray
    kernel: CellGrid

    @staticmethod
    def of(home: np.ndarray, overlap: np.ndarray, seam_cell: int) -> "ObjectGrid":
        """The grid for the estimate's seam ``home`` (L,) and ``overlap`` (L, 2) int (per seam line the
        first and the last position whose canvas pixel holds both views; first > last: none), on cells
        :data:`COARSE_CELLS` x the seam's ``seam_cell`` px."""
        cell = seam_cell * COARSE_CELLS
        count = len(home)
        lines = np.unique(np.append(np.arange(0, count, cell), count - 1)).astype(np.int32)
        first, last = (np.asarray(overlap, np.int64)[lines, k] for k in (0, 1))
        inside = last >= first
        near_home = np.rint(np.asarray(home, np.float64)[lines]).astype(np.int64)
        x0 = ((np.where(inside, first, near_home) // cell) * cell).astype(np.int32)
        width = max(1, int(np.max(np.where(inside, (last - x0) // cell + 1, 1))))
        kernel = CellGrid()
        kernel.x0, kernel.cell, kernel.step = host_array(x0, int), cell, cell
        return ObjectGrid(lines, x0, width, cell, np.asarray(home, np.float64)[lines], kernel)

    @property
    def shape(self) -> tuple[int, int]:
        """(lines, cells): the shape of the object band's per-cell arrays."""
        return len(self.lines), self.width


class ObjectBand:
    """The objects in front of the background over the whole overlap of a static rig, and the route the
    per-frame seam takes round them (module docstring), on the cells of ``grid`` (:class:`ObjectGrid`);
    ``fps``: the video's frame rate.

    Each frame, :meth:`update` on the object band's difference gives ``moving`` (cells in front of
    either view's background, grown by an object's box), ``kept_off`` (the strips each object keeps the
    seam off), both (Kc, width) uint8 on the host with their Warp views in ``views``, and the route: per
    line, where the seam's band must be centred so that the seam can keep off every object (the
    estimate's seam where it can; :meth:`centre`)."""

    def __init__(self, grid: ObjectGrid, fps: float, cfg: Config):
        self.cfg = cfg
        self.grid = grid
        box = 2 * max(1, round(cfg.video_seam_still_box_px / COARSE_CELLS)) + 1
        self._box = (box, np.ones((box, box), np.uint8))
        self._margin_cells = int(np.ceil((0.5 * cfg.transition_px + 2.0) / grid.cell)) + 1
        self._solver = BandPath(len(grid.lines), grid.width, np.array([[0, len(grid.lines) - 1, -1, -1]]),
                                cfg.cpu_threads)
        self._views = ViewBackground(grid.shape, fps, cfg)
        self.host = {"moving": np.zeros(grid.shape, np.uint8), "kept_off": np.zeros(grid.shape, np.uint8),
                     "cost": np.zeros(grid.shape, np.float32)}
        positions = (grid.x0[:, None] + grid.cell * np.arange(grid.width)[None, :]).astype(np.float32)
        self._home_term = np.float32(cfg.video_seam_home_cost) * np.abs(positions - grid.home.astype(np.float32)[:, None])
        self._last_cost = np.full(grid.shape, np.nan, np.float32)  # the route's costs in the last frame
        self.views = {name: host_array(a, wp.uint8 if a.dtype == np.uint8 else float) for name, a in self.host.items()}
        self.pairs: list[tuple[Blob | None, Blob | None]] = []
        self.route = grid.home.copy()  # (Kc,) px: where the seam's band is centred, per object-band line

    def update(self, band) -> bool:
        """The objects and the route of the frame whose object band is ``band`` (``frame_seam.BandFrame``
        on :attr:`grid`) (class docstring); whether the route changed."""
        cfg, grid, host = self.cfg, self.grid, self.host
        off = self._views.update(band.diff, band.total)
        box, kernel = self._box
        solids = [solid(view, box) for view in off]
        np.copyto(host["moving"], cv2.dilate(solids[0] | solids[1], kernel))
        both = band.diff < 0.5 * NOT_BOTH
        crowded = most_off(solids, both) > FOREGROUND_MOST
        # Most of a view off its background: the camera or the light changed, not an object in front.
        least = (OBJECT_BOXES * box) ** 2  # a person's size, not a head turning or a screen's flicker
        self.pairs = [] if crowded else pair_copies(blobs(solids[0], least), blobs(solids[1], least), grid.width)
        keep_off_cells(self.pairs, both, grid.x0 // grid.cell, self._margin_cells, self._margin_cells, MOST_STRIPS,
                       host["kept_off"])
        cost = route_cost(host["kept_off"], both, self._home_term, cfg, host["cost"])
        if np.array_equal(cost, self._last_cost):  # the last frame's costs: its route, which it kept or took
            return False
        np.copyto(self._last_cost, cost)
        route = (self._solver.solve(self.views["cost"], grid.x0 // grid.cell, max(1, int(cfg.seam_max_step_px)), 0.0)
                 * grid.cell).astype(np.int64)  # no steeper than the seam between its lines
        lines = np.arange(len(grid.lines))

        def along(path: np.ndarray) -> float:
            at = np.clip((np.rint(path).astype(np.int64) - grid.x0) // grid.cell, 0, grid.width - 1)
            return float(cost[lines, at].sum())

        # A new route only where it saves more than the margin: while objects only move a little, the
        # seam keeps the side of each it was on.
        if along(self.route) - along(route) <= cfg.video_seam_margin * len(lines):
            return False
        route = np.where(np.abs(route - grid.home) <= grid.cell, grid.home, route)
        changed = not np.array_equal(route, self.route)
        self.route = route
        return changed

    def centre(self, lines: np.ndarray) -> np.ndarray:
        """(n,) float64: where the seam's band is centred on seam lines ``lines``: the estimate's seam
        moved as the route moved it from there (interpolated between object-band lines)."""
        return np.interp(lines, self.grid.lines, self.route)
