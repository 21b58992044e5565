"""The README's Python examples run as written (on the bundled inputs, under the names they use)."""

from __future__ import annotations

import json
import logging
import re
import shutil
from pathlib import Path

import pytest

README = (Path(__file__).resolve().parents[1] / "README.md").read_text()
EXAMPLES = re.findall(r"```python\n(.*?)```", README, re.S)


@pytest.fixture
def workdir(bundled_dir, tmp_path, monkeypatch):
    pair, clips = bundled_dir / "udisd_test_000001", bundled_dir / "video"
    shutil.copy(pair / "a.jpg", tmp_path / "a.jpg")
    shutil.copy(pair / "b.jpg", tmp_path / "b.jpg")
    shutil.copy(clips / "rooftop_left.mp4", tmp_path / "left.mp4")
    shutil.copy(clips / "rooftop_right.mp4", tmp_path / "right.mp4")
    (tmp_path / "my.toml").write_text('device = "cpu"\n')
    monkeypatch.chdir(tmp_path)
    # An example configures logging for its own process: undone here for the tests after it.
    monkeypatch.setattr(logging.root, "handlers", list(logging.root.handlers))
    monkeypatch.setattr(logging.root, "level", logging.root.level)
    return tmp_path


def test_the_readme_has_the_image_video_and_job_examples():
    assert len(EXAMPLES) == 3
    assert "crop_to_covered" in EXAMPLES[0] and "stitch_videos" in EXAMPLES[1] and "run_job" in EXAMPLES[2]


@pytest.mark.parametrize("index", range(len(EXAMPLES)))
def test_a_readme_example_runs(index, workdir, warp_device):
    exec(compile(EXAMPLES[index], f"README.md example {index + 1}", "exec"), {})
    written = {0: ["pano.png", "report.json"], 1: ["pano.mp4"], 2: ["pano.png", "pano.json"]}[index]
    assert all((workdir / name).stat().st_size > 0 for name in written)
    if index == 2:
        assert json.loads((workdir / "pano.json").read_text())["canvas"]["crop_xywh"] is not None
