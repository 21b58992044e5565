"""Settings files (``--config FILE.toml``) and the ``sena-warp config`` listing, both onto :class:`Config`.

A settings file is TOML with top-level ``name = value`` lines, one per :class:`Config` field to change;
``sena-warp config`` prints every field in that form (so its output is a valid settings file), with
the paper's symbol, unit and meaning taken from the field's comment in ``config.py``: the comments
there are the one place where a setting is described. Values are checked here, at the boundary, so a
wrong type, an out-of-range number or a misspelt name stops the run before any work with one line
saying what to change (exit code 2).
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import functools
import inspect
import io
import json
import math
import os
import sys
import tokenize
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from . import __version__, config
from .config import CHOICES, Config
from .errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # the standard library's tomllib, as a backport
    import tomli as tomllib

# Numbers are finite and > 0, except those named here, which may also be 0 ...
MAY_BE_ZERO = frozenset({
    "xfeat_detection_threshold", "min_cossim", "min_global_det", "min_overlap_area_px", "lambda1",
    "unstable_min_points", "unstable_min_det", "unstable_max_disp_px", "w_cond", "w_det", "tau_det", "w_delta",
    "sigma_l_nodes", "ramp_min_px", "ramp_diag_ratio", "gamma_min", "sigma_g_px", "zone_jump_px", "zone_lambda",
    "flat_min_std", "brightness_max_diff", "seam_smooth_sigma_px", "seam_fade_px", "video_crf",
    "video_min_inlier_ratio", "video_max_median_change_px", "video_blend_frames", "cpu_threads", "alpha_margin_px",
    "video_blank_max_std", "sync_min_confidence", "sync_audio_min_rms", "sync_audio_min_peak", "sync_audio_exclusion_s",
    "sync_motion_min_spread", "sync_motion_min_peak", "lambda_bend", "seam_step_cost", "seam_gradient_weight",
    "seam_edge_weight", "seam_separation_weight", "seam_unique_weight", "seam_zone_margin", "seam_refine_px",
    "correction_smooth", "seam_blend_ratio", "gain_outlier_fraction", "gain_dark_level", "video_estimate_workers",
    "seam_prior_weight", "global_model_margin", "video_seam_noise", "video_seam_stay_cost", "video_seam_home_cost", "video_seam_margin",
    "video_seam_jump_cost", "video_seam_motion_cost", "video_gain_settle_s", "video_estimate_lookahead_s",
    "video_drift_check_s", "video_align_prior", "video_align_bend",
})
# ... and those named here have an upper bound too (probabilities, ratios, correlations, x264's quality scale).
AT_MOST = {
    "xfeat_detection_threshold": 1.0, "min_cossim": 1.0, "sift_ratio": 1.0, "ransac_confidence": 1.0,
    "gamma_min": 1.0, "video_min_inlier_ratio": 1.0, "video_crf": 51, "sync_min_overlap": 1.0,
    "sync_min_confidence": 1.0, "sync_audio_min_peak": 1.0, "sync_motion_min_peak": 1.0,
    "gain_outlier_fraction": 1.0, "gain_dark_level": 255.0, "gain_bright_level": 255.0,
    "gain_knee_ratio": 1.0, "video_align_follow": 1.0, "video_align_min_share": 1.0, "video_rig_moving_share": 1.0,
    "video_rig_switch_share": 1.0, "video_rig_still_share": 1.0,
}
KIND_WORDS = {int: "a whole number", float: "a number", str: "text", bool: "true or false"}
SECTION_MARK = "# ---"  # a comment line opening a group of fields in config.py


@dataclass(frozen=True)
class FieldDoc:
    """One :class:`Config` field as ``config.py`` describes it: its group and its comment."""

    name: str
    section: str  # e.g. "Step 3: local affines T_j"
    comment: str  # the paper's symbol, unit and meaning, e.g. "alpha: sigma_j = alpha * diag(c_j), ..."


@functools.lru_cache(maxsize=1)
def field_docs() -> tuple[FieldDoc, ...]:
    """Every :class:`Config` field in declaration order, with the comments written beside it in config.py."""
    source = inspect.getsource(config)
    comments = {tok.start[0]: tok.string.lstrip("#").strip()
                for tok in tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT}
    lines = source.splitlines()
    cls = next(n for n in ast.parse(source).body if isinstance(n, ast.ClassDef) and n.name == Config.__name__)
    fields = {n.lineno: n.target.id for n in cls.body if isinstance(n, ast.AnnAssign)}
    docs, section = [], ""
    for line_no in range(cls.lineno, cls.end_lineno + 1):
        if lines[line_no - 1].strip().startswith(SECTION_MARK):
            section = comments[line_no].strip("- ")
        elif line_no in fields:
            docs.append(FieldDoc(fields[line_no], section, comments.get(line_no, "")))
    return tuple(docs)


@functools.lru_cache(maxsize=1)
def field_types() -> Mapping[str, type]:
    """Field name -> its Python type (``int``, ``float`` or ``str``), read-only; worked out once (checking
    every field had taken 0.13 s of a video's set-up)."""
    hints = typing.get_type_hints(Config)
    return types.MappingProxyType({f.name: hints[f.name] for f in dataclasses.fields(Config)})


def unknown_key_error(key: str, valid: list[str], where: str) -> InputError:
    """The one-line error for a name that is not a setting: the closest valid name, then all of them."""
    close = difflib.get_close_matches(key, valid, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return InputError(f"{where}: unknown setting {key!r}{hint} (valid: {', '.join(valid)})")


def check_value(name: str, value, where: str):
    """``value`` for the Config field ``name``, checked for type and range; InputError saying why not.

    An int is accepted for a float field (TOML ``2`` for ``2.0``) and returned as a float.
    """
    kind = field_types()[name]
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
        shown = json.dumps(value) if isinstance(value, (str, bool, int, float)) else repr(value)
        raise InputError(f"{where}: {name} = {shown} is not {KIND_WORDS[kind]} (default: "
                         f"{_toml_value(getattr(Config, name))})")
    if kind is bool:
        return value
    if kind is str:
        allowed = CHOICES.get(name)
        if allowed is not None and value not in allowed:
            raise InputError(f"{where}: {name} = {json.dumps(value)} is not one of {', '.join(allowed)}")
        return value
    if not math.isfinite(value):
        raise InputError(f"{where}: {name} = {value} must be a finite number")
    low_ok = value >= 0 if name in MAY_BE_ZERO else value > 0
    if not low_ok:
        raise InputError(f"{where}: {name} = {value} must be {'>= 0' if name in MAY_BE_ZERO else '> 0'}")
    if name in AT_MOST and value > AT_MOST[name]:
        raise InputError(f"{where}: {name} = {value} must be <= {AT_MOST[name]}")
    return value


def check_config(cfg: Config, where: str) -> Config:
    """``cfg`` when every field passes :func:`check_value` and the fields that bound each other agree."""
    for f in dataclasses.fields(Config):
        check_value(f.name, getattr(cfg, f.name), where)
    if cfg.conf_min > cfg.conf_max:
        raise InputError(f"{where}: conf_min = {cfg.conf_min} must be <= conf_max = {cfg.conf_max}")
    if cfg.lambda2 <= cfg.lambda1:
        raise InputError(f"{where}: lambda2 = {cfg.lambda2} must be > lambda1 = {cfg.lambda1} (the refit is stronger)")
    return cfg


def check_settings(values: dict, where: str) -> dict:
    """Validated Config changes from a mapping of setting names to values (e.g. a parsed TOML table)."""
    valid = [f.name for f in dataclasses.fields(Config)]
    changes = {}
    for key, value in values.items():
        if isinstance(value, dict):
            raise InputError(f"{where}: [{key}] is a table; settings are top-level 'name = value' lines")
        if key not in valid:
            raise unknown_key_error(key, valid, where)
        changes[key] = check_value(key, value, where)
    return changes


def read_toml(path: str | os.PathLike) -> dict:
    """A TOML file as a dict, or InputError (missing, unreadable, not TOML) on one line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as UTF-8 text ({exc})") from exc
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({' '.join(str(exc).split())})") from exc


def load_settings(path: str | os.PathLike) -> dict:
    """The Config changes a settings file asks for, validated (see the module docstring)."""
    return check_settings(read_toml(path), str(path))


def non_default(cfg: Config) -> dict:
    """The fields of ``cfg`` that differ from :class:`Config`'s defaults, by name, in declaration order."""
    default = Config()
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(Config)
            if getattr(cfg, f.name) != getattr(default, f.name)}


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    return repr(value)  # repr of a float always has a '.' or an exponent, as TOML wants


def config_toml(cfg: Config) -> str:
    """Every field of ``cfg`` as a settings file: grouped as in config.py, each with its comment;
    a field that differs from the default says the default."""
    default = Config()
    out = [f"# sena-warp {__version__} settings. Save as FILE.toml, keep the lines you change and run with",
           "# --config FILE.toml; options given on the command line win over the file."]
    section = None
    for doc in field_docs():
        if doc.section != section:
            section = doc.section
            out += ["", f"# --- {section}"]
        value, was = getattr(cfg, doc.name), getattr(default, doc.name)
        changed = f" (default: {_toml_value(was)})" if value != was else ""
        out.append(f"{doc.name} = {_toml_value(value)}  # {doc.comment}{changed}")
    return "\n".join(out) + "\n"
