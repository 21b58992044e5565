"""``--offset auto`` (video/sync.py): offsets of clips cut at known shifts, refusals, the CLI line.

A cut pair's expected offset is its realised shift (whole frames, see ``sync_bench.cut_pair``)
plus, for clips of two cameras, the recordings' own offset measured on the uncut pair. Targets:
audio within 2 ms, motion within one frame.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import assert_one_line_error, run_cli
from sena_warp.config import Config
from sena_warp.errors import SyncError
from sena_warp.evaluation.sync_bench import SHIFTS_S, cut_pair
from sena_warp.video.reader import probe_video
from sena_warp.video.sync import Signal, check_peak, correlate, estimate_offset, measure_offset

AUDIO_TOL_S = 0.002
# The bundled clips last 2 s, so their cuts share 1 s: the default 3 s minimum would refuse them.
SHORT = Config(sync_min_overlap_s=0.75)


@pytest.fixture(scope="module")
def clips(bundled_dir):
    return bundled_dir / "video"


@pytest.fixture(scope="module")
def rooftop(shared_dir):
    return shared_dir / "videos" / "rooftop_handheld"


def frame_s(path) -> float:
    return float(1 / probe_video(path).fps)


def test_correlate_finds_a_fractional_shift_with_the_offset_sign():
    # The right signal is the left one 0.5 s + 0.3 samples later; its own clock starts 0.1 s later too.
    rate_hz, size = 100.0, 4096
    rng = np.random.default_rng(3)
    smooth = np.fft.irfft(np.fft.rfft(rng.normal(size=size)) * (np.fft.rfftfreq(size) < 0.05), size)
    later = np.fft.irfft(np.fft.rfft(smooth) * np.exp(2j * np.pi * np.fft.rfftfreq(size) * 50.3), size)
    left, right = Signal(smooth[:1500], rate_hz, 0.0), Signal(later[:1500], rate_hz, 0.1)
    peak = correlate(left, right, max_lag_s=10.0, exclusion_s=0.0, min_overlap_s=3.0)
    assert peak.offset_s == pytest.approx(0.503 - 0.1, abs=0.05 / rate_hz)
    assert peak.value > 0.99 and peak.confidence > 0.9


def test_a_periodic_signal_is_ambiguous_and_refused():
    rate_hz = 30.0
    beat = np.sin(2 * np.pi * np.arange(600) / rate_hz)  # one beat a second: every whole second fits
    peak = correlate(Signal(beat, rate_hz, 0.0), Signal(beat[15:], rate_hz, 0.0), 10.0, 0.0, 3.0)
    assert peak.confidence < 0.05
    with pytest.raises(SyncError, match="ambiguous"):
        check_peak(peak, "motion", Config())


def test_audio_of_a_bundled_clip_cut_half_a_second_later(clips, tmp_path):
    cut = cut_pair(clips / "rooftop_left.mp4", clips / "rooftop_left.mp4", tmp_path, 0.5, True, 0.0, 1.5)
    estimate = estimate_offset(cut.left, cut.right, SHORT)
    assert estimate.method == "audio" and cut.realised_shift_s == 0.5
    assert abs(estimate.offset_s - 0.5) < AUDIO_TOL_S and estimate.peak.confidence > SHORT.sync_min_confidence


def test_two_bundled_cameras_cut_apart_keep_their_own_audio_offset(clips, tmp_path):
    left, right = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4"
    own_s = measure_offset(left, right, "audio", SHORT).offset_s
    assert -0.011 < own_s < -0.008  # the phones' own offset (about -9.5 ms on the full recordings)
    for shift_s in (0.5, -0.5):
        cut = cut_pair(left, right, tmp_path, shift_s, True, max(0.0, -shift_s), 1.5)
        found_s = estimate_offset(cut.left, cut.right, SHORT).offset_s
        assert abs(found_s - own_s - cut.realised_shift_s) < AUDIO_TOL_S, shift_s


def test_motion_of_a_bundled_clip_without_audio(clips, tmp_path):
    cut = cut_pair(clips / "rooftop_left.mp4", clips / "rooftop_left.mp4", tmp_path, -0.5, False, 0.5, 1.5)
    estimate = estimate_offset(cut.left, cut.right, SHORT)
    assert not probe_video(cut.left).has_audio and estimate.method == "motion"
    assert abs(estimate.offset_s + 0.5) < frame_s(cut.left)


def test_a_static_scene_is_refused_and_says_why(clips):
    with pytest.raises(SyncError, match="motion: nothing moves") as refused:
        estimate_offset(clips / "office_cam1.mp4", clips / "office_cam2.mp4", Config())
    assert "audio: not both inputs have a track" in str(refused.value)
    assert refused.value.exit_code == 5 and "\n" not in str(refused.value)


def test_clips_sharing_too_little_are_refused(clips, tmp_path):
    # Two disjoint seconds of one clip: no offset lets them share what a match needs.
    cut = cut_pair(clips / "rooftop_left.mp4", clips / "rooftop_left.mp4", tmp_path, 1.0, False, 0.0, 1.0)
    with pytest.raises(SyncError, match="motion: the (inputs share at most|best offset).*"):
        estimate_offset(cut.left, cut.right, SHORT)


def test_cli_refuses_auto_on_a_static_scene_in_one_line(clips, dirs, capfd, warp_device):
    out = dirs[1] / "pano.mp4"
    rc, err, _ = run_cli(["video", clips / "office_cam1.mp4", clips / "office_cam2.mp4", "-o", out,
                          "--offset", "auto"], capfd, warp_device)
    assert rc == 5 and list(dirs[1].iterdir()) == []
    assert_one_line_error(err, "no clear time offset", "give --offset S")


def test_cli_auto_refuses_frames_above_the_limit_before_decoding(clips, dirs, capfd, warp_device, monkeypatch):
    from sena_warp.video import sync

    monkeypatch.setattr(sync, "open_input", lambda path: pytest.fail(f"decoded {path} above the limit"))
    rc, err, _ = run_cli(["video", clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", "-o", dirs[1] / "p.mp4",
                          "--offset", "auto", "--max-megapixels", "0.01"], capfd, warp_device)
    assert rc == 2 and list(dirs[1].iterdir()) == []
    assert_one_line_error(err, "rooftop_left.mp4", "--max-megapixels")


def test_cli_offset_takes_seconds_or_auto_only(clips, dirs, capfd, warp_device):
    rc, err, _ = run_cli(["video", clips / "office_cam1.mp4", clips / "office_cam2.mp4", "-o", dirs[1] / "p.mp4",
                          "--offset", "soon"], capfd, warp_device)
    assert rc == 2 and list(dirs[1].iterdir()) == []
    assert_one_line_error(err, "neither a number of seconds nor 'auto'")


@pytest.fixture(scope="module")
def rooftop_own_s(rooftop) -> float:
    """The two phones' own offset, by audio on the full recordings."""
    return measure_offset(rooftop / "left.mp4", rooftop / "right.mp4", "audio", Config()).offset_s


@pytest.mark.shared
@pytest.mark.parametrize("shift_s", SHIFTS_S)
def test_rooftop_cut_at_known_offsets(rooftop, rooftop_own_s, tmp_path, shift_s):
    left, right = rooftop / "left.mp4", rooftop / "right.mp4"
    same = cut_pair(left, left, tmp_path, shift_s, keep_audio=True)
    assert abs(same.realised_shift_s - shift_s) < frame_s(left)
    found = estimate_offset(same.left, same.right, Config())
    assert found.method == "audio" and abs(found.offset_s - same.realised_shift_s) < AUDIO_TOL_S
    found = measure_offset(same.left, same.right, "motion", Config())
    assert abs(found.offset_s - same.realised_shift_s) < frame_s(left)
    pair = cut_pair(left, right, tmp_path, shift_s, keep_audio=True)
    found = estimate_offset(pair.left, pair.right, Config())
    assert found.method == "audio" and abs(found.offset_s - rooftop_own_s - pair.realised_shift_s) < AUDIO_TOL_S


@pytest.mark.shared
def test_rooftop_pair_offset_by_audio_and_by_motion(rooftop, rooftop_own_s):
    audio = estimate_offset(rooftop / "left.mp4", rooftop / "right.mp4", Config())
    motion = measure_offset(rooftop / "left.mp4", rooftop / "right.mp4", "motion", Config())
    assert audio.method == "audio" and audio.offset_s == rooftop_own_s and -0.011 < audio.offset_s < -0.008
    assert audio.span_s[0] == pytest.approx(9.8, abs=0.1)  # the whole recording: shorter than the span
    assert abs(motion.offset_s - audio.offset_s) < frame_s(rooftop / "left.mp4")


@pytest.mark.shared
@pytest.mark.parametrize("name", ["house_handheld_stereo", "lecture_hall_static", "futsal_night_static"])
def test_recordings_without_a_clear_offset_are_refused(shared_dir, name):
    # house: its audio and its video disagree (audio peak ~-183 ms, motion ~-1.3 s), both weakly;
    # lecture: different sounds, the left view static; futsal: hum and a static night pitch.
    left, right = sorted((shared_dir / "videos" / name).glob("*.mp4"))
    with pytest.raises(SyncError, match=r"no clear time offset \(audio: .*; motion: .*\)"):
        estimate_offset(left, right, Config())


@pytest.mark.shared
def test_cli_auto_prints_the_estimate_and_reports_it(rooftop, tmp_path, dirs, capfd, warp_device):
    cut = cut_pair(rooftop / "left.mp4", rooftop / "left.mp4", tmp_path, 0.5, keep_audio=True, seconds=4.0)
    out, report = dirs[1] / "pano.mp4", dirs[1] / "report.json"
    rc, err, _ = run_cli(["video", cut.left, cut.right, "-o", out, "--offset", "auto", "--report", report],
                         capfd, warp_device)
    assert rc == 0 and len(err) == 2 and err[0].startswith("sena-warp: offset auto: audio, +500.")
    # The right input started 0.5 s later: the first left frames have no partner, and that is said.
    assert err[1].startswith("sena-warp: warning: the right input starts after the left one: the first ") and \
        err[1].endswith(" left frames have no right frame and are not in the output")
    sync = json.loads(report.read_text())["sync"]
    assert sync["method"] == "audio" and abs(sync["offset_ms"] - 500.0) < AUDIO_TOL_S * 1000
    assert sync["confidence"] > Config().sync_min_confidence and sync["span_s"]["left"] > 3.0
    assert json.loads(report.read_text())["inputs"]["right"]["offset_s"] == pytest.approx(0.5, abs=AUDIO_TOL_S)
