import numpy as np
import pytest

from sena_warp.errors import InputError
from sena_warp.rig import detect_rig, image_to_working, map_from_working, matches_to_working, points_to_working

RNG = np.random.default_rng(7)


def _pair(shift_xy):
    pts_a = RNG.uniform(0, 400, size=(200, 2))
    return pts_a, pts_a - np.asarray(shift_xy)


@pytest.mark.parametrize(
    "shift, source, vertical",
    [((300, 5), "a", False), ((-300, 5), "b", False), ((4, 250), "a", True), ((4, -250), "b", True)],
)
def test_left_or_top_view_is_the_source(shift, source, vertical):
    rig = detect_rig(*_pair(shift))
    assert (rig.source, rig.vertical) == (source, vertical)
    assert rig.target == ("b" if source == "a" else "a")


def test_reference_overrides_detection():
    pts_a, pts_b = _pair((300, 0))
    assert detect_rig(pts_a, pts_b, reference="a").source == "b"
    assert detect_rig(pts_a, pts_b, reference="b").source == "a"
    with pytest.raises(InputError):
        detect_rig(pts_a, pts_b, reference="left")


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
    rig = detect_rig(pts_a, pts_b, reference="a")  # ... unless a is chosen as the unwarped reference
    assert rig.vertical and rig.source == "b"
    pts_src, pts_tgt = matches_to_working(pts_a, pts_b, rig)
    np.testing.assert_array_equal(pts_src, pts_b[:, ::-1])
    np.testing.assert_array_equal(pts_tgt, pts_a[:, ::-1])
