"""The image path: every bad input or output ends in ONE stderr line, the right exit code, no file left.

Each CLI case runs ``sena_warp.cli.main`` in-process with ``capfd`` (file-descriptor capture, so
messages printed by C libraries such as libpng count too). Inputs are made in ``tmp_path/in`` from the
bundled pairs; outputs go to ``tmp_path/out``, which must stay empty after a failure (no panorama, no
``.part`` temp file). Truncated JPEG: OpenCV 5 refuses to decode it (no grey fill), so a truncated
input of either format is a clear InputError, exit 2.
"""

from __future__ import annotations

import json
import os
import re

import cv2
import numpy as np
import pytest

from sena_warp import outputs, stitch
from sena_warp.cli import main
from sena_warp.config import Config
from sena_warp.errors import GeometryError, InputError, MatchError, OutputError, StitchError
from sena_warp.features import Matches
from sena_warp.imageio import read_image, to_bgr8
from sena_warp.outputs import atomic_output
from sena_warp.stitch import stitch_images
from helpers import assert_one_line_error, run_cli



@pytest.fixture(scope="module")
def pair(bundled_dir):
    d = bundled_dir / "udisd_test_000001"
    return str(d / "a.jpg"), str(d / "b.jpg")


@pytest.fixture(scope="module")
def img_a(pair):
    return cv2.imread(pair[0], cv2.IMREAD_COLOR)


def cut_in_half(src, dst):
    data = open(src, "rb").read()
    dst.write_bytes(data[: len(data) // 2])
    return dst


# --- 1. unreadable or unsuitable input files: exit 2 --------------------------------------------

BAD_INPUTS = {
    "missing": (lambda d, pair: d / "missing.jpg", ("not found",)),
    "directory": (lambda d, pair: (d / "pics.jpg").mkdir() or d / "pics.jpg", ("not a file",)),
    "text": (lambda d, pair: (d / "notes.jpg").write_text("hello\n") and d / "notes.jpg", ("not a readable image",)),
    "random_bytes": (lambda d, pair: (d / "noise.png").write_bytes(np.random.default_rng(7).bytes(5000))
                     and d / "noise.png", ("not a readable image",)),
    "empty": (lambda d, pair: (d / "empty.png").write_bytes(b"") or d / "empty.png", ("not a readable image",)),
    "truncated_jpeg": (lambda d, pair: cut_in_half(pair[0], d / "cut.jpg"), ("truncated",)),
    # libpng prints "libpng error: ..." on fd 2 itself; it must end up inside the one line.
    "truncated_png": (lambda d, pair: cut_in_half(pair[2], d / "cut.png"), ("truncated", "incomplete")),
    "tiny_8px": (lambda d, pair: cv2.imwrite(str(d / "tiny.png"), cv2.imread(pair[0])[:8, :8]) and d / "tiny.png",
                 ("8x8 px", "at least")),
    # Readable, but below what XFeat can run on: the message names the size (not the file) and the way out.
    "small_for_xfeat": (lambda d, pair: cv2.imwrite(str(d / "s.png"), cv2.imread(pair[0])[:20, :24]) and d / "s.png",
                        ("24x20 px", "too small", "--features sift")),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_file_exit_2_one_line_no_output(case, pair, bundled_dir, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    make, words = BAD_INPUTS[case]
    bad = make(folder_in, (*pair, str(bundled_dir / "graf_gt" / "a.png")))
    out = folder_out / "pano.png"
    rc, err, _ = run_cli(["image", pair[0], str(bad), "-o", str(out)], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, *words)
    assert case == "small_for_xfeat" or str(bad) in err[0]
    assert list(folder_out.iterdir()) == []


# --- 1. odd but valid formats and sizes: must stitch ----------------------------------------------

def _stitch_png(args, out, capfd, warp_device):
    rc, err, _ = run_cli(["image", *args, "-o", str(out), "--report", str(out.with_suffix(".json"))],
                         capfd, warp_device)
    assert rc == 0, err
    return cv2.imread(str(out), cv2.IMREAD_UNCHANGED), json.loads(out.with_suffix(".json").read_text())


@pytest.fixture(scope="module")
def baseline(pair, tmp_path_factory, warp_device):
    out = tmp_path_factory.mktemp("base") / "pano.png"
    assert main(["image", *pair, "-o", str(out), "--device", warp_device]) == 0
    return cv2.imread(str(out), cv2.IMREAD_UNCHANGED)


@pytest.mark.parametrize("kind, convert", [
    ("rgba", lambda img: cv2.cvtColor(img, cv2.COLOR_BGR2BGRA)),
    ("bgr16", lambda img: img.astype(np.uint16) * 257),
    ("rgba16", lambda img: cv2.cvtColor(img, cv2.COLOR_BGR2BGRA).astype(np.uint16) * 257),
])
def test_rgba_and_16bit_inputs_stitch_exactly_like_the_8bit_file(kind, convert, pair, img_a, baseline, dirs, capfd,
                                                                 warp_device):
    folder_in, folder_out = dirs
    odd = folder_in / f"a_{kind}.png"
    assert cv2.imwrite(str(odd), convert(img_a))
    pano, _ = _stitch_png([str(odd), pair[1]], folder_out / "pano.png", capfd, warp_device)
    # 16-bit v * 257 and an opaque alpha carry the same 8-bit colours: the same panorama, pixel for pixel.
    assert np.array_equal(pano, baseline)


def test_grayscale_input_stitches(pair, img_a, baseline, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    grey = folder_in / "a_grey.png"
    assert cv2.imwrite(str(grey), cv2.cvtColor(img_a, cv2.COLOR_BGR2GRAY))
    pano, report = _stitch_png([str(grey), pair[1]], folder_out / "pano.png", capfd, warp_device)
    assert report["global_affine"]["inliers"] >= 100
    # The canvas follows A_glob, which XFeat's matches on a grey copy move a little (measured: 10 px).
    assert abs(pano.shape[0] - baseline.shape[0]) <= 12 and abs(pano.shape[1] - baseline.shape[1]) <= 12


def test_inputs_of_different_sizes_stitch(pair, img_a, dirs, capfd, warp_device):
    """SENA allows different sizes: a at half size still stitches with b (the warped view is rescaled)."""
    folder_in, folder_out = dirs
    half = folder_in / "a_half.png"
    assert cv2.imwrite(str(half), cv2.resize(img_a, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
    pano, report = _stitch_png([str(half), pair[1]], folder_out / "pano.png", capfd, warp_device)
    assert report["global_affine"]["inliers"] >= 12
    # The affine carries the 2x scale: b, the warped view here, shrinks to roughly a's half size.
    scale = np.sqrt(abs(np.linalg.det(np.array(report["global_affine"]["matrix_src_to_tgt"])[:, :2])))
    assert 0.4 < scale < 0.6
    covered = (pano[:, :, 3] > 0).sum()
    assert covered > 256 * 256  # both views contribute, not only the half-size target (the source beyond it is
    # a thin strip, left out by default: a few hundred pixels)


# --- 2. images that do not stitch: exit 3 or 4 ---------------------------------------------------

def test_unrelated_images_exit_3(pair, bundled_dir, dirs, capfd, warp_device):
    _, folder_out = dirs
    out = folder_out / "pano.png"
    rc, err, _ = run_cli(["image", pair[0], str(bundled_dir / "graf_gt" / "b.png"), "-o", str(out)],
                         capfd, warp_device)
    assert rc == MatchError.exit_code
    assert_one_line_error(err, "agree on one affine model", "check that the images overlap", "--features")
    assert list(folder_out.iterdir()) == []


@pytest.mark.parametrize("features", ["xfeat", "sift"])
@pytest.mark.parametrize("value", [0, 128])
def test_featureless_image_exit_3(features, value, pair, img_a, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    flat = folder_in / "flat.png"
    assert cv2.imwrite(str(flat), np.full_like(img_a, value))
    rc, err, _ = run_cli(["image", str(flat), pair[1], "-o", str(folder_out / "p.png"), "--features", features],
                         capfd, warp_device)
    assert rc == MatchError.exit_code
    assert_one_line_error(err, "only 0 matches", "check that the images overlap")
    assert list(folder_out.iterdir()) == []


def test_mirrored_view_exit_4(pair, img_a, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    mirrored = folder_in / "mirror.png"
    assert cv2.imwrite(str(mirrored), img_a[:, ::-1])
    rc, err, _ = run_cli(["image", pair[0], str(mirrored), "-o", str(folder_out / "p.png")], capfd, warp_device)
    assert rc == GeometryError.exit_code
    assert_one_line_error(err, "mirrors")
    assert list(folder_out.iterdir()) == []


def test_zoomed_crop_needs_too_large_canvas_exit_4(bundled_dir, dirs, capfd, warp_device):
    """A 1/3-scale graf against a native 128 px crop of it: the (correct) 3x affine needs ~7x the inputs' area."""
    folder_in, folder_out = dirs
    graf = cv2.imread(str(bundled_dir / "graf_gt" / "a.png"))
    height, width = graf.shape[:2]
    small, crop = folder_in / "small.png", folder_in / "crop.png"
    assert cv2.imwrite(str(small), cv2.resize(graf, None, fx=1 / 3, fy=1 / 3, interpolation=cv2.INTER_AREA))
    assert cv2.imwrite(str(crop), graf[height // 2 - 64:height // 2 + 64, width // 2 - 64:width // 2 + 64])
    rc, err, _ = run_cli(["image", str(small), str(crop), "-o", str(folder_out / "p.png"), "--features", "sift",
                          "--reference", "b"], capfd, warp_device)
    assert rc == GeometryError.exit_code
    assert_one_line_error(err, "canvas", "limit")
    assert list(folder_out.iterdir()) == []


def test_huge_scale_model_is_refused_before_allocating(img_a, monkeypatch):
    """Matches that say 'b is a's top-left corner magnified 200x' must not allocate a 100k x 100k canvas."""
    pts_a = np.random.default_rng(3).uniform(0, 40, (200, 2))

    def fake_matches(img_1, img_2, cfg, transparent):
        return Matches(pts_a, pts_a * 200.0, np.ones(len(pts_a)), len(pts_a), len(pts_a))

    monkeypatch.setattr(stitch, "match_images", fake_matches)
    with pytest.raises(GeometryError, match="canvas"):
        stitch_images(img_a, img_a, Config(device="cpu"), reference="b")


# --- 1. output paths: exit 6, nothing written, inputs untouched -----------------------------------

@pytest.mark.parametrize("name", ["pano.xyz", "pano"])
def test_unknown_output_extension_is_a_bad_option_exit_2(name, pair, dirs, capfd, warp_device):
    _, folder_out = dirs
    rc, err, _ = run_cli(["image", *pair, "-o", str(folder_out / name)], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, "unsupported output type", ".png")
    assert list(folder_out.iterdir()) == []


@pytest.mark.parametrize("where, words", [
    (lambda out: out / "missing" / "pano.png", ("does not exist",)),
    (lambda out: (out / "file.txt").write_text("x") and out / "file.txt" / "pano.png", ("is not a folder",)),
    (lambda out: (out / "pano.png").mkdir() or out / "pano.png", ("is a folder",)),
])
def test_output_where_no_file_can_be_made_exit_6(where, words, pair, dirs, capfd, warp_device):
    _, folder_out = dirs
    out = where(folder_out)
    before = sorted(p.name for p in folder_out.iterdir())
    rc, err, _ = run_cli(["image", *pair, "-o", str(out)], capfd, warp_device)
    assert rc == OutputError.exit_code
    assert_one_line_error(err, *words)
    assert sorted(p.name for p in folder_out.iterdir()) == before


def test_output_in_read_only_folder_exit_6(pair, dirs, capfd, warp_device):
    _, folder_out = dirs
    folder_out.chmod(0o555)
    try:
        if os.access(folder_out, os.W_OK):
            pytest.skip("running as root: chmod does not make a folder read-only")
        rc, err, _ = run_cli(["image", *pair, "-o", str(folder_out / "p.png")], capfd, warp_device)
        assert rc == OutputError.exit_code
        assert_one_line_error(err, "not writable")
        assert list(folder_out.iterdir()) == []
    finally:
        folder_out.chmod(0o755)


def test_output_equal_to_an_input_exit_6_input_untouched(pair, dirs, capfd, warp_device):
    folder_in, _ = dirs
    copy = folder_in / "a.png"
    assert cv2.imwrite(str(copy), cv2.imread(pair[0]))
    before = copy.read_bytes()
    rc, err, _ = run_cli(["image", str(copy), pair[1], "-o", str(copy)], capfd, warp_device)
    assert rc == OutputError.exit_code
    assert_one_line_error(err, "overwrite an input")
    assert copy.read_bytes() == before
    assert sorted(p.name for p in folder_in.iterdir()) == ["a.png"]


@pytest.mark.parametrize("option", ["--report", "--debug"])
def test_unwritable_report_or_debug_path_exit_6_one_line(option, pair, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    blocker = folder_in / "blocker"
    blocker.write_text("a file where a folder is needed")
    rc, err, _ = run_cli(["image", *pair, "-o", str(folder_out / "p.png"), option, str(blocker / "x")],
                         capfd, warp_device)
    assert rc == OutputError.exit_code
    assert_one_line_error(err, str(blocker))


@pytest.mark.parametrize("option", ["--report", "--debug"])
def test_unwritable_report_or_debug_path_leaves_no_panorama(option, pair, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    blocker = folder_in / "blocker"
    blocker.write_text("a file where a folder is needed")
    main(["image", *pair, "-o", str(folder_out / "p.png"), option, str(blocker / "x"), "--device", warp_device])
    assert list(folder_out.iterdir()) == []


# --- 3. library level: only StitchError subclasses -----------------------------------------------

@pytest.mark.parametrize("make_b, error", [
    (lambda a, b: np.zeros_like(b), MatchError),
    (lambda a, b: np.random.default_rng(0).integers(0, 256, b.shape, dtype=np.uint8), MatchError),
    (lambda a, b: np.ascontiguousarray(b[:20, :20]), InputError),
    (lambda a, b: np.ascontiguousarray(b[:16, :]), InputError),
    (lambda a, b: np.ascontiguousarray(b[:64, :64]), MatchError),
    (lambda a, b: np.ascontiguousarray(a[:, ::-1]), GeometryError),
])
def test_stitch_images_raises_only_stitch_errors(make_b, error, pair, img_a):
    img_b = cv2.imread(pair[1])
    with pytest.raises(StitchError) as caught:
        stitch_images(img_a, make_b(img_a, img_b), Config(device="cpu"))
    assert isinstance(caught.value, error)
    assert "\n" not in str(caught.value)


def test_read_image_formats(img_a, tmp_path):
    grey = cv2.cvtColor(img_a, cv2.COLOR_BGR2GRAY)
    cases = {
        "grey.png": (grey, cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)),
        "grey16.png": (grey.astype(np.uint16) * 257, cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)),
        "rgba.png": (cv2.cvtColor(img_a, cv2.COLOR_BGR2BGRA), img_a),
        "bgr16.png": (img_a.astype(np.uint16) * 257, img_a),
        "float.tiff": (img_a.astype(np.float32) / 255.0, img_a),
        "grey.bmp": (grey, cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)),
    }
    for name, (stored, expected) in cases.items():
        assert cv2.imwrite(str(tmp_path / name), stored)
        img = read_image(tmp_path / name)
        assert img.dtype == np.uint8 and img.shape == img_a.shape, name
        assert np.array_equal(img, expected), name


def test_float_image_with_nan_reads_black_without_warning(img_a):
    stored = img_a.astype(np.float32) / 255.0
    stored[:100] = np.nan
    with np.errstate(all="raise"):
        img = to_bgr8(stored)
    assert (img[:100] == 0).all() and np.array_equal(img[100:], img_a[100:])


def test_signed_pixels_are_refused_with_what_to_do(img_a, tmp_path):
    assert cv2.imwrite(str(tmp_path / "s16.tiff"), img_a.astype(np.int16))
    with pytest.raises(InputError, match="unsupported pixel type int16; convert"):
        read_image(tmp_path / "s16.tiff")


def test_atomic_output_turns_os_errors_into_output_errors(tmp_path, monkeypatch):
    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(outputs.tempfile, "mkstemp", refuse)
    with pytest.raises(OutputError, match="Permission denied"):
        with atomic_output(tmp_path / "x.png"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_atomic_output_rename_failure_is_output_error_and_removes_temp(tmp_path, monkeypatch):
    def refuse(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(outputs.os, "replace", refuse)
    with pytest.raises(OutputError, match="No space left"):
        with atomic_output(tmp_path / "x.png") as tmp:
            tmp.write_bytes(b"data")
    assert list(tmp_path.iterdir()) == []


def test_atomic_output_gives_the_file_the_umask_mode_not_mkstemps_0600(tmp_path, monkeypatch):
    monkeypatch.setattr(outputs, "_UMASK", 0o027)  # as read at import by a process with that umask
    with atomic_output(tmp_path / "x.png") as tmp:
        tmp.write_bytes(b"data")
    assert (tmp_path / "x.png").stat().st_mode & 0o777 == 0o640



# --- unrelated noise is refused as unrelated photos are: too few matches agree on what they show ----------

NOISE = {
    "uniform colour": lambda rng: rng.integers(0, 256, (512, 512, 3), dtype=np.uint8),
    "gaussian grey": lambda rng: np.repeat(np.clip(rng.normal(128, 40, (480, 640, 1)), 0, 255).astype(np.uint8), 3, 2),
    "blurred colour": lambda rng: cv2.GaussianBlur(rng.integers(0, 256, (600, 400, 3), dtype=np.uint8), (0, 0), 1.5),
}


@pytest.mark.parametrize("kind", sorted(NOISE))
def test_two_unrelated_noise_images_are_refused_like_unrelated_photos(kind, dirs, capfd, warp_device):
    folder_in, folder_out = dirs
    paths = []
    for seed in (1, 2):
        path = folder_in / f"noise{seed}.png"
        cv2.imwrite(str(path), NOISE[kind](np.random.default_rng(seed)))
        paths.append(path)
    before = [p.read_bytes() for p in paths]
    rc, err, _ = run_cli(["image", *paths, "-o", folder_out / "p.png"], capfd, warp_device)
    assert rc == MatchError.exit_code
    assert_one_line_error(err, "check that the images overlap")
    assert list(folder_out.iterdir()) == [] and [p.read_bytes() for p in paths] == before


@pytest.mark.parametrize("width, height, shown", [
    (640, 480, "640x480 px (0.307 MP)"), (100, 100, "100x100 px (0.01 MP)"), (25000, 25000, "25000x25000 px (625 MP)"),
    (40000, 40000, "40000x40000 px (1600 MP)")])
def test_a_size_refusal_shows_the_megapixels_never_as_0(width, height, shown):
    from sena_warp.imageio import check_size

    with pytest.raises(InputError, match=re.escape(shown)):
        check_size("x.png", width, height, 0.001)
