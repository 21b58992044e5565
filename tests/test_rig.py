import numpy as np
import pytest

from sena_warp.errors import InputError
from sena_warp.rig import detect_rig, image_to_working, map_from_working, matches_to_working, points_to_working

RNG = np.random.default_rng(7)


SHAPE = (800, 800)  # rows, cols of both made-up images


def _pair(shift_xy):
    """Matches of a scene shifted by ``shift_xy`` from a to b, over all of a that b sees."""
    shift = np.asarray(shift_xy, np.float64)
    pts_a = RNG.uniform(np.maximum(shift, 0), np.minimum(799 + shift, 799), size=(200, 2))
    return pts_a, pts_a - shift, SHAPE


def test_side_by_side_views_with_a_near_person_shifting_up_are_not_a_vertical_rig():
    # Two webcams side by side at slightly different heights share most of their view: the wall
    # behind shifts 40 px from a to b, a person close to both 60 px across and 90 px up. The person's
    # matches outnumber the wall's, so the median shift is mostly up; by area the view shifts across.
    wall_a = RNG.uniform([40, 0], [639, 479], size=(250, 2))
    person_a = RNG.uniform([250, 200], [400, 479], size=(600, 2))
    pts_a = np.vstack([wall_a, person_a])
    pts_b = np.vstack([wall_a - [40, 0], person_a - [60, -90]])
    rig = detect_rig(pts_a, pts_b, (480, 640))
    assert abs(rig.median_dy_px) > abs(rig.median_dx_px)  # what the median alone took for a vertical rig
    assert not rig.vertical and rig.source == "a" and rig.shift_x_px == pytest.approx(40, abs=5)


def test_views_sharing_almost_everything_fall_back_on_the_median_shift():
    pts_a = RNG.uniform(0, 639, size=(300, 2))
    rig = detect_rig(pts_a, pts_a - [4.0, -3.0], (640, 640))
    assert (rig.shift_x_px, rig.shift_y_px) == pytest.approx((4.0, -3.0)) and rig.source == "a" and not rig.vertical


@pytest.mark.parametrize(
    "shift, source, vertical",
    [((300, 5), "a", False), ((-300, 5), "b", False), ((4, 250), "a", True), ((4, -250), "b", True)],
)
def test_left_or_top_view_is_the_source(shift, source, vertical):
    rig = detect_rig(*_pair(shift))
    assert (rig.source, rig.vertical) == (source, vertical)
    assert rig.target == ("b" if source == "a" else "a")


def test_reference_overrides_detection():
    pair = _pair((300, 0))
    assert detect_rig(*pair, reference="a").source == "b"
    assert detect_rig(*pair, reference="b").source == "a"
    with pytest.raises(InputError):
        detect_rig(*pair, reference="left")


def test_working_frame_round_trip_for_vertical_rig():
    rig = detect_rig(*_pair((0, 300)))
    img = RNG.integers(0, 255, size=(30, 50, 3), dtype=np.uint8)
    work = image_to_working(img, rig)
    assert work.shape == (50, 30, 3)
    pts = np.array([[7.0, 11.0]])
    wx, wy = points_to_working(pts, rig)[0]
    assert work[int(wy), int(wx)].tolist() == img[11, 7].tolist()
    # A working-frame identity map over the transposed canvas becomes the input-frame identity map.
    ys, xs = np.mgrid[0:50, 0:30].astype(np.float32)
    ident_work = np.dstack([xs, ys])
    ys_in, xs_in = np.mgrid[0:30, 0:50].astype(np.float32)
    np.testing.assert_array_equal(map_from_working(ident_work, rig), np.dstack([xs_in, ys_in]))
    assert map_from_working(np.zeros((50, 30), np.float32), rig).shape == (30, 50)


def test_matches_to_working_orders_by_role_and_transposes_a_vertical_rig():
    pts_b = np.array([[10.0, 50.0], [30.0, 110.0]])
    pts_a = pts_b + [0.0, 150.0]  # scene points lower in a than in b: a is the top view, the source
    rig = detect_rig(pts_a, pts_b, SHAPE, reference="a")  # ... unless a is chosen as the unwarped reference
    assert rig.vertical and rig.source == "b"
    pts_src, pts_tgt = matches_to_working(pts_a, pts_b, rig)
    np.testing.assert_array_equal(pts_src, pts_b[:, ::-1])
    np.testing.assert_array_equal(pts_tgt, pts_a[:, ::-1])
