"""``video/frame_objects.py`` on made-up bands: each view's background model, the objects' blobs,
their copies paired across the views, the strips the seam keeps off, and the route round them. The
per-frame seam that uses them is tested in test_video_frame_seam.py, on a real recording in
test_crossing.py."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sena_warp.config import Config
from sena_warp.kernels.composite import NOT_BOTH
from sena_warp.video.frame_objects import (ObjectBand, ObjectGrid, ViewBackground, blobs, keep_off_cells, merge_strips,
                                           pair_copies, route_cost, solid, whole_band_fit)
from sena_warp.video.frame_seam import BandFrame

CFG = Config(device="cpu")
LINES, CELLS = 120, 61
FPS = 30.0


def textured(seed: int, shape: tuple[int, int] = (LINES, CELLS)) -> np.ndarray:
    """A textured view's luma on a band, float32, 20-200 grey levels."""
    return np.random.default_rng(seed).uniform(20.0, 200.0, shape).astype(np.float32)


def band_of(src: np.ndarray, tgt: np.ndarray, both: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(difference, sum) as ``band_difference`` gives them for the views' luma ``src`` / ``tgt``."""
    both = np.ones(src.shape, bool) if both is None else both
    return (np.where(both, src - tgt, NOT_BOTH).astype(np.float32),
            np.where(both, src + tgt, 0.0).astype(np.float32))


def test_an_exposure_step_over_the_whole_band_is_explained_by_its_gain_and_offset():
    background = textured(1)
    both = np.ones(background.shape, bool)
    both[:, :5] = False  # cells outside the overlap do not enter the fit
    luma = np.where(both, 1.15 * background + 7.0, 900.0).astype(np.float32)

    def unexplained(now):
        gain, offset = whole_band_fit(background, now, both, 12.0)
        return now - background - ((gain - 1.0) * background + offset)

    assert np.abs(unexplained(luma)[both]).max() < 0.01
    # An object over 15 % of the band does not enter the fit: the rest stays explained.
    luma[40:80, 18:46] += 80.0
    outside = both.copy()
    outside[40:80, 18:46] = False
    assert np.abs(unexplained(luma)[outside]).max() < 0.5


def test_each_view_s_foreground_is_its_own():
    models = ViewBackground((LINES, CELLS), FPS, CFG)
    src, tgt = textured(2), textured(3)
    rng = np.random.default_rng(4)
    noisy = [(src + rng.normal(0, 1.5, src.shape), tgt + rng.normal(0, 1.5, tgt.shape)) for _ in range(20)]
    assert not models.update(*band_of(*noisy[0])).any()  # the first frame is the model
    for pair in noisy[1:]:
        assert not models.update(*band_of(*pair)).any()  # encoder-like noise: nothing in front
    # Both cameras' exposure steps, by 12 % and 5 levels, by 5 % and -3: still nothing in front.
    now_src, now_tgt = 1.12 * noisy[-1][0] + 5.0, 1.05 * noisy[-1][1] - 3.0
    assert not models.update(*band_of(now_src, now_tgt)).any()
    # An object in front, 40 px nearer than the background: its copies lie 40 cells apart.
    now_src, now_tgt = now_src.copy(), now_tgt.copy()
    now_src[50:80, 45:55] = 250.0
    now_tgt[50:80, 5:15] = 250.0
    off = models.update(*band_of(now_src, now_tgt))
    expected = np.zeros((2, LINES, CELLS), bool)
    expected[0, 50:80, 45:55] = expected[1, 50:80, 5:15] = True
    assert (off.astype(bool) == expected).mean() > 0.98 and off[0, 55:75, 47:53].all() and off[1, 55:75, 7:13].all()
    # Cells without both views are no one's foreground.
    both = np.ones((LINES, CELLS), bool)
    both[:, :20] = False
    assert not models.update(*band_of(now_src, now_tgt, both))[:, :, :20].any()


def test_cells_that_keep_changing_stop_being_foreground():
    # Leaves in the wind: a patch of one view that changes by +-30 every frame stops counting as
    # something in front once the model has learnt its spread (about the model's time constant).
    models = ViewBackground((LINES, CELLS), FPS, CFG)
    src, tgt = textured(5), textured(6)
    rng = np.random.default_rng(7)
    for _ in range(int(FPS)):  # a second of the still scene: the model settles
        models.update(*band_of(src, tgt))
    found = []
    for _ in range(int(3 * FPS * CFG.video_seam_background_s)):
        now = src.copy()
        now[10:40, 5:25] += rng.choice([-30.0, 30.0], (30, 20)).astype(np.float32)
        found.append(bool(solid(models.update(*band_of(now, tgt))[0], 3)[10:40, 5:25].any()))
    assert found[0] and not any(found[-int(FPS):])


def covered_while_walking_past(cfg: Config, frames: int) -> list[float]:
    """Per frame, the share of a striped figure's cells in front of the source's background (``solid``)
    while it walks past: stripes of 70 and 185 grey levels, 12 px apart on 4 px cells (3 cells), a cell
    a frame, in front of a wall of about 125 that the model has seen empty for a time constant."""
    models = ViewBackground((LINES, CELLS), FPS, cfg)
    wall = (125.0 + np.random.default_rng(15).uniform(-8.0, 8.0, (LINES, CELLS))).astype(np.float32)
    rng = np.random.default_rng(16)
    for _ in range(int(FPS * cfg.video_seam_background_s)):
        models.update(*band_of(wall + rng.normal(0.0, 1.5, wall.shape).astype(np.float32), wall))
    lines, cells = np.mgrid[0:LINES, 0:CELLS]
    inside = (lines >= 30) & (lines < 90) & (cells >= 10) & (cells < 50)
    covered = []
    for frame in range(frames):
        stripes = np.where((2 * (lines + cells - frame) // 3) % 2 == 0, 70.0, 185.0)
        now = np.where(inside, stripes, wall + rng.normal(0.0, 1.5, wall.shape)).astype(np.float32)
        covered.append(float(solid(models.update(*band_of(now, wall))[0], 3)[inside].mean()))
    return covered


def test_a_textured_object_walking_past_stays_in_front_while_it_passes():
    # Each of the figure's cells flips between its stripes on two frames of three. That is the figure's
    # texture, not the wall's usual change: it stays in front while a wide one passes (the crossing
    # benchmark's 150 px at 6 px a frame: 25 frames). With the spread learnt as fast where the view
    # is off as elsewhere (video_seam_spread_learn 1) it was gone within 20 frames, and the route cut
    # the trailing part of such a figure; at a quarter of the rate it stays for 40 (4 px a frame).
    assert min(covered_while_walking_past(CFG, 25)) > 0.95
    assert max(covered_while_walking_past(replace(CFG, video_seam_spread_learn=1.0), 25)[20:]) < 0.05
    assert min(covered_while_walking_past(replace(CFG, video_seam_spread_learn=0.25), 40)) > 0.95


def test_someone_standing_still_stays_in_front_for_a_while():
    # The model learns video_seam_foreground_learn as fast where a view is off it: once it has seen the
    # empty scene for a time constant (its first frames are learnt as their running mean).
    models = ViewBackground((LINES, CELLS), FPS, CFG)
    src, tgt = textured(8), textured(9)
    for _ in range(int(FPS * CFG.video_seam_background_s)):
        models.update(*band_of(src, tgt))
    now = src.copy()
    now[30:60, 20:30] = 240.0
    frames = int(2 * FPS * CFG.video_seam_background_s)  # two time constants
    assert all(models.update(*band_of(now, tgt))[0, 35:55, 22:28].all() for _ in range(frames))


def rectangle(shape: tuple[int, int], lines: slice, cells: slice) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    mask[lines, cells] = 1
    return mask


def test_blobs_are_the_connected_parts_with_their_extent_on_each_line():
    mask = rectangle((LINES, CELLS), slice(10, 30), slice(5, 12)) | rectangle((LINES, CELLS), slice(50, 53), slice(40, 42))
    mask[20, 12:20] = 1  # an arm on one line
    found = blobs(mask, 9)
    assert len(found) == 1  # the 3 x 2 speck is below the least
    blob = found[0]
    assert (blob.first_line, blob.last_line, blob.area) == (10, 29, 20 * 7 + 8)
    assert blob.starts.tolist() == [5] * 20 and blob.ends[10] == 20 and blob.ends[0] == 12


def test_copies_on_the_same_lines_pair_and_the_rest_stay_alone():
    shape = (LINES, CELLS)
    near = blobs(rectangle(shape, slice(20, 80), slice(40, 52)), 1)[0]  # the source's copy
    far = blobs(rectangle(shape, slice(22, 82), slice(10, 22)), 1)[0]  # the target's, 30 cells left
    other = blobs(rectangle(shape, slice(90, 110), slice(10, 40)), 1)[0]  # someone else, on other lines
    pairs = pair_copies([near], [far, other], CELLS)
    assert (near, far) in pairs and (None, other) in pairs and len(pairs) == 2
    assert pair_copies([near], [far], 20) == [(near, None), (None, far)]  # further apart than reach
    # A source blob left of the target's is no copy of it (a nearer object's source copy lies right):
    # what the source's model learnt where someone stood, a second person.
    assert pair_copies([far], [near], CELLS) == [(far, None), (None, near)]
    # Walking in at the target's border (the band's first cell): its cut copy ends left of the
    # source's, which is whole, and begins where the overlap does.
    entering_tgt = blobs(rectangle(shape, slice(20, 80), slice(0, 10)), 1)[0]
    entering_src = blobs(rectangle(shape, slice(20, 80), slice(0, 14)), 1)[0]
    assert pair_copies([entering_src], [entering_tgt], CELLS) == [(entering_src, entering_tgt)]
    level = blobs(rectangle(shape, slice(22, 82), slice(41, 53)), 1)[0]  # at the background's depth, a cell off
    assert pair_copies([level], [near], CELLS) == [(level, near)]
    # A person close to both cameras, wider than the overlap: the source's copy cut by the band's right
    # end, the target's by its left end, on most of the same lines.
    wide_src = blobs(rectangle(shape, slice(10, 110), slice(6, CELLS)), 1)[0]
    wide_tgt = blobs(rectangle(shape, slice(14, 100), slice(0, CELLS - 6)), 1)[0]
    assert pair_copies([wide_src], [wide_tgt], CELLS) == [(wide_src, wide_tgt)]


def kept_off(pairs, both, first, margin_cells=2, margin_lines=3, most=4) -> np.ndarray:
    return keep_off_cells(pairs, both, first, margin_cells, margin_lines, most, np.zeros(both.shape, np.uint8))


def strip_of(line: np.ndarray) -> tuple[int, int]:
    """(first, one past the last) cell kept off on a line holding one strip; (0, 0) for none."""
    on = np.flatnonzero(line)
    assert on.size == 0 or on.size == on[-1] - on[0] + 1, "one strip"
    return (int(on[0]), int(on[-1]) + 1) if on.size else (0, 0)


def test_the_strip_spans_both_copies_and_runs_on_to_a_border_that_cuts_one():
    shape = (LINES, 101)
    both = np.zeros(shape, bool)
    both[:, 10:91] = True  # the overlap: cells 10 to 90
    first = np.zeros(LINES, np.int64)
    src = blobs(rectangle(shape, slice(20, 60), slice(50, 60)), 1)[0]
    tgt = blobs(rectangle(shape, slice(20, 60), slice(30, 40)), 1)[0]
    cells = kept_off([(src, tgt)], both, first)
    assert strip_of(cells[17]) == (28, 62) and not cells[16].any()  # 3 lines above
    assert all(strip_of(cells[k]) == (28, 62) for k in range(17, 63)) and not cells[63:].any()
    # The source's copy at the source's border (its right end): on to the band's end, shown from the target.
    cut = blobs(rectangle(shape, slice(20, 60), slice(82, 91)), 1)[0]
    assert strip_of(kept_off([(cut, tgt)], both, first)[30]) == (28, 101)
    # A target's copy at the target's border (its left end) on a band whose lines begin 5 cells
    # further on every line: the extents are taken where each line begins.
    shifted = first + 5 * (np.arange(LINES) // 40)
    cut = blobs(rectangle(shape, slice(20, 60), slice(10, 20)), 1)[0]
    cells = kept_off([(src, cut)], both, shifted)
    assert strip_of(cells[30]) == strip_of(cells[45]) == (0, 62)


def test_an_object_wider_than_the_overlap_allows_is_passed_at_one_end_on_all_its_lines():
    # The overlap: cells 10 to 90. A figure whose target copy lies against the target's border (cells
    # 10-69) and whose source copy reaches to within a cell of the source's border on its upper lines
    # (30-88) and to 5 cells of it below (30-84): no room on either side of the upper lines, room on
    # the source's side of the lower ones. Shown from the source, where its copy has the more room: on
    # every line the strip stops at the source's copy, the last cell holding both views left open.
    shape = (LINES, 101)
    both = np.zeros(shape, bool)
    both[:, 10:91] = True
    first = np.zeros(LINES, np.int64)
    tgt = blobs(rectangle(shape, slice(20, 61), slice(10, 70)), 1)[0]
    src_cells = rectangle(shape, slice(20, 41), slice(30, 89)) | rectangle(shape, slice(41, 61), slice(30, 85))
    src = blobs(src_cells, 1)[0]
    cells = kept_off([(src, tgt)], both, first)
    assert cells[20:61, :87].all() and not cells[20:61, 89:].any()
    assert strip_of(cells[30]) == (0, 89) and strip_of(cells[55]) == (0, 87)  # the copy, its margin below
    # The other way round (the source's copy against its border, the target's a cell and five cells
    # off its own): shown from the target, on every line.
    tgt_cells = rectangle(shape, slice(20, 41), slice(11, 70)) | rectangle(shape, slice(41, 61), slice(15, 70))
    src = blobs(rectangle(shape, slice(20, 61), slice(31, 91)), 1)[0]
    cells = kept_off([(src, blobs(tgt_cells, 1)[0])], both, first)
    assert cells[20:61, 13:].all() and not cells[20:61, :11].any()


def test_strips_merge_and_the_narrowest_gaps_close_beyond_the_most():
    assert merge_strips([(10, 20), (15, 30), (40, 50)], 4) == [(10, 30), (40, 50)]
    assert merge_strips([(0, 5), (8, 10), (30, 40), (45, 70)], 2) == [(0, 10), (30, 70)]
    # Three people side by side on the same lines: three strips, or two with the narrowest gap closed.
    shape = (LINES, 101)
    both = np.ones(shape, bool)
    first = np.zeros(LINES, np.int64)
    people = [(blobs(rectangle(shape, slice(20, 60), slice(x, x + 6)), 1)[0], None) for x in (20, 40, 80)]
    three = kept_off(people, both, first, margin_cells=2, margin_lines=0, most=3)[40]
    assert np.flatnonzero(np.diff(np.r_[0, three, 0])).tolist() == [18, 28, 38, 48, 78, 88]
    two = kept_off(people, both, first, margin_cells=2, margin_lines=0, most=2)[40]
    assert np.flatnonzero(np.diff(np.r_[0, two, 0])).tolist() == [18, 48, 78, 88]


def test_the_route_costs_home_and_the_strips_and_blocks_cells_without_both_views():
    kept = np.zeros((3, 5), np.uint8)
    kept[1, 1:3] = 1
    both = np.ones((3, 5), bool)
    both[2, 4] = False
    home_term = np.float32([[0.0, 1.5, 3.0, 4.5, 6.0]] * 3)
    cost = route_cost(kept, both, home_term, CFG, np.zeros((3, 5), np.float32))
    expected = home_term + CFG.video_seam_object_cost * kept + CFG.video_seam_blocked_cost * ~both
    np.testing.assert_array_equal(cost, expected.astype(np.float32))


class Overlap:
    """A stand-in for the device frame over an overlap of (LINES, ``width``) px from position 0: the
    views' luma ``src`` / ``tgt`` sampled on an object band's cells, as ``DeviceFrame.objects`` gives them."""

    def __init__(self, src: np.ndarray, tgt: np.ndarray):
        self.src, self.tgt = src, tgt

    def band(self, grid: ObjectGrid) -> BandFrame:
        taken = grid.x0[:, None] + grid.cell * np.arange(grid.width)[None, :]
        inside = taken < self.src.shape[1]
        taken = np.clip(taken, 0, self.src.shape[1] - 1)
        src, tgt = (np.take_along_axis(v[grid.lines], taken, axis=1) for v in (self.src, self.tgt))
        diff, total = band_of(src, tgt, inside)
        return BandFrame.of(diff, total, np.zeros(diff.shape, np.float32))


def test_the_route_leaves_home_only_to_go_round_an_object_and_keeps_its_side():
    width, home = 400, 200.0
    overlap = np.tile(np.int32([0, width - 1]), (LINES, 1))
    objects = ObjectBand(ObjectGrid.of(np.full(LINES, home, np.float32), overlap, 1), FPS, CFG)
    src, tgt = textured(10, (LINES, width)), textured(11, (LINES, width))
    frames = Overlap(src, tgt)
    for _ in range(int(FPS)):  # a second of the empty scene: the models settle
        assert not objects.update(frames.band(objects.grid))  # the route did not change
    np.testing.assert_array_equal(objects.centre(np.arange(LINES)), home)  # nothing in front: home
    # A figure 60 px wide and 20 px nearer than the background, walking right across the seam's home.
    sides = []
    for left in range(100, 300, 8):
        frames.src, frames.tgt = src.copy(), tgt.copy()
        frames.src[30:90, left + 20:left + 80] = 240.0
        frames.tgt[30:90, left:left + 60] = 240.0
        objects.update(frames.band(objects.grid))
        centre = objects.centre(np.arange(30, 90))
        assert np.all((centre <= left - 8) | (centre >= left + 80 + 8))  # clear of both copies and the strip
        sides.append("left" if centre.mean() < left else "right")
    assert sides[0] == "right" and sides[-1] == "left" and sides.count("right") == sides.index("left")  # one jump


def test_a_camera_settling_over_its_first_frames_leaves_nothing_in_front():
    # A webcam's first frames: the first one far off (60 levels darker on a third of the band, as the
    # office recording's left camera starts), the exposure settling over the next five. A model that
    # kept its first frame saw a third of the band in front for seconds; the running mean of the first
    # frames forgets it within a second.
    models = ViewBackground((LINES, CELLS), FPS, CFG)
    src, tgt = textured(12), textured(13)
    rng = np.random.default_rng(14)
    first = src.copy()
    first[:, :20] -= 60.0
    models.update(*band_of(first, tgt))
    for gain in (0.8, 0.9, 0.95, 0.98, 1.0):
        models.update(*band_of(gain * src, tgt))
    found = [bool(solid(models.update(*band_of(src + rng.normal(0.0, 2.0, src.shape).astype(np.float32), tgt))[0],
                        3).any()) for _ in range(int(FPS))]
    assert not any(found[int(FPS) // 3:])
