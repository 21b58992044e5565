import numpy as np
from hypothesis import given, settings, strategies as st

from sena_warp.crop import SEARCH_LONG_SIDE_PX, largest_inner_rectangle


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
def test_rectangle_is_fully_covered_and_misses_at_most_a_search_cell_per_side(x, y, w, h, width):
    height = 150
    mask = np.zeros((height, width), bool)
    mask[y:y + h, x:x + w] = True
    rx, ry, rw, rh = largest_inner_rectangle(mask)
    assert mask[ry:ry + rh, rx:rx + rw].all()
    # The search runs on cells of about scale x scale px: each side of the covered rectangle may lose
    # up to one partly covered cell, plus up to 1 px where its fractional cell edge is rounded inward
    # back to pixels (x=25, w=12, width=548: 2 px lost on each side, cells 1.37 px wide).
    scale = max(1.0, width / SEARCH_LONG_SIDE_PX)
    cell_x, cell_y = width / int(width // scale), height / int(height // scale)
    w_in, h_in = min(w, width - x), min(h, height - y)
    assert rw * rh >= max(0.0, w_in - 2 * cell_x - 2) * max(0.0, h_in - 2 * cell_y - 2)
