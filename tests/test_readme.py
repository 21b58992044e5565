"""The README's Python examples run as written, one after another in one folder, as a reader runs them."""

from __future__ import annotations

import json
import logging
import re
import shutil
from pathlib import Path

import cv2
import pytest

README = (Path(__file__).resolve().parents[1] / "README.md").read_text()
EXAMPLES = re.findall(r"```python\n(.*?)```", README, re.S)


@pytest.fixture
def workdir(bundled_dir, tmp_path, monkeypatch):
    """The folder the README describes: a.jpg, b.jpg, left.mp4, right.mp4 and my.toml."""
    pair, clips = bundled_dir / "udisd_test_000001", bundled_dir / "video"
    shutil.copy(pair / "a.jpg", tmp_path / "a.jpg")
    shutil.copy(pair / "b.jpg", tmp_path / "b.jpg")
    shutil.copy(clips / "rooftop_left.mp4", tmp_path / "left.mp4")
    shutil.copy(clips / "rooftop_right.mp4", tmp_path / "right.mp4")
    (tmp_path / "my.toml").write_text('device = "cpu"\ngrid_x = 4\n')
    monkeypatch.chdir(tmp_path)
    # An example configures logging for its own process: undone here for the tests after it.
    monkeypatch.setattr(logging.root, "handlers", list(logging.root.handlers))
    monkeypatch.setattr(logging.root, "level", logging.root.level)
    return tmp_path


def test_the_readme_has_the_files_videos_settings_and_arrays_examples():
    assert len(EXAMPLES) == 4
    assert "from sena_warp import Config, stitch_images" in EXAMPLES[0] and "stitch_videos" in EXAMPLES[1]
    assert "overwrite=True" in EXAMPLES[2] and "sena_warp.stitch import stitch_images" in EXAMPLES[3]


def test_the_readme_examples_run_in_order_in_one_folder(workdir, warp_device, capsys):
    for index, example in enumerate(EXAMPLES):
        exec(compile(example, f"README.md example {index + 1}", "exec"), {})
    printed = capsys.readouterr().out.splitlines()
    assert all((workdir / name).stat().st_size > 0
               for name in ("pano.png", "pano.json", "check.png", "pano.mp4", "cropped.png"))
    assert json.loads((workdir / "pano.json").read_text())["canvas"]["crop_xywh"] is not None
    # The video example: its span (1 s at 30 fps) in HEVC at most 320 wide; its still as wide.
    video = cv2.VideoCapture(str(workdir / "pano.mp4"))
    assert video.get(cv2.CAP_PROP_FRAME_WIDTH) == 320 == cv2.imread(str(workdir / "check.png")).shape[1]
    assert printed[1].startswith("30 {'codec': 'libx265'")
    # The third example was refused first (exit code 6), then replaced the panorama with its settings' one.
    assert printed[2].startswith("6 pano.png: exists")
    replaced, cropped = cv2.imread(str(workdir / "pano.png"), cv2.IMREAD_UNCHANGED), json.loads(
        (workdir / "pano.json").read_text())["output"]
    assert replaced.shape[2] == 4 and replaced.shape[0] * replaced.shape[1] > cropped["width"] * cropped["height"]
