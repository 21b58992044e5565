"""``from sena_warp import ...``: files in and files out with a Config, as the commands do."""

from __future__ import annotations

import subprocess
import sys

import pytest

import sena_warp
from sena_warp import Config, StitchError, load_config, stitch_images, stitch_videos
from sena_warp.errors import InputError, OutputError


def test_importing_the_package_does_not_load_warp():
    # The command line's --help imports the package: the API's Warp comes in on first use only.
    done = subprocess.run([sys.executable, "-c", "import sys, sena_warp; print('warp' in sys.modules)"],
                          capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == "False"
    assert set(sena_warp.__all__) == {"Config", "StitchError", "load_config", "stitch_images", "stitch_videos"}


def test_a_config_s_settings_reach_the_stitch_and_outputs_follow_the_command_line_s_rules(bundled_dir, tmp_path,
                                                                                           warp_device):
    pair = bundled_dir / "udisd_test_000001"
    out = tmp_path / "p.png"
    report = stitch_images(pair / "a.jpg", pair / "b.jpg", out, Config(grid_x=4, device=warp_device),
                           report=tmp_path / "p.json")
    assert report["run"]["settings"] == {"grid_x": 4} and (tmp_path / "p.json").is_file()
    with pytest.raises(OutputError, match="p.png: exists") as refused:
        stitch_images(pair / "a.jpg", pair / "b.jpg", out, Config(device=warp_device))
    assert refused.value.exit_code == 6
    before = out.stat().st_mtime_ns
    stitch_images(pair / "a.jpg", pair / "b.jpg", out, Config(device=warp_device), overwrite=True)
    assert out.stat().st_mtime_ns != before


def test_a_video_s_span_and_offset_are_its_own(bundled_dir, tmp_path, warp_device):
    clips = bundled_dir / "video"
    cfg = Config(device=warp_device, video_start_s=1.0, video_estimate_pairs=1, video_audio="none")
    report = stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "v.mp4", cfg,
                           offset=0.1)
    assert report["frames_out"] == 30 and report["sync"] == {"method": "manual", "offset_ms": 100.0}


def test_a_bad_settings_file_is_one_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("grid_x = 0\n")
    with pytest.raises(InputError, match=r"grid_x = 0 is out of range \[1, 64\]") as bad:
        load_config(path)
    assert isinstance(bad.value, StitchError) and "\n" not in str(bad.value)
