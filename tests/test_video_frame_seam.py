"""``video/frame_seam.py`` on synthetic bands: the background model behind the static rig's motion
cost, the whole band's exposure fit and the line dilation. The per-frame seam on real clips is tested
in test_video_stitch.py (still lines) and test_crossing.py (an object crossing the seam)."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.video.frame_seam import BandFrame, FrameSeam, cell_px, line_step, lines_near, whole_band_fit

CFG = Config(device="cpu")
LINES, BAND = 120, 30
FPS = 30.0


def static_band(seed: int) -> np.ndarray:
    """A textured band's source-plus-target luma (L, 2 BAND + 1) float32, 40-400 grey levels."""
    rng = np.random.default_rng(seed)
    return rng.uniform(40.0, 400.0, (LINES, 2 * BAND + 1)).astype(np.float32)


HOME = 100  # the estimate's seam on every line; the bands below start at HOME - BAND


def seam(cfg: Config = CFG, cell: int = 1) -> FrameSeam:
    return FrameSeam(np.full(LINES, float(HOME), np.float32), BAND, cell, True, FPS, cfg)


def model_seam() -> FrameSeam:
    """A seam solved on every line: its band's cells are ``static_band``'s."""
    return seam(CFG.replace(video_seam_line_step=1))


def in_front(band: FrameSeam, total: np.ndarray, both: np.ndarray) -> np.ndarray:
    """``band.foreground`` of a band's source-plus-target ``total`` and the cells holding ``both`` views."""
    diff = np.where(both, 0.0, NOT_BOTH).astype(np.float32)
    return band.model.foreground(BandFrame.of(diff, total.astype(np.float32), np.zeros_like(diff)))


def explained_change(background: np.ndarray, total: np.ndarray, both: np.ndarray, noise: float) -> np.ndarray:
    """The change of ``total`` from ``background`` that the whole band's fit explains."""
    gain, offset = whole_band_fit(background, total, both, noise)
    return (gain - 1.0) * background + offset


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


def test_an_exposure_step_over_the_whole_band_is_explained_by_its_gain_and_offset():
    background = static_band(1)
    both = np.ones(background.shape, bool)
    both[:, :5] = False  # cells outside the overlap do not enter the fit
    total = np.where(both, 1.15 * background + 7.0, 900.0).astype(np.float32)
    explained = explained_change(background, total, both, 12.0)
    assert np.abs((total - background - explained)[both]).max() < 0.01
    # An object over 15 % of the band does not enter the fit: the rest stays explained.
    total[40:80, 18:46] += 160.0
    explained = explained_change(background, total, both, 12.0)
    outside = both.copy()
    outside[40:80, 18:46] = False
    assert np.abs((total - background - explained)[outside]).max() < 0.5


def test_an_object_is_foreground_and_an_exposure_step_or_noise_is_not():
    band = model_seam()
    background = static_band(2)
    both = np.ones(background.shape, bool)
    rng = np.random.default_rng(4)
    noisy = [background + rng.normal(0.0, 2.0, background.shape).astype(np.float32) for _ in range(20)]
    first = in_front(band, noisy[0], both)
    assert not first.any()  # the first frame is the model
    for frame in noisy[1:]:
        assert not in_front(band, frame, both).any()  # encoder-like noise: nothing in front
    # Both cameras' exposure steps by 12 % and 5 levels: still nothing in front.
    assert not in_front(band, 1.12 * noisy[-1] + 5.0, both).any()
    # A 16 x 12 object brighter than the background by 60 levels in one view.
    with_object = noisy[-1].copy()
    with_object[50:66, 20:32] += 60.0
    moving = in_front(band, with_object, both)
    assert moving[50:66, 20:32].all()
    box = 2 * CFG.video_seam_still_box_px + 1  # grown by this much at most
    assert not moving[:50 - box].any() and not moving[66 + box:].any()
    assert not moving[:, :20 - box].any() and not moving[:, 32 + box:].any()


def test_cells_that_keep_changing_stop_being_foreground():
    # Leaves in the wind: a patch of the band that changes by +-30 every frame stops counting as
    # something in front once the model has learnt its spread (about the model's time constant).
    band = model_seam()
    background = static_band(5)
    both = np.ones(background.shape, bool)
    rng = np.random.default_rng(6)
    frames = int(3 * FPS * CFG.video_seam_background_s)
    found = []
    for _ in range(frames):
        frame = background.copy()
        frame[10:40, 5:25] += rng.choice([-30.0, 30.0], (30, 20)).astype(np.float32)
        found.append(bool(in_front(band, frame, both)[10:40, 5:25].any()))
    assert found[1] and not any(found[-int(FPS):])


class BandFrames:
    """A stand-in for the device frame: the band's difference and sum of the current frame, given
    (L, 2 BAND + 1) per px from HOME - BAND, sampled on a seam's solved lines' cells as
    ``DeviceFrame.band`` gives them, with the change from the difference it gave last."""

    def __init__(self, diff: np.ndarray, total: np.ndarray):
        self.diff, self.total = diff, total
        self.last: np.ndarray | None = None

    def band(self, seam: FrameSeam) -> BandFrame:
        solved = seam.grid.lines
        taken = seam.place.x0[:, None] + seam.cell * np.arange(seam.grid.width)[None, :] - (HOME - BAND)
        inside = (taken >= 0) & (taken <= 2 * BAND)
        taken = np.clip(taken, 0, 2 * BAND)
        diff = np.where(inside, np.take_along_axis(self.diff[solved], taken, axis=1), NOT_BOTH).astype(np.float32)
        total = np.where(inside, np.take_along_axis(self.total[solved], taken, axis=1), 0.0).astype(np.float32)
        last = self.last if self.last is not None else np.zeros_like(diff)
        delta = np.where(inside & (last < 0.5 * NOT_BOTH), np.abs(diff - last), 0.0).astype(np.float32)
        self.last = diff
        return BandFrame.of(diff, total, delta)


def next_seam(seam: FrameSeam, frames: BandFrames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seam of the next frame of ``frames``."""
    return seam.next(frames.band(seam))


def valley_band(column: int) -> np.ndarray:
    """A band difference falling by 3 grey levels a cell to 0 at ``column``."""
    cells = np.arange(2 * BAND + 1, dtype=np.float32)
    return np.broadcast_to(3.0 * np.abs(cells - column), (LINES, 2 * BAND + 1)).copy()


def valley_seam(cell: int, seed: int) -> tuple[FrameSeam, BandFrames]:
    """A seam on cells of ``cell`` px and frames whose difference's valley is at its home, over a
    textured background (``static_band(seed)``)."""
    return seam(cell=cell), BandFrames(valley_band(BAND), static_band(seed))


@pytest.mark.parametrize("cell", [1, 2, 3])
def test_without_anything_in_front_the_seam_glides_and_then_stays(cell):
    # The difference's valley moves 20 px away at once (nothing in front of the background): the seam
    # may follow at video_seam_speed_px a frame (one cell where cells are wider), not jump; once nothing
    # changes it keeps its place (still lines), though the valley is still 18 px away.
    band, frames = valley_seam(cell, 7)
    first, _, _ = next_seam(band, frames)
    assert np.abs(first - HOME).max() <= cell // 2  # home, the valley (its nearest cell)
    next_seam(band, frames)
    frames.diff = valley_band(BAND + 20)
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
    for _ in range(5):
        home, _, _ = next_seam(band, frames)
    # A 40-line object over band cells 18-45 (the seam at cell 30 runs through it), 80 levels brighter
    # in both views; its two copies differ little inside (a smooth object), at its edges a lot. The
    # background around it differs by 8 levels.
    frames.total = background.copy()
    frames.total[40:80, 18:46] += 160.0
    frames.diff = np.full((LINES, 2 * BAND + 1), 8.0, np.float32)
    frames.diff[40:80, 18:46] = 2.0
    frames.diff[40:80, [18, 19, 44, 45]] = 60.0
    positions, offsets_src, offsets_tgt = next_seam(band, frames)
    cells = positions - (HOME - BAND)
    assert np.all((cells[40:80] < 18) | (cells[40:80] > 45))  # round the object, not through it
    assert np.abs(positions - home).max() > max(CFG.video_seam_speed_px, cell)  # a jump, not a glide
    assert offsets_src.shape == (LINES, 1) and np.allclose(offsets_src, -offsets_tgt)


def test_a_reset_to_the_same_home_keeps_the_band_and_a_new_home_starts_it_again():
    band, frames = valley_seam(1, 9)
    for _ in range(3):
        next_seam(band, frames)
    assert band.still.all()  # nothing changes: every line still
    band.reset(band.home.copy())  # the maps moved with a camera's drift, the seam did not
    next_seam(band, frames)
    assert band.still.all()  # the last difference was kept: still at once
    band.reset(band.home + 4.0)  # a new estimate's seam: the band's cells moved
    next_seam(band, frames)
    assert not band.still.any()  # no last difference on the new cells: nothing is still yet
    next_seam(band, frames)
    assert band.still.all()
