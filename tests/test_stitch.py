import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation.metrics import overlap_psnr_ssim
from sena_warp.gains import compensated
from sena_warp.stitch import stitch_images


def beyond_seam_px(maps) -> int:
    """Distance from the seam past which the target shows alone, with its gains only: the transition,
    its smoothing and the seam blend's fade."""
    cfg = Config()
    return int(np.ceil(0.5 * cfg.transition_px + 3 * cfg.seam_smooth_sigma_px + maps.seam.offsets.fade_px)) + 2


def target_as_shown(maps, img_tgt):
    """The target with its gains: what the panorama shows of it away from the seam."""
    gains = maps.seam.gains
    return compensated(img_tgt, gains.gain_tgt, gains.bias_tgt, gains.knee_grey, gains.knee_peak)


@pytest.fixture(scope="module")
def pano(udisd_pair, warp_device):
    return stitch_images(*udisd_pair, Config(device=warp_device))


def test_panorama_covers_both_inputs_once(pano, udisd_pair):
    img_a, img_b = udisd_pair
    covered = int((pano.image[:, :, 3] > 0).sum())
    # The union of two 512x512 views that overlap: more than one view, less than two.
    assert 512 * 512 * 1.05 < covered < 512 * 512 * 2
    assert pano.maps.rig.source == "b"  # b is the left view of this pair (median dx < 0)


def test_target_is_pasted_unwarped_right_of_the_seam(pano, udisd_pair):
    maps = pano.maps
    img_tgt = target_as_shown(maps, maps.rig.pick(*udisd_pair)[1])
    ox, oy = (int(round(v)) for v in maps.warp.overlap.canvas.offset_tgt)
    seam_x = maps.seam.maps.seam_x_canvas
    fade = int(np.ceil(maps.seam.offsets.fade_px)) + 1  # the border blend's reach from the top and bottom borders
    rows = np.arange(oy + fade, oy + img_tgt.shape[0] - fade)
    x = int(np.nanmax(seam_x[rows])) + beyond_seam_px(maps)
    region = pano.image[rows, x:ox + img_tgt.shape[1] - 5, :3]
    expect = img_tgt[rows - oy, x - ox:img_tgt.shape[1] - 5]
    assert region.shape[1] > 50
    assert np.abs(region.astype(int) - expect).max() <= 1


def test_anchors_meet_and_sena_warp_aligns_the_overlap(pano, udisd_pair, warp_device):
    cfg = Config(device=warp_device)
    seam = pano.maps.seam
    assert len(seam.anchors_src_canvas) >= 5
    warp = pano.maps.warp
    img_src, img_tgt = pano.maps.rig.pick(*udisd_pair)
    from sena_warp.warp_map import remap_image, source_map_canvas

    def overlap_psnr(map_src):
        warped, valid = remap_image(img_src, map_src, cfg)
        placed = np.zeros_like(warped)
        valid_tgt = np.zeros(valid.shape, bool)
        ox, oy = (int(round(v)) for v in warp.overlap.canvas.offset_tgt)
        placed[oy:oy + img_tgt.shape[0], ox:ox + img_tgt.shape[1]] = img_tgt
        valid_tgt[oy:oy + img_tgt.shape[0], ox:ox + img_tgt.shape[1]] = True
        return overlap_psnr_ssim(warped, valid, placed, valid_tgt)[0]

    affine_only = source_map_canvas(warp.overlap.canvas, warp.glob.affine_src_to_tgt,
                                    np.zeros_like(warp.field_canvas), cfg)
    assert overlap_psnr(warp.map_src_canvas) > overlap_psnr(affine_only)


def test_vertical_rig_is_stitched_like_the_transposed_horizontal_one(pano, udisd_pair, warp_device):
    img_a, img_b = (np.ascontiguousarray(img.transpose(1, 0, 2)) for img in udisd_pair)
    vertical = stitch_images(img_a, img_b, Config(device=warp_device))
    maps = vertical.maps
    assert maps.rig.vertical and maps.rig.source == pano.maps.rig.source
    h, w = vertical.image.shape[:2]
    # XFeat sees other keypoints on transposed images, so A_glob differs slightly: sizes within 2 %.
    assert abs(h / pano.image.shape[1] - 1) < 0.02 and abs(w / pano.image.shape[0] - 1) < 0.02
    # Below the seam the (top/bottom) target is pasted unwarped: the maps came back transposed right.
    img_tgt = target_as_shown(maps, maps.rig.pick(img_a, img_b)[1])
    # The working frame swaps x and y: the target's input-frame offset is (columns oy, rows ox).
    ox, oy = (int(round(v)) for v in maps.warp.overlap.canvas.offset_tgt)
    seam_row = int(np.nanmax(maps.seam.maps.seam_x_canvas)) + beyond_seam_px(maps)
    h_t, w_t = img_tgt.shape[:2]
    fade = int(np.ceil(maps.seam.offsets.fade_px)) + 1  # the border blend's reach from the target's side borders
    region = vertical.image[seam_row:ox + h_t - 5, oy + fade:oy + w_t - fade, :3]
    expect = img_tgt[seam_row - ox:h_t - 5, fade:w_t - fade]
    assert region.shape == expect.shape and region.shape[0] > 50
    assert np.abs(region.astype(int) - expect).max() <= 1


def test_the_input_order_does_not_change_the_panorama(pano, udisd_pair, warp_device):
    """'a b' and 'b a' give the same roles, the same maps and the same pixels."""
    swapped = stitch_images(udisd_pair[1], udisd_pair[0], Config(device=warp_device))
    assert swapped.maps.rig.source == "a"  # the same image (b of the original order) is the source
    np.testing.assert_array_equal(swapped.image, pano.image)


def test_a_detached_piece_of_the_source_below_the_target_is_left_out(bundled_dir, warp_device):
    """graf_gt: right of the seam the warped source reaches below the target's bottom edge again after
    a gap, a piece of other content (columns 366-531) cut by both views' borders. By default the
    panorama shows none of it; with the paper's coverage (``source_past_target``) it does."""
    from helpers import read_pair

    img_a, img_b = read_pair(bundled_dir / "graf_gt")
    shown = {}
    for on in (False, True):
        pano = stitch_images(img_a, img_b, Config(device=warp_device, source_past_target=on))
        maps = pano.maps
        assert not maps.rig.vertical
        oy = int(round(maps.warp.overlap.canvas.offset_tgt[1]))
        below = pano.image[oy + maps.rig.pick(img_a, img_b)[1].shape[0]:, 366:532, 3]
        shown[on] = int((below > 0).sum())
    assert shown[False] == 0 and shown[True] > 500
