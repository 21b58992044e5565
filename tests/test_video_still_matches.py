"""What moves, left out of the first estimate (``video/still_matches.py``, ``video_still_background``):
crafted matches of a still background and of a moving thing over five pairs, and the real cafe clip,
whose near person holds more matches than the room behind him."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.features import Matches
from sena_warp.video.estimate import Attempt, best_first_estimate, first_pairs, moving_in_front, pair_models
from sena_warp.video.reader import YuvFrame
from sena_warp.video.still_matches import moving_models, recurring, without_models

CFG = Config(device="cpu", video_still_background=True)
PAIRS = 5
BACKGROUND_SHIFT = np.array([20.0, 8.0])  # where the target sees the still background, from the source
NEAR_SHIFT = np.array([150.0, 5.0])  # ... and the near person: his parallax is larger


def matches_of(pts_a: np.ndarray, shift: np.ndarray, rng: np.random.Generator) -> Matches:
    pts_b = pts_a + shift + rng.normal(0.0, 0.3, pts_a.shape)  # a keypoint is found to about a pixel
    return Matches(pts_a + rng.normal(0.0, 0.3, pts_a.shape), pts_b, np.ones(len(pts_a)), len(pts_a), len(pts_a))


def joined(*parts: Matches) -> Matches:
    return Matches(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("pts_a", "pts_b", "scores")),
                   sum(p.n_keypoints_a for p in parts), sum(p.n_keypoints_b for p in parts))


def rig_pairs(moving_person: bool, moving_rig: bool, seed: int = 3) -> list[Matches]:
    """Five pairs' matches: 40 points of a still background (the same places in every pair, unless the
    rig moves them), and, with ``moving_person``, 60 points of a person at new places in each pair."""
    rng = np.random.default_rng(seed)
    background = rng.uniform([0, 0], [600, 450], (40, 2))
    pairs = []
    for k in range(PAIRS):
        still = matches_of(background + (k * 12.0 if moving_rig else 0.0), BACKGROUND_SHIFT, rng)
        person = matches_of(rng.uniform([150, 50], [450, 450], (60, 2)), NEAR_SHIFT, rng)
        pairs.append(joined(person, still) if moving_person else still)
    return pairs


def others(pairs: list[Matches], k: int) -> list[Matches]:
    return [m for j, m in enumerate(pairs) if j != k]


def test_a_still_background_recurs_and_a_moving_person_does_not():
    pairs = rig_pairs(moving_person=True, moving_rig=False)
    again = recurring(pairs[0], others(pairs, 0), CFG.video_recur_px)
    assert again[60:].mean() > 0.9 and again[:60].mean() < 0.05


def test_the_person_holding_the_most_matches_is_left_out_and_the_background_kept():
    pairs = rig_pairs(moving_person=True, moving_rig=False)
    models, found = moving_models(pairs[0], others(pairs, 0), CFG.video_recur_px, CFG)
    assert found and len(models) == 1
    assert np.allclose(models[0][:, 2], NEAR_SHIFT, atol=2.0)  # the model left out is the person's
    kept = without_models(pairs[0], models, CFG.ransac_reproj_px)
    assert len(kept) == 40 and np.allclose(np.median(kept.pts_b - kept.pts_a, axis=0), BACKGROUND_SHIFT, atol=0.5)


@pytest.mark.parametrize("moving_rig", [False, True])
def test_nothing_is_left_out_of_a_still_scene_or_a_moving_rig(moving_rig):
    """A still scene's first model is its background; a moving rig's points recur nowhere (all of the
    view moves between pairs): its matches are kept as they are either way."""
    pairs = rig_pairs(moving_person=False, moving_rig=moving_rig)
    models, found = moving_models(pairs[0], others(pairs, 0), CFG.video_recur_px, CFG)
    assert models == [] and found is not moving_rig


def test_the_bundled_office_leaves_nothing_out(bundled_dir):
    clips = bundled_dir / "video"
    cfg = CFG.replace(video_estimate_pairs=3)
    _, _, attempts = best_first_estimate(first_pairs(clips / "office_cam1.mp4", clips / "office_cam2.mp4", 0.0, cfg),
                                         cfg, "auto")
    assert [a.moving_left_out for a in attempts] == [0, 0, 0]
    assert not moving_in_front(attempts, attempts[0].pair, cfg)


@pytest.mark.shared
@pytest.mark.parametrize("still_background", [True, False])
def test_the_cafe_is_aligned_on_the_room_not_on_the_person_in_front(shared_dir, still_background):
    """Two webcams side by side see the room behind the person about 20 px apart and him 100-200 px
    apart (he is close to both); he holds most of the matches. With ``video_still_background`` the
    maps align the room; without (the default) the person."""
    clip = shared_dir / "videos" / "cafe_person_close"
    cfg = CFG.replace(video_still_background=still_background)
    maps, chosen, attempts = best_first_estimate(first_pairs(clip / "left.avi", clip / "right.avi", 0.0, cfg),
                                                 cfg, "auto")
    shift = np.abs(maps.warp.glob.affine_src_to_tgt[:, 2])
    if still_background:
        assert shift[0] < 40.0 and shift[1] < 20.0, shift
        assert any(a.moving_left_out > 0 for a in attempts) or chosen != max(attempts, key=lambda a: a.inliers).pair
    else:
        assert shift[0] > 100.0, shift
        assert all(a.moving_left_out == 0 for a in attempts)
    # Aligned on the person, the maps are what moves in front of the room: aligned every frame (timeline.py).
    assert moving_in_front(attempts, chosen, cfg) is not still_background


def attempt(pair: int, leading_recur: float | None, background: bool) -> Attempt:
    return Attempt(pair, 0.25 * pair, 100, None, 0, leading_recur, background)


@pytest.mark.parametrize("leading, backgrounds, expected", [
    ((0.0, 0.0), (True, False), True),  # the chosen pair's model is on what moves, another pair found the room
    ((0.0, 0.4), (False, True), False),  # the chosen pair's model recurs: a still scene's
    ((0.0, 0.0), (False, False), False),  # nothing recurs anywhere: a rig that moves
    ((0.0, 0.1), (True, False), False),  # the chosen model recurs in between: it says nothing
    ((0.0, None), (True, False), False),  # the chosen pair has no model
])
def test_the_estimate_is_on_something_in_front_when_its_model_moves_before_a_still_background(
        leading, backgrounds, expected):
    attempts = [attempt(k, recur, found) for k, (recur, found) in enumerate(zip(leading, backgrounds))]
    assert moving_in_front(attempts, 1, CFG) is expected


def test_the_models_of_each_pair_are_told_in_turn():
    """``PairModels`` of crafted pairs: the person first (recurring nowhere), the still room after him."""
    pairs = rig_pairs(moving_person=True, moving_rig=False)
    frame = YuvFrame(0.0, 0, np.zeros((450, 600), np.uint8), np.zeros((225, 300), np.uint8),
                     np.zeros((225, 300), np.uint8))  # the views' size: the matches are in its pixels
    judged = pair_models([(100, k, frame, frame, m) for k, m in enumerate(pairs)], CFG)
    assert all(j.leading_recur is not None and j.leading_recur < 0.05 and j.background and len(j.moving) == 1
               for j in judged)
