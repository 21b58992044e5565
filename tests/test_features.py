"""Step 0 (docs/method.md): detection, matching, the Matches record, the match picture and the CLI."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from conftest import shared_pairs
from sena_warp.cli import main
from sena_warp.config import Config
from sena_warp.debug import draw_matches
from sena_warp.errors import InputError
from sena_warp.features import Matches, detect, match_images, match_mutual_nn, match_ratio
from sena_warp.imageio import read_image
from helpers import read_pair

GT_TOLERANCE_PX = 3.0


@pytest.fixture(scope="module")
def graf(bundled_dir):
    img_a, img_b = read_pair(bundled_dir / "graf_gt")
    return img_a, img_b, np.loadtxt(bundled_dir / "graf_gt" / "H_a_to_b.txt")


def _within_ground_truth(matches: Matches, homography_a_to_b: np.ndarray) -> int:
    """Matches whose point in b lies within GT_TOLERANCE_PX of H applied to the point in a."""
    pts_b_expected = cv2.perspectiveTransform(matches.pts_a[None], homography_a_to_b)[0]
    return int(np.sum(np.linalg.norm(pts_b_expected - matches.pts_b, axis=1) <= GT_TOLERANCE_PX))


@pytest.mark.parametrize("detector, min_correct", [("xfeat", 100), ("sift", 100)])
def test_graf_matches_agree_with_ground_truth_homography(graf, detector, min_correct):
    img_a, img_b, homography = graf
    matches = match_images(img_a, img_b, Config(features=detector))
    correct = _within_ground_truth(matches, homography)
    print(f"\ngraf_gt {detector}: {len(matches)} matches, {correct} within {GT_TOLERANCE_PX:g} px "
          f"({correct / max(len(matches), 1):.1%}); keypoints {matches.n_keypoints_a}/{matches.n_keypoints_b}")
    assert correct >= min_correct
    assert correct / len(matches) >= 0.4  # graf1 -> graf3 is a ~30-degree viewpoint change: many wrong ones
    assert matches.pts_a.dtype == np.float64 and matches.pts_a.shape == matches.pts_b.shape == (len(matches), 2)


def _unit_rows(x: np.ndarray) -> np.ndarray:
    return (x / np.linalg.norm(x, axis=1, keepdims=True)).astype(np.float32)


def test_mutual_nn_recovers_a_permutation_and_drops_one_sided_matches():
    rng = np.random.default_rng(0)
    desc_b = _unit_rows(rng.normal(size=(50, 64)))
    perm = rng.permutation(50)
    desc_a = _unit_rows(desc_b[perm] + 0.05 * rng.normal(size=(50, 64)))
    idx_a, idx_b, cossim = match_mutual_nn(desc_a, desc_b, min_cossim=0.82)
    np.testing.assert_array_equal(idx_a, np.arange(50))
    np.testing.assert_array_equal(idx_b, perm)
    assert np.all(cossim >= 0.82)
    # A second, less similar copy of b[perm[0]] in a: b's nearest is the first one, so no match for it.
    worse_copy = _unit_rows(desc_b[perm[:1]] + 0.2 * rng.normal(size=(1, 64)))
    idx_a, idx_b, _ = match_mutual_nn(np.vstack([desc_a, worse_copy]), desc_b, min_cossim=0.0)
    assert 50 not in idx_a and len(idx_a) == 50


def test_mutual_nn_is_the_argmax_definition_on_real_descriptors(udisd_pair):
    """The column maxima stand in for an argmax down the columns: the same pairs, in the same order, as
    the definition (i's best in b is j and j's best in a is i) on the bundled pair's XFeat descriptors,
    and with a tie (a duplicated descriptor) the first of the tied rows."""
    cfg = Config()
    (_, desc_a, _), (_, desc_b, _) = (detect(img, cfg) for img in udisd_pair)
    matched = match_mutual_nn(desc_a, desc_b, cfg.min_cossim)[0][0]
    desc_a = np.vstack([desc_a, desc_a[matched:matched + 1]])  # a matched row again, last: tied in every column

    def definition(a, b):
        cossim = a @ b.T
        best_b, best_a = np.argmax(cossim, axis=1), np.argmax(cossim, axis=0)
        idx = np.arange(len(a))
        keep = (best_a[best_b] == idx) & (cossim[idx, best_b] >= cfg.min_cossim)
        return idx[keep], best_b[keep]

    got = match_mutual_nn(desc_a, desc_b, cfg.min_cossim)
    expected = definition(desc_a, desc_b)
    assert len(got[0]) > 500 and matched in got[0] and len(desc_a) - 1 not in got[0]
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[1], expected[1])


def test_mutual_nn_cosine_threshold():
    desc_a = np.array([[1.0, 0.0], [0.0, 1.0]], np.float32)
    desc_b = np.array([[0.8, 0.6], [-0.6, 0.8]], np.float32)  # cosines 0.8 (a0-b0) and 0.8 (a1-b1)
    assert len(match_mutual_nn(desc_a, desc_b, min_cossim=0.82)[0]) == 0
    idx_a, idx_b, cossim = match_mutual_nn(desc_a, desc_b, min_cossim=0.75)
    np.testing.assert_array_equal(idx_a, [0, 1])
    np.testing.assert_array_equal(idx_b, [0, 1])
    np.testing.assert_allclose(cossim, [0.8, 0.8], atol=1e-6)


def test_ratio_test_rejects_ambiguous_neighbours():
    desc_a = np.array([[0.0, 0.0], [10.0, 0.0]], np.float32)
    desc_b = np.array([[1.0, 0.0], [-1.1, 0.0], [10.0, 0.5], [20.0, 0.0]], np.float32)
    # a0: nearest b0 at 1.0, second b1 at 1.1 (ambiguous); a1: b2 at 0.5, second b0 at 9.0 (clear).
    idx_a, idx_b, scores = match_ratio(desc_a, desc_b, ratio=0.75)
    np.testing.assert_array_equal(idx_a, [1])
    np.testing.assert_array_equal(idx_b, [2])
    np.testing.assert_allclose(scores, [1.0 - 0.5 / 9.0], rtol=1e-5)
    assert len(match_ratio(desc_a, desc_b[:1], ratio=0.75)[0]) == 0  # one candidate: no ratio


@pytest.mark.parametrize("detector", ["xfeat", "sift"])
def test_flat_image_gives_no_matches(bundled_dir, detector):
    flat = np.full((480, 640, 3), 128, np.uint8)
    img_a, _ = read_pair(bundled_dir / "udisd_test_000001")
    cfg = Config(features=detector)
    assert len(detect(flat, cfg)[0]) == 0
    matches = match_images(flat, img_a, cfg)
    assert len(matches) == 0 and matches.n_keypoints_a == 0 and matches.n_keypoints_b > 0
    assert matches.pts_a.shape == (0, 2) and matches.pts_b.shape == (0, 2)


def test_unknown_detector_is_an_input_error(graf):
    with pytest.raises(InputError, match="orb"):
        match_images(graf[0], graf[1], Config(features="orb"))


def test_matches_record_is_frozen():
    matches = Matches(np.zeros((3, 2)), np.ones((3, 2)), np.ones(3), 10, 12)
    assert len(matches) == 3
    with pytest.raises(AttributeError):
        matches.n_keypoints_a = 4


def test_draw_matches_side_by_side_with_lines():
    img_a = np.zeros((40, 60, 3), np.uint8)
    img_b = np.full((50, 30, 3), 200, np.uint8)
    matches = Matches(np.array([[10.0, 20.0]]), np.array([[10.0, 20.0]]), np.ones(1), 1, 1)
    picture = draw_matches(img_a, img_b, matches)
    assert picture.shape == (50, 90, 3)
    np.testing.assert_array_equal(picture[:50, 60 + 15], 200)  # b on the right, untouched away from lines
    assert picture[40:, :60].max() == 0  # a padded with black below
    assert picture[20, 40].max() > 0  # the line from (10, 20) in a to (70, 20) on the canvas
    np.testing.assert_array_equal(draw_matches(img_a, img_b, Matches(np.zeros((0, 2)), np.zeros((0, 2)),
                                                                     np.zeros(0), 0, 0))[:40, :60], img_a)


def test_cli_match_writes_picture(bundled_dir, tmp_path, capsys):
    folder = bundled_dir / "udisd_test_000001"
    out = tmp_path / "m.png"
    assert main(["match", str(folder / "a.jpg"), str(folder / "b.jpg"), "-o", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["matches"] >= 500 and summary["keypoints_a"] > summary["matches"]
    assert read_image(out).shape == (512, 1024, 3)


@pytest.mark.shared
@pytest.mark.parametrize("pair", shared_pairs())
def test_every_shared_pair_has_matches_with_both_detectors(shared_dir, pair):
    img_a, img_b = read_pair(shared_dir / "pairs" / pair)
    for detector in ("xfeat", "sift"):
        cfg = Config(features=detector)
        matches = match_images(img_a, img_b, cfg)
        assert len(matches) >= cfg.min_inliers, f"{pair}: {detector} gave {len(matches)} matches"
