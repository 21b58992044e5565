import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from sena_warp.cli import _rate_kbps, _seconds, main


@pytest.fixture(scope="module")
def pair(bundled_dir):
    d = bundled_dir / "udisd_test_000001"
    return str(d / "a.jpg"), str(d / "b.jpg")


def test_image_writes_transparent_png_report_and_debug(pair, tmp_path, warp_device, capsys):
    out, report, debug = tmp_path / "pano.png", tmp_path / "r.json", tmp_path / "dbg"
    rc = main(["image", *pair, "-o", str(out), "--report", str(report), "--debug", str(debug),
               "--device", warp_device])
    assert rc == 0
    pano = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert pano.shape[2] == 4
    covered = pano[:, :, 3] > 0
    assert 0.6 < covered.mean() < 1.0  # both views, and transparent corners where nothing was covered
    data = json.loads(report.read_text())
    assert data["global_affine"]["inliers"] >= 100
    assert data["anchors"]["count"] >= 5
    assert data["metrics"]["anchor_residual_median_px"] <= 1.5
    assert set(data["timing_s"]) >= {"features", "global_affine", "ffd", "gains", "zone", "chain", "seam_blend",
                                    "composite"}
    assert data["warp"]["ffd_model"] == "fit" and not data["warp"]["gate"]
    # One picture per stage: the matches side by side, then the stages on the (working-frame) canvas,
    # which for this horizontal rig is the panorama's own grid (no gate: the fitted lattice needs none).
    # A blank or half-drawn picture would have a grey-level std far below 40.
    names = ["01_matches.jpg", "02_overlap_cells.jpg", "03_ffd_field.jpg",
             "05_warped_over_target.jpg", "06_zone_chain_seam.jpg", "07_alpha.jpg"]
    assert sorted(p.name for p in debug.iterdir()) == names
    for name in names:
        picture = cv2.imread(str(debug / name))
        assert picture.shape == ((512, 1024, 3) if name == "01_matches.jpg" else (*pano.shape[:2], 3)), name
        assert picture.std() > 30, name  # a picture of something: a flat one is near 0 (the alpha map: 39.96)
    assert str(out) in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dbg", "pano.png", "r.json"]


def test_image_crop_is_fully_covered_jpeg(pair, tmp_path, warp_device):
    out = tmp_path / "pano.jpg"
    assert main(["image", *pair, "-o", str(out), "--crop", "--device", warp_device]) == 0
    pano = cv2.imread(str(out))
    # No black border left: every edge row/column is mostly image content.
    for edge in (pano[0], pano[-1], pano[:, 0], pano[:, -1]):
        assert (edge.max(axis=1) > 10).mean() > 0.9


def test_reference_choice_swaps_the_warped_input(pair, tmp_path, warp_device):
    report = tmp_path / "r.json"
    assert main(["image", *pair, "-o", str(tmp_path / "p.png"), "--reference", "b", "--report", str(report),
                 "--device", warp_device]) == 0
    assert json.loads(report.read_text())["rig"]["source"] == "a"


@pytest.mark.parametrize("make_input, message", [
    (lambda d: d / "missing.jpg", "not found"),
    (lambda d: (d / "junk.jpg").write_bytes(b"not an image") and d / "junk.jpg", "not a readable image"),
])
def test_bad_input_is_one_line_error_and_no_output(make_input, message, pair, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    bad = make_input(folder)
    out = tmp_path / "p.png"
    assert main(["image", str(bad), pair[1], "-o", str(out), "--device", "cpu"]) == 2
    err = capsys.readouterr().err.splitlines()
    # Not a terminal: plain progress lines (the stage it reached), then the error, one line.
    assert err == ["sena-warp: reading images", err[-1]] and err[-1].startswith("sena-warp: error: ")
    assert message in err[-1]
    assert not out.exists() and list(tmp_path.iterdir()) == [folder]


def test_unknown_output_type_is_refused_before_work(pair, tmp_path, capsys):
    assert main(["image", *pair, "-o", str(tmp_path / "p.gif")]) == 2  # a bad option, like any other
    assert "unsupported output type" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# --- the standard streams: a stdout that cannot take the results, a closed stderr, names with newlines ---

REPO = Path(__file__).resolve().parents[1]
RUN = "import sys; from sena_warp.cli import main; sys.exit(main(sys.argv[1:]))"


def run(argv, **streams) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", RUN, *map(str, argv), "--device", "cpu"], cwd=REPO, text=True,
                          **{"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, **streams})


@pytest.mark.parametrize("command", ["image", "match", "config"])
def test_a_stdout_that_cannot_take_the_results_is_one_line_exit_6(command, pair, tmp_path):
    argv = {"image": ["image", *pair, "-o", tmp_path / "p.png", "-q"], "match": ["match", *pair, "-q"],
            "config": ["config"]}[command]
    if command == "image":
        argv.remove("-q")  # the summary line is what goes to stdout
    with open("/dev/full", "w") as full:
        done = run(argv, stdout=full)
    lines = [line for line in done.stderr.splitlines() if ": error: " in line or "Traceback" in line
             or "Exception" in line]
    assert done.returncode == 6, done.stderr
    assert lines == ["sena-warp: error: stdout: cannot write the results (No space left on device)"]
    if command == "image":  # the panorama was committed before the summary line
        assert cv2.imread(str(tmp_path / "p.png")) is not None


def closed_stderr():
    os.close(2)


def test_with_stderr_closed_a_run_succeeds_and_no_output_holds_its_messages(pair, tmp_path):
    done = run(["image", *pair, "-o", tmp_path / "p.png", "--report", tmp_path / "r.json"], stderr=None,
               preexec_fn=closed_stderr)
    assert done.returncode == 0 and done.stdout.startswith(f"{tmp_path / 'p.png'}: ")
    assert cv2.imread(str(tmp_path / "p.png")) is not None and json.loads((tmp_path / "r.json").read_text())
    failed = run(["image", pair[0], tmp_path / "missing.jpg", "-o", tmp_path / "q.png"], stderr=None,
                 preexec_fn=closed_stderr)
    assert failed.returncode == 2 and not (tmp_path / "q.png").exists()


@pytest.mark.parametrize("name", ["new\nline.jpg", "carriage\rreturn.jpg", "tab\there.jpg", "esc\x1b[2Jape.jpg"])
def test_a_name_with_control_characters_stays_on_one_stderr_line(name, pair, tmp_path, capfd):
    missing = tmp_path / name
    capfd.readouterr()
    assert main(["image", pair[0], str(missing), "-o", str(tmp_path / "p.png"), "-q", "--device", "cpu"]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "\r" not in err and "\x1b" not in err
    assert err == f"sena-warp: error: {str(missing).encode('unicode_escape').decode()}: file not found\n"


def test_python_m_sena_warp_is_the_command(tmp_path):
    # The same parser and messages as the installed script, under the script's name.
    done = subprocess.run([sys.executable, "-m", "sena_warp", "config", "--threads", "3"], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0 and "cpu_threads = 3" in done.stdout
    done = subprocess.run([sys.executable, "-m", "sena_warp", "video", "left.mp4"], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.startswith("sena-warp: error: ") and "sena-warp video --help" in done.stderr


@pytest.mark.parametrize("text, seconds", [("90", 90.0), ("90.5", 90.5), ("1:30.5", 90.5), ("01:00:02", 3602.0)])
def test_times_are_read_as_ffmpeg_reads_them(text, seconds):
    assert _seconds(text) == seconds


@pytest.mark.parametrize("text, kbps", [("8M", 8000), ("8000k", 8000), ("2.5m", 2500), ("8000000", 8000)])
def test_bit_rates_are_read_as_ffmpeg_reads_them(text, kbps):
    assert _rate_kbps(text) == kbps


def test_the_video_options_reach_the_report(bundled_dir, tmp_path, capsys, warp_device):
    clips = bundled_dir / "video"
    argv = ["video", str(clips / "rooftop_left.mp4"), str(clips / "rooftop_right.mp4"), "-o", str(tmp_path / "o.mkv"),
            "--report", str(tmp_path / "r.json"), "--ss", "0:00.5", "-t", "0.5", "--codec", "libx265", "--bitrate",
            "400k", "--maxrate", "600k", "--device", warp_device]
    assert main(argv) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["span_s"] == {"start": 0.5, "end": 1.0} and report["frames_out"] == 15
    encoder = report["output"]["encoder"]
    assert (encoder["codec"], encoder["bitrate_kbps"], encoder["maxrate_kbps"]) == ("libx265", 400, 600)
    assert report["run"]["settings"]["video_start_s"] == 0.5
    assert "(libx265, 400 kbit/s, peak 600 kbit/s)" in capsys.readouterr().out


@pytest.mark.parametrize("options, message", [
    (["--to", "1", "-t", "1"], "--to and -t both end the span; give one of them"),
    (["--crf", "18", "--bitrate", "1M"], "--crf and --bitrate are two ways to set the rate; give one of them"),
    (["--ss", "1", "--to", "0.5"], "the span ends at 0.5 s, not after its start at 1 s"),
    (["--ss", "soon"], "argument --ss: 'soon' is not a time"),
    (["--bitrate", "fast"], "argument --bitrate: 'fast' is not a bit rate"),
])
def test_a_bad_span_or_rate_is_one_line_and_no_output(options, message, bundled_dir, tmp_path, capsys):
    clips = bundled_dir / "video"
    argv = ["video", str(clips / "rooftop_left.mp4"), str(clips / "rooftop_right.mp4"), "-o", str(tmp_path / "o.mp4"),
            *options]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not (tmp_path / "o.mp4").exists()
