"""The first estimate's screening (``video/estimate.py``) on the bundled clips: pairs ranked at a lower
resolution, the chosen one estimated at the full working resolution, and a pair whose screening
failed still tried in full."""

from __future__ import annotations

import pytest

from sena_warp.config import Config
from sena_warp.video import estimate
from sena_warp.video.estimate import best_first_estimate, first_pairs, screening_config, spaced_pairs, spaced_span

CFG = Config(device="cpu", video_estimate_pairs=2)


@pytest.fixture(scope="module")
def clips(bundled_dir):
    return bundled_dir / "video"


@pytest.fixture
def full_estimates(monkeypatch) -> list:
    """The ``matches`` every full estimate was handed (None: it matched the pair itself)."""
    seen = []
    real = estimate.estimate_pair

    def spy(frame_l, frame_r, cfg, reference, matches=None):
        seen.append(matches)
        return real(frame_l, frame_r, cfg, reference, matches)

    monkeypatch.setattr(estimate, "estimate_pair", spy)
    return seen


def best_of(left, right, cfg):
    return best_first_estimate(first_pairs(left, right, 0.0, cfg), cfg, "auto")


def test_screening_caps_xfeat_working_side_only():
    hd = ((1080, 1920), (1080, 1920))
    assert screening_config(CFG, hd).xfeat_max_side == 640
    assert screening_config(CFG.replace(xfeat_max_side=512), hd).xfeat_max_side == 512  # never above the estimate's
    assert screening_config(CFG.replace(features="sift"), hd) == CFG.replace(features="sift")  # no working side
    # A side too small for XFeat on these frames (a side under 32 px): screened as they are estimated.
    tiny = CFG.replace(video_screen_max_side=40)
    assert screening_config(tiny, hd) == tiny


def test_inputs_within_the_screening_side_reuse_the_screening_matches(clips, full_estimates):
    """The office clips (640 px wide) are screened exactly as they are estimated: one matching per pair."""
    maps, chosen, attempts = best_of(clips / "office_cam1.mp4", clips / "office_cam2.mp4", CFG)
    assert len(full_estimates) == 1 and full_estimates[0] is not None
    assert maps.warp.glob.n_inliers == next(a.inliers for a in attempts if a.pair == chosen)


def test_a_pair_screened_smaller_is_matched_again_at_full_resolution(clips, full_estimates):
    cfg = CFG.replace(video_screen_max_side=384)
    maps, chosen, attempts = best_of(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", cfg)
    assert full_estimates == [None]
    screened = next(a.inliers for a in attempts if a.pair == chosen)
    assert maps.warp.glob.n_inliers > 1.3 * screened  # the full resolution finds more of the same model


def test_pairs_whose_screening_failed_are_still_estimated_in_full(clips, full_estimates):
    """At 384 px the office clips give too few matches on every pair; 640 px (the estimate's) is enough."""
    cfg = CFG.replace(video_screen_max_side=384)
    maps, chosen, attempts = best_of(clips / "office_cam1.mp4", clips / "office_cam2.mp4", cfg)
    assert chosen == 0 and full_estimates == [None]
    assert maps.warp.glob.n_inliers > 0
    # The report's attempts: the others' screening errors; the chosen pair's full estimate.
    assert [(a.inliers, a.error) for a in attempts if a.pair == chosen] == [(maps.warp.glob.n_inliers, None)]
    assert all(a.error is not None for a in attempts if a.pair != chosen)


def test_a_screening_side_too_small_for_xfeat_screens_at_the_estimate_s(clips, full_estimates):
    cfg = CFG.replace(video_screen_max_side=40)  # 640x480 at 40 px would be 32 x 0 px
    maps, chosen, attempts = best_of(clips / "office_cam1.mp4", clips / "office_cam2.mp4", cfg)
    assert len(full_estimates) == 1 and full_estimates[0] is not None
    assert maps.warp.glob.n_inliers == next(a.inliers for a in attempts if a.pair == chosen)


@pytest.mark.parametrize("available, taken, yielded", [(100, 21, [0, 5, 10, 15, 20]), (12, 12, [0, 5, 10]),
                                                       (1, 1, [0])])
def test_spaced_pairs_take_no_pair_after_the_last_they_yield(available, taken, yielded):
    pulled = []

    def pairs():
        for i in range(available):
            pulled.append(i)
            yield i, -i

    cfg = Config()  # five pairs, five apart
    assert [index for index, _, _ in spaced_pairs(pairs(), cfg)] == yielded
    assert len(pulled) == taken == min(available, spaced_span(cfg))


def test_first_pairs_are_spaced_by_the_setting(clips):
    pairs = list(first_pairs(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", 0.0,
                             CFG.replace(video_estimate_pairs=3, video_estimate_spacing=4)))
    assert [index for index, _, _ in pairs] == [0, 4, 8]
    assert [round(float(frame_l.time_s) * 30) for _, frame_l, _ in pairs] == [0, 4, 8]
