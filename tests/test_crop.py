import numpy as np
from hypothesis import given, settings, strategies as st

from sena_warp.crop import largest_inner_rectangle


def test_rectangle_of_a_known_shape():
    mask = np.zeros((300, 500), bool)
    mask[20:280, 40:460] = True
    mask[20:60, 40:200] = False  # a notch at the top left
    x, y, w, h = largest_inner_rectangle(mask)
    assert mask[y:y + h, x:x + w].all()
    assert w * h >= 0.95 * (420 * 220)  # the rectangle below the notch is 420 x 220


def test_empty_mask_gives_empty_rectangle():
    assert largest_inner_rectangle(np.zeros((40, 50), bool)) == (0, 0, 0, 0)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 60), st.integers(0, 60), st.integers(1, 80), st.integers(1, 80), st.integers(200, 900))
def test_rectangle_is_always_fully_covered(x, y, w, h, width):
    mask = np.zeros((150, width), bool)
    mask[y:y + h, x:x + w] = True
    rx, ry, rw, rh = largest_inner_rectangle(mask)
    assert mask[ry:ry + rh, rx:rx + rw].all()
