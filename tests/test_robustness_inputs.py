"""Inputs too large, turned by metadata, with alpha or float pixels,
and failures that say what is the matter. Through the CLI where the promise is the CLI's (one stderr
line, exit code, nothing left, inputs unchanged); on the reader where it is about pixels.
"""

from __future__ import annotations

import json
from fractions import Fraction

import av
import cv2
import numpy as np
import pytest

from sena_warp import imageio
from sena_warp.config import Config
from sena_warp.errors import InputError, MatchError
from sena_warp.features import match_images
from sena_warp.image_header import read_header
from sena_warp.imageio import read_image, read_image_masked
from sena_warp.video.loop import VideoOptions, run_video
from helpers import (assert_one_line_error, claiming, claiming_more, decoded_frames, encoded, one_mjpeg_frame,
                     png_claiming,
                     reencode_with_black_start, run_cli, with_orientation)
from test_video_loop import SideBySide

FAST_VIDEO = ["--audio", "none", "--crf", "35"]


@pytest.fixture(scope="module")
def pair(bundled_dir):
    d = bundled_dir / "udisd_test_000001"
    return d / "a.jpg", d / "b.jpg"


@pytest.fixture(scope="module")
def img_a(pair):
    return cv2.imread(str(pair[0]))


@pytest.fixture(scope="module")
def baseline(pair, tmp_path_factory, warp_device):
    """The panorama (BGRA) of the bundled pair as it is."""
    out = tmp_path_factory.mktemp("base") / "pano.png"
    from sena_warp.cli import main
    assert main(["image", *map(str, pair), "-o", str(out), "--device", warp_device]) == 0
    return cv2.imread(str(out), cv2.IMREAD_UNCHANGED)


def stitch_png(args, out, capfd, warp_device):
    rc, err, _ = run_cli(["image", *args, "-o", out, "--report", out.with_suffix(".json")], capfd, warp_device)
    assert rc == 0 and err == [], err
    return cv2.imread(str(out), cv2.IMREAD_UNCHANGED), json.loads(out.with_suffix(".json").read_text())


# --- 2. sizes read from the header, refused before decoding --------------------------------------------

MORE_FORMATS = ["bigtiff", ".gif", ".jp2", "j2k", ".hdr", ".pfm", ".ppm", ".pgm", ".pbm", ".pam", ".ras"]


@pytest.mark.parametrize("fmt", [".png", ".jpg", ".tif", ".webp", ".bmp", *MORE_FORMATS])
def test_every_format_the_decoder_is_given_has_its_size_read_from_the_header(fmt, img_a):
    """The size the header gives is the size the decoder makes, for every format that reaches it."""
    data = encoded(fmt, img_a[:48, :70])
    header = read_header(data)
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert (header.width, header.height) == (decoded.shape[1], decoded.shape[0]) == (70, 48)


@pytest.mark.parametrize("fmt", MORE_FORMATS)
def test_a_huge_image_of_any_other_format_is_refused_from_its_header_before_decoding(fmt, pair, img_a, dirs, capfd,
                                                                                    warp_device, monkeypatch):
    """The bombs: a 19 KB BigTIFF, a 300 KB GIF, JPEG 2000 and Radiance HDR files took gigabytes before
    the refusal (docs/benchmarks.md has the peak RSS before and after)."""
    folder_in, folder_out = dirs
    huge = folder_in / "huge.img"  # the decoder goes by the content, not by the name
    huge.write_bytes(claiming_more(fmt, 20000, 15000, img_a[:48, :70]))
    assert (read_header(huge.read_bytes()).width, read_header(huge.read_bytes()).height) == (20000, 15000)
    monkeypatch.setattr(imageio, "_decode_quietly", lambda data: pytest.fail("decoded a refused image"))
    before = huge.read_bytes()
    rc, err, _ = run_cli(["image", huge, pair[0], "-o", folder_out / "p.png"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, str(huge), "20000x15000 px (300 MP)", "above the limit of 100 MP per input")
    assert list(folder_out.iterdir()) == [] and huge.read_bytes() == before


@pytest.mark.parametrize("make", [
    lambda img: encoded(".avif", img),  # a format whose size is not read here
    lambda img: encoded(".gif", img)[:8],  # a header cut before its size
    lambda img: b"P6\nwide tall\n255\n" + bytes(100),  # a garbled header
], ids=["avif", "cut gif", "garbled ppm"])
def test_an_image_whose_size_cannot_be_read_is_refused_without_decoding(make, pair, img_a, dirs, capfd, warp_device,
                                                                        monkeypatch):
    folder_in, folder_out = dirs
    odd = folder_in / "odd.png"
    odd.write_bytes(make(img_a[:48, :70]))
    monkeypatch.setattr(imageio, "_decode_quietly", lambda data: pytest.fail("decoded an image of unknown size"))
    rc, err, _ = run_cli(["image", odd, pair[0], "-o", folder_out / "p.png"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, str(odd), "not a readable image (corrupt, truncated or unsupported format)")
    assert list(folder_out.iterdir()) == []


def test_a_video_frame_too_large_is_refused_from_the_streams_coded_size_before_decoding(bundled_dir, dirs, capfd,
                                                                                       warp_device, monkeypatch):
    """A small file can hold one huge frame (a 1.5 MB .mov, one 16000x16000 MJPEG frame): the probe decoded
    it for its display rotation before any limit was checked."""
    from sena_warp.video import reader

    folder_in, folder_out = dirs
    big = one_mjpeg_frame(folder_in / "big.mov", 1280, 1024)
    monkeypatch.setattr(reader, "_first_frame_rotation", lambda container: pytest.fail("decoded a refused frame"))
    reader._probe_version.cache_clear()
    for offset in ("0", "auto"):
        rc, err, _ = run_cli(["video", big, bundled_dir / "video" / "rooftop_right.mp4", "-o", folder_out / "v.mp4",
                              "--max-megapixels", "1", "--offset", offset], capfd, warp_device)
        assert rc == InputError.exit_code
        assert_one_line_error(err, str(big), "a frame is 1280x1024 px (1.31 MP), above the limit of 1 MP per input")
    assert list(folder_out.iterdir()) == []


@pytest.mark.parametrize("ext, size", [(".png", (25000, 25000)), (".jpg", (30000, 20000)), (".tif", (20000, 20000)),
                                       (".webp", (16000, 16000)), (".bmp", (12000, 12000))])
def test_a_huge_image_is_refused_from_its_header_before_decoding(ext, size, pair, img_a, dirs, capfd, warp_device,
                                                                 monkeypatch):
    folder_in, folder_out = dirs
    huge = folder_in / f"huge{ext}"
    huge.write_bytes(claiming(ext, *size, img_a))
    assert (read_header(huge.read_bytes()).width, read_header(huge.read_bytes()).height) == size
    monkeypatch.setattr(imageio, "_decode_quietly", lambda data: pytest.fail("decoded a refused image"))
    before = huge.read_bytes()
    rc, err, _ = run_cli(["image", huge, pair[0], "-o", folder_out / "p.png"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, str(huge), f"{size[0]}x{size[1]} px", "above the limit of 100 MP per input",
                          "--max-megapixels")
    assert list(folder_out.iterdir()) == [] and huge.read_bytes() == before


def test_an_image_above_opencvs_decoder_limit_is_refused_whatever_the_limit(pair, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    huge = folder_in / "huge.png"
    huge.write_bytes(png_claiming(40000, 40000))
    rc, err, _ = run_cli(["image", pair[0], huge, "-o", folder_out / "p.png", "--max-megapixels", "5000"],
                         capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, "40000x40000 px (1600 MP), above the 1074 MP OpenCV decodes")
    assert list(folder_out.iterdir()) == []


def test_max_megapixels_sets_the_limit_for_images_and_video_frames(pair, bundled_dir, dirs, capfd, warp_device):
    _, folder_out = dirs
    rc, err, _ = run_cli(["image", *pair, "-o", folder_out / "p.png", "--max-megapixels", "0.2"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, "image is 512x512 px", "above the limit of 0.2 MP")
    clips = bundled_dir / "video"
    rc, err, _ = run_cli(["video", clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", "-o", folder_out / "v.mp4",
                          "--max-megapixels", "0.1"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, "a frame is 270x480 px", "above the limit of 0.1 MP")
    assert list(folder_out.iterdir()) == []


# --- 5. EXIF orientation and video display matrices: stitched upright --------------------------------------

# The stored pixels of an upright image that each EXIF orientation turns upright again.
STORED_FOR = {1: lambda u: u, 2: lambda u: u[:, ::-1], 3: lambda u: u[::-1, ::-1], 4: lambda u: u[::-1],
              5: lambda u: u.swapaxes(0, 1), 6: lambda u: np.rot90(u, 1), 7: lambda u: u[::-1, ::-1].swapaxes(0, 1),
              8: lambda u: np.rot90(u, -1)}


@pytest.mark.parametrize("ext", [".jpg", ".png"])
@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_exif_orientation_reads_upright_like_opencvs_own_handling(orientation, ext, img_a, tmp_path):
    stored = np.ascontiguousarray(STORED_FOR[orientation](img_a[:200, :300]))
    path = tmp_path / f"o{ext}"
    path.write_bytes(with_orientation(cv2.imencode(ext, stored)[1].tobytes(), ext, orientation))
    upright = read_image(path)
    assert np.array_equal(upright, cv2.imread(str(path), cv2.IMREAD_COLOR))  # OpenCV applies EXIF in this mode
    if ext == ".png":  # lossless: exactly the pixels before they were stored turned
        assert np.array_equal(upright, img_a[:200, :300])


def test_a_photo_stored_turned_stitches_exactly_like_the_upright_one(pair, img_a, baseline, dirs, capfd, warp_device):
    """A phone's usual portrait photo: stored turned, EXIF 6. (All eight read upright: the test above.)"""
    folder_in, folder_out = dirs
    orientation = 6
    turned = folder_in / "a_turned.png"
    stored = np.ascontiguousarray(STORED_FOR[orientation](img_a))
    turned.write_bytes(with_orientation(cv2.imencode(".png", stored)[1].tobytes(), ".png", orientation))
    pano, _ = stitch_png([turned, pair[1]], folder_out / "pano.png", capfd, warp_device)
    assert np.array_equal(pano, baseline)


def lossless_clip(frames, path, turn_ccw: int, count: int) -> None:
    """The first ``count`` frames stored turned clockwise by ``turn_ccw`` quarter turns, with a display
    matrix turning them back (lossless x264, so decoding gives the stored planes exactly)."""
    first = frames[0]
    h, w = first.y.shape if turn_ccw % 2 == 0 else first.y.shape[::-1]
    with av.open(str(path), "w") as c:
        stream = c.add_stream("libx264", rate=30, options={"qp": "0", "preset": "ultrafast"})
        stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
        if turn_ccw:
            stream.set_display_rotation(90 * turn_ccw)
        for i, f in enumerate(frames[:count]):
            planes = [np.ascontiguousarray(np.rot90(p, -turn_ccw)) for p in (f.y, f.u, f.v)]
            frame = av.VideoFrame(w, h, "yuv420p")
            for plane, src in zip(frame.planes, planes):
                rows = np.frombuffer(plane, np.uint8, count=plane.height * plane.line_size)
                rows.reshape(plane.height, plane.line_size)[:, : plane.width] = src
            frame.pts, frame.time_base = i, Fraction(1, 30)
            c.mux(stream.encode(frame))
        c.mux(stream.encode(None))


def test_a_phone_video_with_a_display_matrix_stitches_like_the_upright_one(bundled_dir, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    clips = bundled_dir / "video"
    frames = decoded_frames(clips / "rooftop_left.mp4")
    upright, turned = folder_in / "upright.mp4", folder_in / "turned.mp4"
    lossless_clip(frames, upright, 0, 20)
    lossless_clip(frames, turned, 1, 20)
    assert [np.array_equal(a.y, b.y) for a, b in zip(decoded_frames(upright), decoded_frames(turned))] == [True] * 20
    reports, outs = [], []
    for name, left in (("u", upright), ("t", turned)):
        out, report = folder_out / f"{name}.mp4", folder_out / f"{name}.json"
        # Lossless (crf 0): libx264's lossy output was not always the same for the same frames after an
        # earlier test's failed NVENC probe in the process, and the frames are what is compared.
        rc, err, _ = run_cli(["video", left, clips / "rooftop_right.mp4", "-o", out, "--report", report, "--audio",
                              "none", "--crf", "0"], capfd, warp_device)
        reports.append(json.loads(report.read_text()))
        # The rotation is a note, said on stderr as it is found (the upright clip has none).
        assert rc == 0 and err == [f"sena-warp: warning: {note}" for note in reports[-1]["notes"]], err
        outs.append(decoded_frames(out))
    assert reports[1]["inputs"]["left"]["rotation_deg"] == 90
    assert (reports[1]["inputs"]["left"]["width"], reports[1]["inputs"]["left"]["height"]) == (270, 480)
    assert any("displayed turned 90 degrees" in note for note in reports[1]["notes"])
    assert reports[0]["stitch"]["first_estimate"]["inliers"] == reports[1]["stitch"]["first_estimate"]["inliers"]
    assert len(outs[0]) == len(outs[1]) == 20
    assert all(np.array_equal(a.y, b.y) for a, b in zip(*outs))


# --- 6. input semantics: alpha as validity, float ranges --------------------------------------------------

MAGENTA = (255, 0, 255)


@pytest.fixture(scope="module")
def transparent_b(pair, tmp_path_factory):
    """b (the source SENA warps in this pair) with its left 40 % fully transparent and magenta there."""
    img_b = cv2.imread(str(pair[1]))
    rgba = cv2.cvtColor(img_b, cv2.COLOR_BGR2BGRA)
    cut = int(0.4 * img_b.shape[1])
    rgba[:, :cut, :3] = MAGENTA
    rgba[:, :cut, 3] = 0
    path = tmp_path_factory.mktemp("rgba") / "b.png"
    cv2.imwrite(str(path), rgba)
    return path, cut


def magenta_pixels(img: np.ndarray) -> int:
    return int((np.abs(img[:, :, :3].astype(int) - MAGENTA).max(axis=2) < 40).sum())


def test_no_keypoint_is_kept_on_or_near_transparent_pixels(pair, transparent_b):
    path, cut = transparent_b
    img_b, transparent = read_image_masked(path)
    assert transparent is not None and transparent[:, :cut].all() and not transparent[:, cut:].any()
    cfg = Config(device="cpu")
    matches = match_images(read_image(pair[0]), img_b, cfg, (None, transparent))
    assert len(matches) > 100
    assert matches.pts_b[:, 0].min() >= cut + cfg.alpha_margin_px - 0.5


def test_transparent_pixels_are_not_content_on_the_canvas(pair, transparent_b, baseline, dirs, capfd, warp_device):
    _, folder_out = dirs
    path, _ = transparent_b
    pano, report = stitch_png([pair[0], path], folder_out / "pano.png", capfd, warp_device)
    assert report["rig"]["source"] == "b" and report["global_affine"]["inliers"] >= 100
    assert magenta_pixels(pano) == 0  # not one pixel of the fill under alpha 0
    # What only b's transparent part would cover is uncovered now (alpha 0), the rest as before.
    assert (pano[:, :, 3] == 0).sum() > (baseline[:, :, 3] == 0).sum() + 10000
    # The same colours as an opaque file: the fill shows.
    opaque = path.with_name("opaque.png")
    cv2.imwrite(str(opaque), cv2.imread(str(path), cv2.IMREAD_COLOR))
    rc, err, _ = run_cli(["image", pair[0], opaque, "-o", folder_out / "opaque.png"], capfd, warp_device)
    assert rc == 0 and magenta_pixels(cv2.imread(str(folder_out / "opaque.png"))) > 10000


@pytest.mark.parametrize("scale", [1.0, 255.0, 65535.0])
def test_float_images_are_scaled_by_their_range(scale, img_a, tmp_path):
    path = tmp_path / "f.tiff"
    assert cv2.imwrite(str(path), (img_a.astype(np.float32) * np.float32(scale / 255.0)))
    assert np.abs(read_image(path).astype(int) - img_a).max() <= (0 if scale <= 255 else 1)


def test_a_float_tiff_of_0_255_values_stitches_like_the_8_bit_file(pair, img_a, baseline, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    path = folder_in / "a.tiff"
    assert cv2.imwrite(str(path), img_a.astype(np.float32))
    pano, _ = stitch_png([path, pair[1]], folder_out / "pano.png", capfd, warp_device)
    assert np.array_equal(pano, baseline)


# --- 8. failures that say what is the matter ---------------------------------------------------------------

def test_images_far_apart_in_size_say_so(pair, img_a, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    small = folder_in / "small.png"
    cv2.imwrite(str(small), cv2.resize(cv2.imread(str(pair[1])), (64, 64), interpolation=cv2.INTER_AREA))
    rc, err, _ = run_cli(["image", pair[0], small, "-o", folder_out / "p.png"], capfd, warp_device)
    assert rc in (MatchError.exit_code, 4)
    assert_one_line_error(err, "the images differ 8.0x in size (a 512x512 px, b 64x64 px)",
                          "resize the larger one")
    assert list(folder_out.iterdir()) == []


def test_a_video_starting_black_names_the_times_tried_and_the_blank_frames(bundled_dir, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    clips = bundled_dir / "video"
    black = folder_in / "black_start.mp4"
    reencode_with_black_start(clips / "rooftop_left.mp4", black, 30)
    rc, err, _ = run_cli(["video", black, clips / "rooftop_right.mp4", "-o", folder_out / "v.mp4", *FAST_VIDEO],
                         capfd, warp_device)
    assert rc == MatchError.exit_code
    assert_one_line_error(err, "no stitch found on the first frame pairs (left frames at 0.00, 0.17, 0.33, 0.50, "
                          "0.67 s)", "the left frames there are blank", "trim the blank start")
    assert "right frames there are blank" not in err[0]
    assert list(folder_out.iterdir()) == []


def test_videos_of_other_cameras_and_resolutions_say_both_resolutions(bundled_dir, dirs, capfd, warp_device):
    _, folder_out = dirs
    clips = bundled_dir / "video"
    rc, err, _ = run_cli(["video", clips / "rooftop_left.mp4", clips / "office_cam1.mp4", "-o", folder_out / "v.mp4",
                          *FAST_VIDEO], capfd, warp_device)
    assert rc in (MatchError.exit_code, 4)
    assert_one_line_error(err, "the inputs' resolutions differ (left 270x480, right 640x480)")
    assert list(folder_out.iterdir()) == []


# --- 7. an audio layout the output cannot take: re-encoded, or left out with a warning ----------------------

def with_audio(src, dst, codec: str, layout: str, container: str) -> None:
    """``src``'s video packets with 2 s of noise as ``codec`` audio in ``layout``."""
    rate = 48000
    with av.open(str(src)) as cin, av.open(str(dst), "w", format=container) as cout:
        video_in = cin.streams.video[0]
        video_out = cout.add_stream_from_template(video_in)
        audio = cout.add_stream(codec, rate=rate, layout=layout)
        fmt, channels = audio.codec_context.format.name, audio.codec_context.layout.nb_channels
        samples = 960
        for i in range(2 * rate // samples):
            noise = (0.1 * np.random.default_rng(i).standard_normal((channels, samples))).astype(np.float32)
            if fmt.startswith("s16"):
                noise = (noise * 3000).astype(np.int16)
            frame = av.AudioFrame.from_ndarray(noise if fmt.endswith("p") else noise.T.reshape(1, -1), format=fmt,
                                               layout=layout)
            frame.sample_rate, frame.pts = rate, i * samples
            cout.mux(audio.encode(frame))
        cout.mux(audio.encode(None))
        for packet in cin.demux(video_in):
            if packet.dts is not None:
                packet.stream = video_out
                cout.mux(packet)


@pytest.mark.parametrize("codec, layout, container, out_ext, mode, words", [
    # Matroska keeps PCM without a layout name; MP4's muxer refuses 3 such channels, AAC cannot take them.
    ("pcm_s16le", "2.1", "matroska", ".mp4", None, "3 channels without a layout"),
    # The MOV muxer refuses Opus in 7.1: re-encoded to AAC.
    ("libopus", "7.1", "matroska", ".mov", "aac", "the mov muxer refuses a copy of its opus audio"),
])
def test_audio_the_muxer_refuses_is_reencoded_or_left_out_with_a_note(codec, layout, container, out_ext, mode, words,
                                                                      bundled_dir, tmp_path):
    clips = bundled_dir / "video"
    source = tmp_path / "with_audio.mkv"
    with_audio(clips / "rooftop_left.mp4", source, codec, layout, container)
    out = tmp_path / f"out{out_ext}"
    report = run_video(source, clips / "rooftop_right.mp4", out, SideBySide, VideoOptions())
    assert report["output"]["audio_mode"] == mode and report["frames_out"] == 60
    assert any(words in said for said in report["notes"] + report["warnings"])
    left_out = [w for w in report["warnings"] if "the output has no audio" in w]
    assert len(left_out) == (1 if mode is None else 0)
    with av.open(str(out)) as c:
        assert len(c.streams.audio) == (0 if mode is None else 1)


# --- the Python API checks its arguments: InputErrors that say what was expected ------------------------

def _api_calls(img, pano_bgra):
    from sena_warp.crop import crop_to_covered
    from sena_warp.jobs import Job
    from sena_warp.stitch import stitch_images

    return {
        "stitch_images None": (lambda: stitch_images(None, img, Config()), "img_a: expected a BGR uint8 array"),
        "stitch_images grey": (lambda: stitch_images(img[:, :, 0], img, Config()), "of shape (512, 512); read_image"),
        "stitch_images BGRA": (lambda: stitch_images(img, pano_bgra, Config()), "img_b: expected a BGR uint8 array of "
                                                                               "shape (H, W, 3), got a uint8 array of "
                                                                               "shape (40, 60, 4)"),
        "stitch_images empty": (lambda: stitch_images(img[:0], img, Config()), "image is 512x0 px"),
        "stitch_images float": (lambda: stitch_images(img.astype(np.float32), img, Config()), "got a float32 array"),
        "stitch_images mask": (lambda: stitch_images(img, img, Config(), transparent=(np.zeros((3, 3), bool), None)),
                               "the transparent mask of img_a must be None or a bool array of shape (512, 512)"),
        "stitch_images cfg dict": (lambda: stitch_images(img, img, {"grid_x": 8}), "cfg must be a Config"),
        "crop_to_covered BGR": (lambda: crop_to_covered(img), "crop_to_covered: expected a BGRA uint8 array"),
        "Job bogus": (lambda: Job("bogus", ("a.jpg", "b.jpg"), "p.png"), "kind 'bogus' unknown; use one of image"),
        "Job one input": (lambda: Job("image", "a.jpg", "p.png"), "inputs must be two paths (a and b)"),
        "Job bad setting": (lambda: Job("image", ("a.jpg", "b.jpg"), "p.png", {"grid_x": "8"}),
                            'grid_x = "8" is not a whole number'),
        "Job offset": (lambda: Job("video", ("l.mp4", "r.mp4"), "v.mp4", offset_s="abc"), "offset 'abc' s is not a time"),
        "Job overwrite": (lambda: Job("image", ("a.jpg", "b.jpg"), "p.png", overwrite=True), "overwrite must be one of"),
        "VideoOptions offset": (lambda: VideoOptions(offset_s="abc"), "offset 'abc' s is not a time"),
        "VideoOptions crf": (lambda: VideoOptions(crf=99), "video_crf = 99 is out of range [0, 51]"),
    }


@pytest.mark.parametrize("case", sorted(_api_calls(np.zeros((1, 1, 3), np.uint8), None)))
def test_the_python_api_refuses_a_wrong_argument_with_an_input_error_saying_what_was_expected(case, img_a):
    pano_bgra = np.zeros((40, 60, 4), np.uint8)
    before = img_a.copy()
    call, words = _api_calls(img_a, pano_bgra)[case]
    with pytest.raises(InputError) as caught:
        call()
    assert words in str(caught.value) and "\n" not in str(caught.value)
    assert np.array_equal(img_a, before)


def test_stitch_videos_replaces_an_existing_output_only_when_asked(bundled_dir, tmp_path, warp_device):
    from sena_warp.errors import OutputError
    from sena_warp.video.stitch import stitch_videos

    clips = bundled_dir / "video"
    left, right = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4"
    out = tmp_path / "v.mp4"
    out.write_bytes(b"an earlier result")
    cfg = Config(device=warp_device, video_audio="none", video_crf=35, video_estimate_pairs=1)
    with pytest.raises(OutputError, match="exists"):
        stitch_videos(left, right, out, cfg)  # options=None: taken from cfg
    assert out.read_bytes() == b"an earlier result" and sorted(p.name for p in tmp_path.iterdir()) == ["v.mp4"]
    with pytest.raises(InputError, match="options must be a VideoOptions or None, got dict"):
        stitch_videos(left, right, out, cfg, {"offset_s": 0})
    report = stitch_videos(left, right, out, cfg, overwrite=True)
    assert report["frames_out"] > 0 and len(decoded_frames(out)) == report["frames_out"]
