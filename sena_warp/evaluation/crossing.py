"""The crossing clip: a figure nearer than the background walking across a static rig's overlap.

A real fixed two-camera recording is the background (its frames in turn, played back and forth when
the walk needs more of them). A striped rectangle, the figure, is pasted opaque into both views: it
walks at a constant speed along one row of the right view, from where only the left camera sees it,
across the overlap, to where only the right camera does (``direction`` "right"), or back
("left"). In the left view it sits where the background behind it is (SIFT matches of the first frame
pair on its rows, weighted by their distance: independent of SENA) shifted right by the walk's
``parallax_px``: it is that much nearer than the background (a person 3 m in front of a wall
6 m away, seen by webcams half a metre apart, is about 40 px), and a warp aligned to the background
cannot align it. Every frame knows where the figure is in both views exactly.

:class:`CrossingFigures` observes the stitch of such a clip (``stitch_videos(observer=...)``) and
measures per frame, in the figure's own pixels, how much of it the output shows and in how many
pieces (:func:`shown_figure`).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from sena_warp.affine import apply_affine, compose_affine, invert_affine
from sena_warp.errors import InputError
from sena_warp.video.maps import sampled_mask
from sena_warp.video.reader import FrameReader, probe_video
from sena_warp.video.stitch import CompositedFrame
from sena_warp.video.writer import VideoWriter

from .naturalness import view_weights

HEIGHT_PX = 200  # the figure's height
MARGIN_PX = 12  # the walk starts and ends this far beyond where a view alone sees the figure
STRIPE_PX = 12  # period of the figure's diagonal stripes
OUTLINE_PX = 3  # its dark outline
GLOBAL_WEIGHT = 1e-3  # every background match's weight in the local affine behind the figure, beyond its nearness
CLIP_CRF = 10  # near-lossless clips: the figures are about the seam, not the encoder
CLIP_FPS = 30  # a clip's frame rate where none is given
SIFT_RATIO = 0.75
HOMOGRAPHY_PX = 3.0  # RANSAC threshold of the background's homography (``background_homography``)
MISMATCH_PX = 12.0  # a background match further than this off the pair's homography is a mismatch
WHOLE_SHARE = 0.9  # a frame shows the figure whole when this share of it is shown, in one piece
PIECE_SHARE = 0.02  # a piece: a connected part of the shown figure of at least this share of it
TWICE_SHARE = 0.02  # shown twice: this share of the figure shown from both views at two places
COINCIDE_PX = 2.0  # the two copies on the canvas coincide when this close (median over the figure)
SHOWN_WEIGHT = 0.5  # a canvas pixel shows a view where that view's weight is at least this
BLOCK_PX = 2  # the figure's shown share is counted in blocks of this x this of its pixels
WINDOW_STRIDE = 8  # the canvas pixels showing the figure are looked for on every this-th pixel first


@dataclass(frozen=True)
class Walk:
    """One walk of the figure: ``parallax_px`` (its disparity beyond the background's, px: it is
    nearer), ``width_px`` by ``height_px``, ``speed_px`` per frame, ``direction`` "right" (from the
    left camera's side to the right camera's) or "left"."""

    parallax_px: float
    width_px: int
    speed_px: float
    direction: str = "right"
    height_px: int = HEIGHT_PX

    def __post_init__(self):
        if self.direction not in ("right", "left"):
            raise ValueError(f"direction {self.direction!r}: use 'right' or 'left'")
        if self.speed_px <= 0 or self.width_px < 2 or self.height_px < 2:
            raise ValueError(f"{self}: speed, width and height must be positive")

    @property
    def name(self) -> str:
        return f"d{self.parallax_px:g}_w{self.width_px}_{self.direction}_s{self.speed_px:g}"


@dataclass(frozen=True)
class CrossingClip:
    """The clip's files and ground truth: ``figure_to_left`` / ``figure_to_right`` (F, 2, 3) float64,
    per frame the affine from the figure's pixels (x, y) to each view's (the right view's a shift;
    the left view's the background's local affine behind it, moved by the parallax); ``mask`` (h, w)
    bool the figure's pixels (all of its rectangle); ``overlap_end_px``: the right view's x where the
    left view ends, on the figure's middle row. The figure walks in from frame ``lead_frames`` on
    (frame ``lead_frames + i`` is the affines' i-th); the frames before show the recording alone."""

    left: Path
    right: Path
    figure_to_left: np.ndarray
    figure_to_right: np.ndarray
    mask: np.ndarray
    walk: Walk
    overlap_end_px: float
    lead_frames: int

    @property
    def frames(self) -> int:
        return self.lead_frames + len(self.figure_to_left)

    def corner_right(self, index: int) -> np.ndarray:
        """(2,) (x, y) of the figure's pixel (0, 0) in the right view in walking frame ``index``."""
        return self.figure_to_right[index - self.lead_frames, :, 2]

    def in_overlap(self) -> np.ndarray:
        """(F,) bool: the frames in which a copy of the figure reaches into the overlap (in the right
        view's terms: from x 0 to ``overlap_end_px``; the left view's copy is the parallax further right)."""
        left = self.figure_to_right[:, 0, 2]
        inside = (left + self.mask.shape[1] + max(self.walk.parallax_px, 0.0) >= 0) & (left <= self.overlap_end_px)
        return np.concatenate([np.zeros(self.lead_frames, bool), inside])

    def affines(self, index: int, source: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The figure-to-view affines of frame ``index``, (2, 3) each: (the source view's, the target
        view's), or None where the figure is not there; ``source`` "left" or "right"."""
        if not self.lead_frames <= index < self.frames:
            return None
        left, right = self.figure_to_left[index - self.lead_frames], self.figure_to_right[index - self.lead_frames]
        return (left, right) if source == "left" else (right, left)


def sift_matches(img_left: np.ndarray, img_right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pts_left, pts_right) (N, 2) float64 (x, y): SIFT matches between two BGR views (ratio test)."""
    sift = cv2.SIFT_create()
    grey = [cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) for img in (img_left, img_right)]
    (kp_l, des_l), (kp_r, des_r) = (sift.detectAndCompute(g, None) for g in grey)
    pairs = cv2.BFMatcher().knnMatch(des_l, des_r, k=2)
    good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < SIFT_RATIO * n.distance]
    if len(good) < 12:
        raise InputError(f"crossing clip: only {len(good)} SIFT matches between the views")
    return np.float64([kp_l[m.queryIdx].pt for m in good]), np.float64([kp_r[m.trainIdx].pt for m in good])


def background_homography(img_left: np.ndarray, img_right: np.ndarray) -> np.ndarray:
    """3x3 homography (left pixels -> right pixels) of the background: SIFT, ratio test, RANSAC at
    :data:`HOMOGRAPHY_PX`."""
    homography, _ = cv2.findHomography(*sift_matches(img_left, img_right), cv2.RANSAC, HOMOGRAPHY_PX)
    return homography


def background_matches(img_left: np.ndarray, img_right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pts_left, pts_right) (N, 2) float64 (x, y): SIFT matches of the background (``sift_matches``), less
    those more than :data:`MISMATCH_PX` off a homography fitted to them by RANSAC (mismatches; the
    homography is loose enough to keep the scene's depth)."""
    pts_l, pts_r = sift_matches(img_left, img_right)
    _, inliers = cv2.findHomography(pts_l, pts_r, cv2.RANSAC, MISMATCH_PX)
    kept = inliers.ravel().astype(bool)
    return pts_l[kept], pts_r[kept]


def background_affines(pts_left: np.ndarray, pts_right: np.ndarray, x_right: np.ndarray, rows: tuple[float, float],
                       reach_px: float) -> np.ndarray:
    """(F, 2, 3) float64: the background's local affine right view -> left view behind a figure at
    right-view x ``x_right`` (F,) (its middle) spanning ``rows`` (top, bottom): least squares on the
    matches on those rows, each weighted by a Gaussian of its x's distance (sigma ``reach_px``; the
    nearest matches' where the figure is beyond them), plus :data:`GLOBAL_WEIGHT` for all of them (a
    fit where few are near)."""
    on_rows = (pts_right[:, 1] >= rows[0]) & (pts_right[:, 1] <= rows[1])
    if on_rows.sum() < 12:
        raise InputError(f"crossing clip: only {int(on_rows.sum())} background matches on the figure's rows")
    src, dst = pts_right[on_rows], pts_left[on_rows]
    at = np.clip(np.asarray(x_right, np.float64), src[:, 0].min(), src[:, 0].max())
    weights = np.exp(-0.5 * ((src[None, :, 0] - at[:, None]) / reach_px) ** 2) + GLOBAL_WEIGHT
    design = np.column_stack([src, np.ones(len(src))])
    affines = []
    for w in np.sqrt(weights):
        solution, *_ = np.linalg.lstsq(design * w[:, None], dst * w[:, None], rcond=None)
        affines.append(solution.T)
    return np.asarray(affines)


def figure_patch(width: int, height: int) -> np.ndarray:
    """(height, width, 3) uint8 BGR: the figure, diagonal stripes of two saturated colours inside a
    dark outline, so that a missing strip, a doubled one or a step shows at once."""
    rows, cols = np.mgrid[0:height, 0:width]
    stripe = ((rows + cols) // (STRIPE_PX // 2)) % 2 == 0
    patch = np.where(stripe[:, :, None], np.uint8([40, 200, 250]), np.uint8([200, 60, 170]))
    edge = (rows < OUTLINE_PX) | (cols < OUTLINE_PX) | (rows >= height - OUTLINE_PX) | (cols >= width - OUTLINE_PX)
    patch[edge] = (30, 30, 30)
    return patch.astype(np.uint8)


def paste(frame: np.ndarray, patch: np.ndarray, figure_to_view: np.ndarray) -> np.ndarray:
    """``frame`` with ``patch`` (h, w, 3) pasted opaque through the affine ``figure_to_view`` (2, 3)
    from the patch's pixels (x, y) to the frame's."""
    height, width = frame.shape[:2]
    placed = cv2.warpAffine(patch.astype(np.float32), figure_to_view, (width, height), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.ones(patch.shape[:2], np.float32), figure_to_view, (width, height),
                          flags=cv2.INTER_LINEAR)
    mixed = mask[:, :, None] * placed + (1.0 - mask[:, :, None]) * frame.astype(np.float32)
    return np.clip(np.rint(mixed), 0, 255).astype(np.uint8)


def write_clip(path: Path, frames_bgr: Iterable[np.ndarray], fps: Fraction | int = CLIP_FPS,
               crf: int = CLIP_CRF) -> None:
    """An H.264 clip of BGR frames (H, W, 3) uint8 with even sides at ``fps``, at ``crf`` (near-lossless
    by default)."""
    frames_bgr = iter(frames_bgr)
    first = next(frames_bgr)
    height, width = first.shape[:2]
    with VideoWriter(path, width, height, Fraction(fps), "libx264", crf, "veryfast") as writer:
        for index, frame in enumerate(itertools.chain([first], frames_bgr)):
            i420 = cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420)
            chroma = i420[height:].reshape(2, height // 2, width // 2)
            writer.write(i420[:height], chroma[0], chroma[1], index)


def recording_frames(path: Path, count: int) -> list[np.ndarray]:
    """``count`` BGR frames of the recording ``path``: its frames in turn, played back and forth (a
    static scene: the turns are where its people and lights change direction)."""
    with FrameReader(path) as reader:
        frames = [frame.to_bgr() for frame, _ in zip(reader, range(count))]
    if not frames:
        raise InputError(f"crossing clip: {path} has no frames")
    cycle = frames + frames[-2:0:-1] if len(frames) > 2 else frames
    return [cycle[i % len(cycle)] for i in range(count)]


def walk_affines(pts_left: np.ndarray, pts_right: np.ndarray, shape: tuple[int, int], walk: Walk
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """(figure -> left view, figure -> right view) (F, 2, 3) float64 per frame, and the right view's x
    where the left view ends on the figure's middle row, for a walk across the overlap of views of
    ``shape`` (rows, cols) whose background matches are ``pts_left`` / ``pts_right``
    (``background_matches``).

    The figure's middle row is the right view's. In the right view its left edge goes from one figure
    width plus the parallax (and :data:`MARGIN_PX`) left of the view, where only the left camera sees
    it, to :data:`MARGIN_PX` beyond where the left view's right border crosses its middle row, where
    only the right camera does; ``direction`` "left" walks back. In the left view it lies as the
    background behind it does (``background_affines``), moved right by the parallax."""
    height, width = shape
    top = (height - walk.height_px) / 2.0
    rows = (top, top + walk.height_px)
    middle = top + walk.height_px / 2.0
    overlap_end = width - 1.0  # where the left view's right border lands on the middle row: twice refined
    for _ in range(2):
        to_left = background_affines(pts_left, pts_right, [overlap_end], rows, walk.width_px)[0]
        overlap_end += width - 1.0 - apply_affine(to_left, np.array([[overlap_end, middle]]))[0, 0]
    start = -float(walk.width_px) - walk.parallax_px - MARGIN_PX
    end = overlap_end + MARGIN_PX
    xs = start + walk.speed_px * np.arange(int(np.ceil((end - start) / walk.speed_px)) + 1)
    if walk.direction == "left":
        xs = xs[::-1]
    to_right = np.zeros((len(xs), 2, 3))
    to_right[:, 0, 0] = to_right[:, 1, 1] = 1.0
    to_right[:, 0, 2], to_right[:, 1, 2] = xs, top
    parallax = np.float64([[1, 0, walk.parallax_px], [0, 1, 0]])
    to_left = [compose_affine(parallax, compose_affine(behind, figure))
               for behind, figure in zip(background_affines(pts_left, pts_right, xs + walk.width_px / 2.0, rows,
                                                            walk.width_px), to_right)]
    return np.asarray(to_left), to_right, overlap_end


def make_crossing_clip(left: Path, right: Path, folder: Path, walk: Walk, lead_frames: int) -> CrossingClip:
    """Write ``left.mp4`` / ``right.mp4`` into ``folder``: the static recording ``left`` / ``right``
    (the left camera's and the right one's, one even-sided size), alone for ``lead_frames`` frames
    (give the first estimate's: ``video.estimate.spaced_span``, so that it sees the background, as a
    rig set up before people walk through), then with the figure walking across its overlap (module
    docstring); return the clip with its ground truth."""
    info_l, info_r = probe_video(left), probe_video(right)
    if (info_l.width, info_l.height) != (info_r.width, info_r.height) or info_l.width % 2 or info_l.height % 2:
        raise InputError("crossing clip: the views must have one even-sided size")
    first_l, first_r = (recording_frames(path, 1)[0] for path in (left, right))
    to_left, to_right, overlap_end = walk_affines(*background_matches(first_l, first_r),
                                                  (info_r.height, info_r.width), walk)
    patch = figure_patch(walk.width_px, walk.height_px)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"left": folder / "left.mp4", "right": folder / "right.mp4"}
    for side, path, affines in (("left", left, to_left), ("right", right, to_right)):
        frames = recording_frames(path, lead_frames + len(affines))
        walking = (paste(frame, patch, a) for frame, a in zip(frames[lead_frames:], affines))
        write_clip(paths[side], itertools.chain(frames[:lead_frames], walking), info_r.fps)
    return CrossingClip(paths["left"], paths["right"], to_left, to_right,
                        np.ones((walk.height_px, walk.width_px), bool), walk, overlap_end, lead_frames)


@dataclass(frozen=True)
class ShownFigure:
    """What one output frame shows of the figure, counted in blocks of :data:`BLOCK_PX` x
    :data:`BLOCK_PX` of the figure's own pixels (a warp that shrinks a view's copy a little skips some
    of its pixels, never a block).

    ``truth``: how many of them the better view's copy puts on the canvas (what a whole figure
    shows); ``shown``: how many the output shows, from either view; ``twice``: how many it shows from
    both views at two places (the copies ``apart_px`` apart, median over the blocks both copies put on
    the canvas; None when they share none); ``pieces``: connected parts of what it shows (each at least
    :data:`PIECE_SHARE` of the truth; the two views' parts count apart when the copies are more than
    :data:`COINCIDE_PX` apart); ``source_share``: the share of the shown blocks that come from the
    source."""

    truth: int
    shown: int
    twice: int
    pieces: int
    apart_px: float | None
    source_share: float

    @property
    def whole(self) -> bool:
        return self.shown >= WHOLE_SHARE * self.truth and self.pieces == 1

    @property
    def doubled(self) -> bool:
        return self.twice >= TWICE_SHARE * self.truth

    def as_dict(self) -> dict:
        return {"truth_blocks": self.truth, "shown_pct": round(100.0 * self.shown / max(self.truth, 1), 1),
                "twice_pct": round(100.0 * self.twice / max(self.truth, 1), 1), "pieces": self.pieces,
                "apart_px": None if self.apart_px is None else round(self.apart_px, 2),
                "source_pct": round(100.0 * self.source_share, 1), "whole": self.whole, "doubled": self.doubled}


def _window(map_canvas: np.ndarray, figure_to_view: np.ndarray, mask: np.ndarray) -> tuple[slice, slice]:
    """(rows, cols) of the canvas that hold every pixel ``map_canvas`` (H, W, 2) samples from the
    figure's box in that view (through ``figure_to_view`` (2, 3)): found on every
    :data:`WINDOW_STRIDE`-th pixel, the box and the window widened by a stride."""
    height, width = mask.shape
    corners = apply_affine(figure_to_view, np.float64([[0, 0], [width, 0], [0, height], [width, height]]))
    low, high = corners.min(axis=0) - WINDOW_STRIDE, corners.max(axis=0) + WINDOW_STRIDE
    coarse = map_canvas[::WINDOW_STRIDE, ::WINDOW_STRIDE]
    with np.errstate(invalid="ignore"):
        near = np.all((coarse >= low) & (coarse <= high), axis=2)
    if not near.any():
        return slice(0, 0), slice(0, 0)
    rows, cols = (np.flatnonzero(near.any(axis=k)) * WINDOW_STRIDE for k in (1, 0))
    return (slice(max(rows[0] - WINDOW_STRIDE, 0), min(rows[-1] + WINDOW_STRIDE + 1, map_canvas.shape[0])),
            slice(max(cols[0] - WINDOW_STRIDE, 0), min(cols[-1] + WINDOW_STRIDE + 1, map_canvas.shape[1])))


def _figure_blocks(map_canvas: np.ndarray, valid: np.ndarray, figure_to_view: np.ndarray, mask: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(block, inside) per canvas pixel: the figure block (flat index into :func:`block_mask`'s grid)
    the canvas pixel samples through ``map_canvas`` (H, W, 2) where it is ``valid`` (H, W) when the
    figure lies in that view through ``figure_to_view`` (2, 3), and whether it samples one of the
    figure's pixels (``mask`` (h, w) bool) at all."""
    height, width = mask.shape
    at = apply_affine(invert_affine(figure_to_view), map_canvas.reshape(-1, 2).astype(np.float64))
    col, row = (np.floor(at[:, k] + 0.5).reshape(valid.shape) for k in (0, 1))
    inside = valid & (col >= 0) & (col < width) & (row >= 0) & (row < height)  # False on NaN
    col, row = np.where(inside, col, 0).astype(np.int64), np.where(inside, row, 0).astype(np.int64)
    inside &= mask[row, col]
    return (row // BLOCK_PX) * -(-width // BLOCK_PX) + col // BLOCK_PX, inside


def block_mask(mask: np.ndarray) -> np.ndarray:
    """(ceil(h / BLOCK_PX), ceil(w / BLOCK_PX)) bool: the blocks holding a pixel of ``mask`` (h, w)."""
    height, width = mask.shape
    padded = np.zeros((-(-height // BLOCK_PX) * BLOCK_PX, -(-width // BLOCK_PX) * BLOCK_PX), bool)
    padded[:height, :width] = mask
    return padded.reshape(padded.shape[0] // BLOCK_PX, BLOCK_PX, -1, BLOCK_PX).any(axis=(1, 3))


def _pieces(cells: np.ndarray, shape: tuple[int, int], least: float) -> int:
    """Connected parts (8-neighbours) of at least ``least`` blocks of the figure's blocks ``cells``
    (bool, flat over a grid of ``shape``)."""
    count, _, stats, _ = cv2.connectedComponentsWithStats(cells.reshape(shape).astype(np.uint8), connectivity=8)
    return int((stats[1:, cv2.CC_STAT_AREA] >= least).sum())


def shown_figure(maps: tuple[np.ndarray, np.ndarray], valid: tuple[np.ndarray, np.ndarray], alpha: np.ndarray,
                 figure_to_views: tuple[np.ndarray, np.ndarray], mask: np.ndarray) -> ShownFigure:
    """What the output shows of the figure (``ShownFigure``), from each view's (source's, target's):
    ``maps`` (H, W, 2) the canvas's (x, y) sample positions in it, ``valid`` (H, W) where they are in
    it, ``figure_to_views`` (2, 3) the affine from the figure's pixels to it; ``alpha`` (H, W) the
    source's weight where both are valid; ``mask`` (h, w) bool the figure's pixels."""
    grid = block_mask(mask).shape
    size = grid[0] * grid[1]
    seen, shown, where = [], [], []
    for view, (map_canvas, affine) in enumerate(zip(maps, figure_to_views)):
        window = _window(map_canvas, affine, mask)  # the figure's few canvas pixels, not all of them
        weight = view_weights(alpha[window], valid[0][window], valid[1][window])[view]
        cell, inside = _figure_blocks(map_canvas[window], valid[view][window], affine, mask)
        rows, cols = np.mgrid[window]
        hits = np.bincount(cell[inside], minlength=size)
        seen.append(hits > 0)
        shown.append(np.bincount(cell[inside & (weight >= SHOWN_WEIGHT)], minlength=size) > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            where.append(np.stack([np.bincount(cell[inside], c[inside], minlength=size) / hits
                                   for c in (cols, rows)], axis=1))
    both = seen[0] & seen[1]
    apart = float(np.median(np.hypot(*(where[0][both] - where[1][both]).T))) if both.any() else None
    truth = int(max(seen[0].sum(), seen[1].sum()))
    union = shown[0] | shown[1]
    least = PIECE_SHARE * truth
    together = apart is not None and apart <= COINCIDE_PX
    pieces = _pieces(union, grid, least) if together else sum(_pieces(s, grid, least) for s in shown)
    twice = 0 if together else int((shown[0] & shown[1]).sum())
    from_src = int(shown[0].sum())
    return ShownFigure(truth=truth, shown=int(union.sum()), twice=twice, pieces=pieces, apart_px=apart,
                       source_share=from_src / max(1, from_src + int(shown[1].sum())))


class CrossingFigures:
    """The observer measuring a stitched crossing clip (``stitch_videos(observer=...)``): per frame,
    what the output shows of the figure (:func:`shown_figure`); :meth:`figures` when the run is done.
    ``keep_frames``: output frame indices whose (y, u, v) planes and seam are kept (``frames``)."""

    def __init__(self, clip: CrossingClip, keep_frames: tuple[int, ...] = ()):
        self.clip = clip
        self.keep_frames = set(keep_frames)
        self.per_frame: list[dict] = []
        self.frames: dict[int, tuple[tuple[np.ndarray, ...], np.ndarray, bool]] = {}
        self._valid: tuple[np.ndarray, np.ndarray] | None = None

    def __call__(self, frame: CompositedFrame) -> None:
        affines = self.clip.affines(frame.index, frame.source)
        if affines is None:
            return
        maps = frame.maps
        if self._valid is None:
            self._valid = (sampled_mask(maps.map_src_luma, frame.planes_src[0].shape),
                           sampled_mask(maps.map_tgt_luma, frame.planes_tgt[0].shape))
        alpha, _ = frame.weights()
        shown = shown_figure((maps.map_src_luma, maps.map_tgt_luma), self._valid, alpha, affines, self.clip.mask)
        self.per_frame.append({"frame": frame.index, **shown.as_dict()})
        if frame.index in self.keep_frames:
            self.frames[frame.index] = (tuple(p.copy() for p in frame.canvas()), frame.seam.copy(),
                                        frame.lines_are_rows)

    def figures(self) -> dict:
        """JSON-ready: frames counted (the figure on the canvas), frames not whole, frames doubled, the
        least shown share, the most pieces, and every frame's figures."""
        counted = [f for f in self.per_frame if f["truth_blocks"] > 0]
        return {
            "walk": self.clip.walk.name,
            "frames_counted": len(counted),
            "frames_not_whole": [f["frame"] for f in counted if not f["whole"]],
            "frames_doubled": [f["frame"] for f in counted if f["doubled"]],
            "shown_pct_min": min((f["shown_pct"] for f in counted), default=None),
            "pieces_max": max((f["pieces"] for f in counted), default=0),
            "per_frame": self.per_frame,
        }
