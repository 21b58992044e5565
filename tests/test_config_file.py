"""Settings files (``--config FILE.toml``) and ``sena-warp config``: every Config field, checked at the boundary."""

from __future__ import annotations

import dataclasses
import json
import sys

import pytest

from sena_warp import config_file
from sena_warp.cli import main
from sena_warp.config import BOUNDS_BETWEEN, CHOICES, RANGES, Config, field_types
from sena_warp.config_file import check_config, config_toml, field_docs, load_settings, non_default
from sena_warp.errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

NAMES = [f.name for f in dataclasses.fields(Config)]


def run_config(argv, capsys) -> tuple[int, str, list[str]]:
    rc = main(["config", *map(str, argv)])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err.splitlines()


def test_every_field_has_its_comment_and_group_from_config_py():
    docs = field_docs()
    assert [d.name for d in docs] == NAMES
    assert all(d.comment and d.section for d in docs), [d.name for d in docs if not (d.comment and d.section)]
    by_name = {d.name: d for d in docs}
    assert by_name["alpha"].comment.startswith("alpha: sigma_j = alpha * diag(c_j)")  # the paper's symbol
    assert by_name["alpha"].section == "warp, fine tuning: local affines T_j (step 3)"
    assert "px" in by_name["xfeat_max_side"].comment and "nodes" in by_name["sigma_l_nodes"].comment  # units


def test_the_listing_is_a_settings_file_of_the_defaults(capsys, tmp_path):
    rc, out, err = run_config([], capsys)
    assert rc == 0 and err == []
    assert tomllib.loads(out) == dataclasses.asdict(Config())
    assert 'grid_x = 6  # G_x: cells across the overlap' in out and out.rstrip().endswith("]")
    assert "# --- warp, fine tuning: seam guard, gate G (step 5)" in out
    saved = tmp_path / "defaults.toml"
    saved.write_text(out)
    assert load_settings(saved) == dataclasses.asdict(Config())  # saved as it is, it is a valid --config file


def test_a_settings_file_changes_fields_and_options_win_over_it(capsys, tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('grid_x = 8\nlambda1 = 0  # an int where a float goes\nfeatures = "sift"\n')
    assert load_settings(path) == {"grid_x": 8, "lambda1": 0.0, "features": "sift"}
    rc, out, _ = run_config(["--config", path, "--features", "xfeat", "--threads", 2], capsys)
    listed = tomllib.loads(out)
    assert rc == 0 and (listed["grid_x"], listed["features"], listed["cpu_threads"]) == (8, "xfeat", 2)
    assert "grid_x = 8  # G_x" in out and out.count("(default: ") == 3  # grid_x, lambda1, cpu_threads


@pytest.mark.parametrize("text, words", [
    ("grid_xx = 8\n", ["unknown setting 'grid_xx'; did you mean 'grid_x' or 'grid_y'? (all settings: sena-warp config)"]),
    ("qqqq = 8\n", ["unknown setting 'qqqq' (all settings: sena-warp config)"]),
    ("grid_x = 8.5\n", ["grid_x = 8.5 is not a whole number", "default: 6"]),
    ("grid_x = true\n", ["grid_x = true is not a whole number"]),
    ("features = 3\n", ['features = 3 is not text (default: "xfeat")']),
    ('alpha = "big"\n', ['alpha = "big" is not a number']),
    ('features = "orb"\n', ['features = "orb" is not one of xfeat, sift']),
    ("grid_x = 0\n", ["grid_x = 0 is out of range [1, 64]"]),
    ("cpu_threads = -1\n", ["cpu_threads = -1 is out of range [0, 256]"]),
    ("ransac_confidence = 1.5\n", ["ransac_confidence = 1.5 is out of range (0, 1]"]),
    ("video_crf = 52\n", ["video_crf = 52 is out of range [0, 51]"]),
    ("gain_stride = 1000000000\n", ["gain_stride = 1000000000 is out of range [1, 64]"]),
    ("lattice_nx = 100000\n", ["lattice_nx = 100000 is out of range [2, 512]"]),
    ("seam_separation_rows = 1000000000\n", ["seam_separation_rows = 1000000000 is out of range [1, 64]"]),
    ("seam_blend_rows = 1000000000\n", ["seam_blend_rows = 1000000000 is out of range [1, 1023]"]),
    ("flat_patch_px = 100000\n", ["flat_patch_px = 100000 is out of range [1, 64]"]),
    ("cpu_threads = 100000\n", ["cpu_threads = 100000 is out of range [0, 256]"]),
    ("gain_dark_level = 250.0\n", ["gain_dark_level = 250.0 must be < gain_bright_level = 250.0"]),
    ("alpha = nan\n", ["alpha = nan must be a finite number"]),
    ("conf_min = 2.0\n", ["conf_min = 2.0 must be <= conf_max = 1.5 (k_min <= k_max)"]),
    ("lambda2 = 0.001\n", ["lambda1 = 0.005 must be < lambda2 = 0.001 (the refit is stronger)"]),
    ("[step3]\nalpha = 0.3\n", ["[step3] is a table; settings are top-level"]),
    ("grid_x = \n", ["not valid TOML", "line 1"]),
])
def test_a_bad_settings_file_is_one_line_exit_2(text, words, capsys, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    rc, out, err = run_config(["--config", path], capsys)
    assert rc == 2 and out == "" and len(err) == 1 and err[0].startswith("sena-warp: error: ")
    for word in words:
        assert word in err[0], (word, err[0])


def test_a_missing_settings_file_and_a_bad_option_are_exit_2(capsys, tmp_path):
    rc, _, err = run_config(["--config", tmp_path / "none.toml"], capsys)
    assert rc == 2 and err == [f"sena-warp: error: {tmp_path / 'none.toml'}: file not found"]
    rc = main(["image", "a.jpg", "b.jpg", "-o", str(tmp_path / "p.png"), "--threads", "0"])  # argparse's own error
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "--threads: 0 is not a positive whole number" in err[0]
    rc = main(["image", "a.jpg", "b.jpg", "-o", str(tmp_path / "p.png"), "--threads", "999"])  # the setting's range
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and err == ["sena-warp: error: --threads: cpu_threads = 999 is out of range [0, 256]"]
    assert list(tmp_path.iterdir()) == []


def test_every_number_has_a_range_that_holds_its_default_and_every_bound_names_real_fields():
    numbers = {name for name, kind in field_types().items() if kind in (int, float)}
    assert set(RANGES) == numbers
    assert set(CHOICES) <= {name for name, kind in field_types().items() if kind is str}
    assert all(RANGES[name].holds(getattr(Config(), name)) for name in numbers)
    assert {name for name, _, other, _ in BOUNDS_BETWEEN} | {other for _, _, other, _ in BOUNDS_BETWEEN} <= numbers
    assert check_config(Config(), "defaults") == Config()


@pytest.mark.parametrize("changes, words", [
    ({"video_crf": 99}, "video_crf = 99 is out of range [0, 51]"),
    ({"grid_x": "8"}, 'grid_x = "8" is not a whole number (default: 6)'),
    ({"grid_x": 8.0}, "grid_x = 8.0 is not a whole number"),
    ({"alpha": True}, "alpha = true is not a number"),
    ({"features": None}, "features = None (NoneType) is not text"),
    ({"alpha": float("inf")}, "alpha = inf must be a finite number"),
    ({"lambda1": 2.0}, "lambda1 = 2.0 must be < lambda2 = 1.0"),
    ({"device": "tpu"}, 'device = "tpu" is not one of auto, cpu, cuda'),
])
def test_config_in_python_checks_types_ranges_and_bounds_as_a_settings_file_does(changes, words):
    with pytest.raises(InputError) as caught:
        Config(**changes)
    assert str(caught.value) == f"Config: {words}" or str(caught.value).startswith(f"Config: {words}")
    with pytest.raises(InputError, match="Config: video_crf = 52"):
        Config().replace(video_crf=52)


def test_config_in_python_takes_an_int_for_a_float_and_numpy_numbers():
    import numpy as np

    cfg = Config(alpha=1, grid_x=np.int64(8), lambda2=np.float32(2.0))
    assert (cfg.alpha, type(cfg.alpha), cfg.grid_x, type(cfg.grid_x)) == (1.0, float, 8, int)
    assert tomllib.loads(config_toml(cfg))["grid_x"] == 8


def test_non_default_lists_what_differs_in_field_order():
    assert non_default(Config()) == {}
    assert non_default(Config(grid_y=3, features="sift")) == {"features": "sift", "grid_y": 3}


def test_config_toml_writes_each_type_as_toml_reads_it_back():
    cfg = Config(sigma_d_ratio=1e-7, video_preset="slow", zone_eps=0.5)
    assert tomllib.loads(config_toml(cfg)) == dataclasses.asdict(cfg)
    with pytest.raises(InputError, match="unknown setting 'alfa'; did you mean 'alpha'"):
        config_file.check_settings({"alfa": 1.0}, "here")
    assert json.loads(json.dumps(non_default(cfg))) == non_default(cfg)  # JSON-ready for the report
