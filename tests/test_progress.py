"""What a run says while it works: stage names from start-up on, counts, one line per warning.

A redrawn line on a terminal (``--progress bar``), whole lines otherwise (no escape codes in logs),
one JSON object per line for machines; ``-q`` keeps only warnings and errors, ``-v`` adds each step
and its time. Library callers see nothing until they configure logging.
"""

from __future__ import annotations

import io
import json
import logging

import pytest

from sena_warp import progress
from sena_warp.cli import build_parser, main
from sena_warp.kernels import runtime
from sena_warp.progress import LOGGER, ConsoleHandler, Count, stage

IMAGE_STAGES = ["reading images", "estimating maps", "compositing", "writing outputs"]
VIDEO_STAGES = ["opening videos", "estimating maps", "stitching frames"]


@pytest.fixture(scope="module")
def pair(bundled_dir):
    return [str(bundled_dir / "udisd_test_000001" / name) for name in ("a.jpg", "b.jpg")]


@pytest.fixture(scope="module")
def clips(bundled_dir):
    return [str(bundled_dir / "video" / name) for name in ("office_cam1.mp4", "office_cam2.mp4")]


@pytest.fixture(scope="module")
def one_try(tmp_path_factory):
    """A settings file: the first estimate from one frame pair (the tests are about what is said)."""
    path = tmp_path_factory.mktemp("settings") / "fast.toml"
    path.write_text("video_estimate_pairs = 1\n")
    return str(path)


def screen(text: str) -> list[str]:
    """The lines a terminal shows for ``text``: a redraw (``\\r`` and erase-line) replaces its line."""
    shown = (line.split("\r\x1b[K")[-1] for line in text.split("\n"))
    return [line for line in shown if line]


def cli(argv, capfd, warp_device) -> tuple[int, str, str]:
    capfd.readouterr()
    rc = main([*map(str, argv), "--device", warp_device])
    captured = capfd.readouterr()
    return rc, captured.out, captured.err


def test_plain_lines_name_each_stage_without_escape_codes(pair, tmp_path, capfd, warp_device):
    rc, out, err = cli(["image", *pair, "-o", tmp_path / "p.png"], capfd, warp_device)
    assert rc == 0 and "\x1b" not in err and "\r" not in err
    assert err.splitlines() == [f"sena-warp: {name}" for name in IMAGE_STAGES]
    assert out.startswith(f"{tmp_path / 'p.png'}: ") and out.count("\n") == 1


def test_verbose_adds_each_step_with_its_time_and_quiet_says_nothing(pair, tmp_path, capfd, warp_device):
    rc, _, err = cli(["image", *pair, "-o", tmp_path / "p.png", "-v"], capfd, warp_device)
    steps = [line.split(": ")[1] for line in err.splitlines() if line.endswith(" s")]
    assert rc == 0 and steps[:2] == ["load_kernels", "features"] and "seam_maps" in steps and "composite" in steps
    rc, out, err = cli(["image", *pair, "-o", tmp_path / "q.png", "-q"], capfd, warp_device)
    assert rc == 0 and out == "" and err == ""


def test_json_progress_is_one_object_per_line(clips, one_try, tmp_path, capfd, warp_device):
    rc, out, err = cli(["video", *clips, "-o", tmp_path / "o.mp4", "--progress", "json", "--config", one_try],
                       capfd, warp_device)
    events = [json.loads(line) for line in err.splitlines()]
    assert rc == 0 and out.startswith(str(tmp_path / "o.mp4"))
    assert [e["stage"] for e in events if e["event"] == "stage"] == VIDEO_STAGES
    counts = [e for e in events if e["event"] == "progress"]
    assert counts[-1]["done"] == counts[-1]["total"] == 48 and counts[-1]["name"] == "frames"
    assert counts[-1]["rate"] > 0 and counts[-1]["rate_unit"] == "fps"
    assert all(a["time_s"] <= b["time_s"] for a, b in zip(events, events[1:]))


def test_bar_redraws_one_line_and_a_fallback_is_one_warning_line(clips, one_try, tmp_path, capfd, warp_device):
    rc, _, err = cli(["video", *clips, "-o", tmp_path / "o.mp4", "--report", tmp_path / "r.json", "--progress",
                      "bar", "--config", one_try, "--codec", "h264_nvenc"], capfd, warp_device)
    encoder = json.loads((tmp_path / "r.json").read_text())["output"]["encoder"]
    assert rc == 0 and encoder["requested"] == "h264_nvenc"
    assert "\r\x1b[Ksena-warp: stitching frames" in err
    assert "100% |" + "#" * progress.BAR_WIDTH + "| 48/48 frames" in err
    warnings = [line for line in screen(err) if line.startswith("sena-warp: warning: encoder")]
    if encoder["codec"] == "h264_nvenc":  # a machine where NVENC opens: nothing to warn about
        assert warnings == []
    else:
        assert len(warnings) == 1 and warnings[0].startswith("sena-warp: warning: encoder h264_nvenc ")
        assert warnings[0].endswith("; used libx264")


def test_a_failure_ends_in_one_error_line_in_every_mode(tmp_path, capfd, warp_device):
    missing = tmp_path / "missing.jpg"
    for mode in ("plain", "bar"):
        rc, _, err = cli(["image", missing, missing, "-o", tmp_path / "p.png", "--progress", mode], capfd, warp_device)
        assert rc == 2 and screen(err)[-1] == f"sena-warp: error: {missing}: file not found"
    rc, _, err = cli(["image", missing, missing, "-o", tmp_path / "p.png", "--progress", "json"], capfd, warp_device)
    assert rc == 2 and json.loads(err.splitlines()[-1])["message"] == f"{missing}: file not found"


def test_every_subcommand_answers_version(capsys):
    commands = build_parser()._subparsers._group_actions[0].choices
    assert {"image", "video", "match", "batch", "config", "eval", "bench"} <= set(commands)
    for command in commands:
        assert main([command, "--version"]) == 0 and capsys.readouterr().out == "sena-warp 0.1.0\n"


def test_compiling_kernels_is_said_once_and_counted_module_by_module(monkeypatch, caplog, warp_device):
    runtime.prewarm(warp_device)
    monkeypatch.setattr(runtime, "_loaded", set())
    monkeypatch.setattr(runtime, "_loads", {})
    monkeypatch.setattr(runtime, "_compile_count", None)
    with caplog.at_level(logging.DEBUG, logger="sena_warp"):
        runtime.prewarm(warp_device)  # shipped or cached: nothing to say
        assert not [r for r in caplog.records if hasattr(r, "stage") or hasattr(r, "count")]
        # As a first run without the shipped builds sees it: every module is compiled, each one counted.
        monkeypatch.setattr(runtime, "_loaded", set())
        monkeypatch.setattr(runtime, "_loads", {})
        monkeypatch.setattr(runtime, "shipped_build", lambda module, device: None)
        monkeypatch.setattr(runtime, "_in_kernel_cache", lambda module, device: False)
        runtime.prewarm(warp_device, channels=(1, 2))
        runtime.prewarm(warp_device, channels=(1, 2))
    stages = [r.stage for r in caplog.records if hasattr(r, "stage") and r.levelno == logging.INFO]
    assert stages == ["compiling kernels (first run only)"]
    modules = runtime.kernel_modules(warp_device, (1, 2))
    counts = [r.done for r in caplog.records if hasattr(r, "count")]
    assert sorted(counts) == list(range(1, sum(len(m) for m in modules.values()) + 1))
    assert sum(r.getMessage().startswith("compiled ") for r in caplog.records if r.levelno == logging.DEBUG) == len(counts)


def test_a_count_is_shown_at_most_once_per_interval_and_always_at_its_end(monkeypatch):
    stream = io.StringIO()
    handler = ConsoleHandler(stream, "plain", verbose=False)
    LOGGER.addHandler(handler)
    monkeypatch.setattr(LOGGER, "level", logging.INFO)
    try:
        stage("stitching frames")
        count = Count("frames", 1000, "fps")
        for done in range(1, 1001):
            count.update(done)
        count.close(1000)
        LOGGER.warning("a fallback")
    finally:
        LOGGER.removeHandler(handler)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "sena-warp: stitching frames" and lines[-1] == "sena-warp: warning: a fallback"
    assert 2 <= len(lines) - 2 <= 3 and lines[-2].startswith("sena-warp: 1000/1000 frames")


@pytest.mark.parametrize("mode", ["plain", "json"])
def test_a_count_s_last_figure_is_said_once(mode, monkeypatch):
    # Jobs take longer than the redraw interval: every update is shown, and the close must not repeat the last.
    monkeypatch.setitem(progress.REDRAW_INTERVAL_S, mode, 0.0)
    stream = io.StringIO()
    handler = ConsoleHandler(stream, mode, verbose=False)
    LOGGER.addHandler(handler)
    monkeypatch.setattr(LOGGER, "level", logging.INFO)
    try:
        count = Count("jobs", 3, "jobs/s")
        for done in (1, 2, 3):
            count.update(done)
        count.close(3)
    finally:
        LOGGER.removeHandler(handler)
    lines = stream.getvalue().splitlines()
    shown = [json.loads(line)["done"] for line in lines] if mode == "json" else [line.split()[1] for line in lines]
    assert shown == ([1, 2, 3] if mode == "json" else ["1/3", "2/3", "3/3"])
