"""Settings files (``--config FILE.toml``) and ``sena-warp config``: every Config field, checked at the boundary."""

from __future__ import annotations

import dataclasses
import json
import sys

import pytest

from sena_warp import config_file
from sena_warp.cli import main
from sena_warp.config import CHOICES, Config
from sena_warp.config_file import (AT_MOST, MAY_BE_ZERO, check_config, config_toml, field_docs, load_settings,
                                   non_default)
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
    assert by_name["alpha"].section == "Step 3: local affines T_j"
    assert "px" in by_name["xfeat_max_side"].comment and "nodes" in by_name["sigma_l_nodes"].comment  # units


def test_the_listing_is_a_settings_file_of_the_defaults(capsys, tmp_path):
    rc, out, err = run_config([], capsys)
    assert rc == 0 and err == []
    assert tomllib.loads(out) == dataclasses.asdict(Config())
    assert 'grid_x = 6  # G_x: cells across the overlap' in out
    assert "# --- Step 5: seam guard (gate G)" in out
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
    ("grid_xx = 8\n", ["unknown setting 'grid_xx'", "did you mean 'grid_x'?", "valid: max_input_megapixels, alpha_margin_px"]),
    ("grid_x = 8.5\n", ["grid_x = 8.5 is not a whole number", "default: 6"]),
    ("grid_x = true\n", ["grid_x = true is not a whole number"]),
    ("features = 3\n", ['features = 3 is not text (default: "xfeat")']),
    ('alpha = "big"\n', ['alpha = "big" is not a number']),
    ('features = "orb"\n', ['features = "orb" is not one of xfeat, sift']),
    ("grid_x = 0\n", ["grid_x = 0 must be > 0"]),
    ("cpu_threads = -1\n", ["cpu_threads = -1 must be >= 0"]),
    ("ransac_confidence = 1.5\n", ["ransac_confidence = 1.5 must be <= 1.0"]),
    ("video_crf = 52\n", ["video_crf = 52 must be <= 51"]),
    ("alpha = nan\n", ["alpha = nan must be a finite number"]),
    ("conf_min = 2.0\n", ["conf_min = 2.0 must be <= conf_max = 1.5"]),
    ("lambda2 = 0.001\n", ["lambda2 = 0.001 must be > lambda1 = 0.005"]),
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


def test_the_limits_name_real_fields_and_the_defaults_pass_them():
    assert (MAY_BE_ZERO | set(AT_MOST) | set(CHOICES)) <= set(NAMES)
    assert check_config(Config(), "defaults") == Config()
    for name, value in AT_MOST.items():  # an upper bound never excludes the default
        assert getattr(Config(), name) <= value


def test_non_default_lists_what_differs_in_field_order():
    assert non_default(Config()) == {}
    assert non_default(Config(grid_y=3, features="sift")) == {"features": "sift", "grid_y": 3}


def test_config_toml_writes_each_type_as_toml_reads_it_back():
    cfg = Config(sigma_d_ratio=1e-7, video_preset="slow", zone_eps=0.5)
    assert tomllib.loads(config_toml(cfg)) == dataclasses.asdict(cfg)
    with pytest.raises(InputError, match="unknown setting 'alfa'; did you mean 'alpha'"):
        config_file.check_settings({"alfa": 1.0}, "here")
    assert json.loads(json.dumps(non_default(cfg))) == non_default(cfg)  # JSON-ready for the report
