"""``video/frame_seam.py`` on synthetic bands: its grid, the line dilation, the glide, the jump round
what is in front (``frame_objects``, tested in test_video_frame_objects.py) and a new estimate's band.
The per-frame seam on real clips is tested in test_video_stitch.py (still lines) and test_crossing.py
(a figure crossing the seam)."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.video.frame_seam import BandFrame, FrameSeam, cell_px, gentle, line_step, lines_near

CFG = Config(device="cpu")
LINES, BAND = 120, 30
REACH = 3 * BAND  # both views are sampled within this of the estimate's seam: the overlap
FPS = 30.0


def static_band(seed: int) -> np.ndarray:
    """A textured overlap's source-plus-target luma (L, 2 REACH + 1) float32, 40-400 grey levels."""
    rng = np.random.default_rng(seed)
    return rng.uniform(40.0, 400.0, (LINES, 2 * REACH + 1)).astype(np.float32)


HOME = 200  # the estimate's seam on every line; the overlap's arrays below start at HOME - REACH
OVERLAP = np.tile(np.int32([HOME - REACH, HOME + REACH]), (LINES, 1))  # where both views are, per line


def seam(cfg: Config = CFG, cell: int = 1) -> FrameSeam:
    """A static rig's seam (it watches what is in front) on cells of ``cell`` px."""
    return FrameSeam(np.full(LINES, float(HOME), np.float32), BAND, cell, OVERLAP, True, FPS, cfg)


def test_a_cell_is_the_same_share_of_the_inputs_whatever_their_size():
    def cell(*shapes):
        return cell_px(shapes, CFG)

    assert cell((480, 640), (480, 640)) == 1  # the shared 640-px recordings
    assert cell((480, 270), (480, 270)) == 1  # a portrait phone clip
    assert cell((720, 1280), (720, 1280)) == 2
    assert cell((1080, 1920), (1080, 1920)) == cell((1920, 1080), (1920, 1080)) == 3
    assert cell((2160, 3840), (2160, 3840)) == 6
    assert cell((2160, 3840), (720, 1280)) == 2  # the smaller input's
    # Square cells: solved on every cell-th line where cells are wider than the line step.
    assert [line_step(c, CFG) for c in (1, 2, 3, 6)] == [CFG.video_seam_line_step, 2, 3, 6]


def test_lines_near_is_a_dilation_along_the_lines():
    rng = np.random.default_rng(3)
    for reach in (0, 1, 4, 200):
        flags = rng.random(50) < 0.05
        expected = np.array([flags[max(0, i - reach): i + reach + 1].any() for i in range(50)])
        np.testing.assert_array_equal(lines_near(flags, reach), expected)


def test_gentle_moves_a_centre_line_no_more_than_a_path_can_follow():
    # A step of 30 px between two lines: clamped forwards (the rise spread over the next lines), then
    # backwards (the fall over the lines before it).
    out = gentle(np.float64([0, 0, 30, 30, 30, 0, 0]), 10.0)
    np.testing.assert_array_equal(out, [0, 0, 10, 20, 30, 20, 10])
    np.testing.assert_array_equal(gentle(np.arange(5.0), 2.0), np.arange(5.0))  # already gentle: unchanged


class BandFrames:
    """A stand-in for the device frame: the overlap's difference and sum of the current frame, given
    (L, 2 REACH + 1) per px from HOME - REACH, sampled on a seam's solved lines' cells as
    ``DeviceFrame.band`` gives them (with the change from the difference it gave last), with its
    object band's where it has one."""

    def __init__(self, diff: np.ndarray, total: np.ndarray):
        self.diff, self.total = diff, total
        self.last: np.ndarray | None = None

    def sampled(self, lines: np.ndarray, x0: np.ndarray, cell: int, width: int) -> tuple[np.ndarray, np.ndarray]:
        taken = x0[:, None] + cell * np.arange(width)[None, :] - (HOME - REACH)
        inside = (taken >= 0) & (taken <= 2 * REACH)
        taken = np.clip(taken, 0, 2 * REACH)
        diff = np.where(inside, np.take_along_axis(self.diff[lines], taken, axis=1), NOT_BOTH).astype(np.float32)
        total = np.where(inside, np.take_along_axis(self.total[lines], taken, axis=1), 0.0).astype(np.float32)
        return diff, total

    def band(self, seam: FrameSeam) -> tuple[BandFrame, BandFrame | None]:
        diff, total = self.sampled(seam.grid.lines, seam.place.x0, seam.cell, seam.grid.width)
        last = self.last if self.last is not None else np.zeros_like(diff)
        delta = np.where((diff < 0.5 * NOT_BOTH) & (last < 0.5 * NOT_BOTH), np.abs(diff - last), 0.0)
        self.last = diff
        if seam.objects is None:
            return BandFrame.of(diff, total, delta.astype(np.float32)), None
        grid = seam.objects.grid
        diff_o, total_o = self.sampled(grid.lines, grid.x0, grid.cell, grid.width)
        return BandFrame.of(diff, total, delta.astype(np.float32)), BandFrame.of(diff_o, total_o, np.zeros_like(diff_o))


def next_seam(seam: FrameSeam, frames: BandFrames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seam of the next frame of ``frames``, as the video's frame path takes it."""
    return seam.next(*frames.band(seam))


def valley_band(column: int) -> np.ndarray:
    """An overlap's difference falling by 3 grey levels a px to 0 at ``column`` (from HOME - REACH)."""
    cells = np.arange(2 * REACH + 1, dtype=np.float32)
    return np.broadcast_to(3.0 * np.abs(cells - column), (LINES, 2 * REACH + 1)).copy()


def valley_seam(cell: int, seed: int) -> tuple[FrameSeam, BandFrames]:
    """A seam on cells of ``cell`` px and frames whose difference's valley is at its home, over a
    textured background (``static_band(seed)``)."""
    return seam(cell=cell), BandFrames(valley_band(REACH), static_band(seed))


@pytest.mark.parametrize("cell", [1, 2, 3])
def test_a_moving_rig_s_seam_glides_and_then_stays(cell):
    # The difference's valley moves 20 px away at once: a moving rig's seam may follow at
    # video_seam_speed_px a frame (one cell where cells are wider), not jump; once nothing changes it
    # keeps its place (still lines), though the valley is still 18 px away.
    band = FrameSeam(np.full(LINES, float(HOME), np.float32), BAND, cell, OVERLAP, False, FPS, CFG)
    frames = BandFrames(valley_band(REACH), static_band(7))
    first, _, _ = next_seam(band, frames)
    assert np.abs(first - HOME).max() <= cell // 2  # home, the valley (its nearest cell)
    next_seam(band, frames)
    frames.diff = valley_band(REACH + 20)
    moved, _, _ = next_seam(band, frames)
    step = np.abs(moved - first)
    assert step.max() <= max(CFG.video_seam_speed_px, cell) and step.max() > 0
    for _ in range(3):  # the same frame again: every line still, the seam stays
        again, _, _ = next_seam(band, frames)
        np.testing.assert_array_equal(again, moved)
        assert band.still.all()


@pytest.mark.parametrize("cell", [1, 2, 3])
def test_the_seam_steps_round_an_object_in_front_of_the_background(cell):
    band, frames = valley_seam(cell, 8)
    background = frames.total
    for _ in range(int(FPS)):  # a second of the empty scene: the background models settle
        home, _, _ = next_seam(band, frames)
    # A 100-line object 24 cells wide from 10 cells before the seam (it is found on cells four times as
    # wide), 80 levels brighter in both views; its two copies differ little inside (a smooth object),
    # at its edges a lot.
    start, end = REACH - 10 * cell, REACH + 14 * cell
    frames.total = background.copy()
    frames.total[10:110, start:end] += 160.0
    frames.diff = valley_band(REACH)
    frames.diff[10:110, start:end] = 2.0
    frames.diff[10:110, [start, start + 1, end - 2, end - 1]] = 60.0
    # The object band comes down with the seam's band: the band is placed round the object for the
    # frame after the one it appeared in (an object that walks in is seen on the overlap before).
    next_seam(band, frames)
    positions, offsets_src, offsets_tgt = next_seam(band, frames)
    at = positions - (HOME - REACH)
    assert np.all((at[10:110] < start) | (at[10:110] >= end))  # round the object, not through it
    assert np.abs(positions - home).max() > max(CFG.video_seam_speed_px, cell)  # a jump, not a glide
    assert offsets_src.shape == (LINES, 1) and np.allclose(offsets_src, -offsets_tgt)


def test_a_reset_to_the_same_home_keeps_the_band_and_a_new_home_starts_it_again():
    band, frames = valley_seam(1, 9)
    for _ in range(3):
        next_seam(band, frames)
    assert band.still.all()  # nothing changes: every line still
    band.reset(band.home.copy(), OVERLAP)  # the maps moved with a camera's drift, the seam did not
    next_seam(band, frames)
    assert band.still.all()  # the last difference was kept: still at once
    band.reset(band.home + 4.0, OVERLAP + 4)  # a new estimate's seam: the band's cells moved
    next_seam(band, frames)
    assert not band.still.any()  # no last difference on the new cells: nothing is still yet
    next_seam(band, frames)
    assert band.still.all()


def test_a_moving_plan_drops_the_object_band_and_a_static_one_learns_a_new_one():
    band, frames = valley_seam(2, 8)
    background = frames.total
    for _ in range(int(FPS)):
        next_seam(band, frames)
    frames.total = background.copy()
    frames.total[10:110, REACH - 20:REACH + 28] += 160.0  # an object on the seam: the band goes round it
    for _ in range(2):
        next_seam(band, frames)
    home_x0 = band.place.x0.copy()
    assert band.jumps and band.objects is not None
    band.set_jumps(False)  # the rig started moving: nothing is in front of a background that moves
    assert not band.jumps and band.objects is None
    assert not band.work.host["moving"].any() and not band.work.host["kept_off"].any()
    centred = FrameSeam(band.home, BAND, 2, OVERLAP, False, FPS, CFG).place.x0
    np.testing.assert_array_equal(band.place.x0, centred)  # the band back about the estimate's seam
    assert not np.array_equal(home_x0, centred)
    next_seam(band, frames)  # a moving plan's frame: no object band comes down
    band.set_jumps(True)  # static again: a new object band, whose models learn from the next frame
    assert band.objects is not None and band.objects.pairs == []
