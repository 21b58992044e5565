"""Settings files (``--config FILE.toml``) and the ``sena-warp config`` listing, both onto :class:`Config`.

A settings file is TOML with top-level ``name = value`` lines, one per :class:`Config` field to change;
``sena-warp config`` prints every field in that form (so its output is a valid settings file), with
the paper's symbol, unit and meaning taken from the field's comment in ``config.py``: the comments
there are the one place where a setting is described, ``config.RANGES`` and ``config.CHOICES`` the
values it may take. Values are checked here, at the boundary, so a wrong type, an out-of-range number
or a misspelt name stops the run before any work with one line saying what to change (exit code 2).
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import functools
import inspect
import io
import os
import sys
import tokenize
from dataclasses import dataclass
from pathlib import Path

from . import __version__, config
from .config import RANGES, Config, config_problem, field_types, shown, value_problem
from .errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # the standard library's tomllib, as a backport
    import tomli as tomllib

SECTION_MARK = "# ---"  # a comment line opening a group of fields in config.py
CLOSEST = 3  # an unknown setting's error names at most this many close names


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


def unknown_key_error(key: str, valid: list[str], where: str) -> InputError:
    """The one-line error for a name that is not a setting: the closest few valid names, not all of them."""
    close = difflib.get_close_matches(key, valid, n=CLOSEST)
    hint = f"; did you mean {' or '.join(repr(name) for name in close)}?" if close else ""
    return InputError(f"{where}: unknown setting {key!r}{hint} (all settings: sena-warp config)")


def check_value(name: str, value, where: str):
    """``value`` for the Config field ``name``, checked for type and range (``config.RANGES``,
    ``config.CHOICES``); InputError saying why not.

    An int is accepted for a float field (TOML ``2`` for ``2.0``) and returned as a float.
    """
    problem = value_problem(name, value)
    if problem is not None:
        raise InputError(f"{where}: {problem}")
    return float(value) if field_types()[name] is float else value


def check_config(cfg: Config, where: str) -> Config:
    """``cfg`` when every field passes :func:`check_value` and the fields that bound each other agree
    (``config.BOUNDS_BETWEEN``); a Config checks itself when made, this names ``where`` it came from."""
    problem = config_problem(cfg)
    if problem is not None:
        raise InputError(f"{where}: {problem}")
    return cfg


def settings_config(settings: dict, where: str) -> Config:
    """The defaults with ``settings`` (names and values already checked one by one), the fields that bound
    each other checked together; InputError naming ``where`` the settings came from."""
    try:
        return Config().replace(**settings)
    except InputError as exc:
        raise InputError(f"{where}: {str(exc).removeprefix('Config: ')}") from None


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


def config_toml(cfg: Config) -> str:
    """Every field of ``cfg`` as a settings file: grouped by stage as in config.py, each with its comment
    and, for numbers, its range; a field that differs from the default says the default."""
    default = Config()
    out = [f"# sena-warp {__version__} settings. Save as FILE.toml, keep the lines you change and run with",
           "# --config FILE.toml; options given on the command line win over the file. Grouped by stage",
           "# (features, warp, seam, exposure, video, sync, encoding, runtime): in each group the settings",
           "# changed most come first, the fine tuning after them. Numbers end with their range: [1, 64] from 1 to",
           "# 64, (0, 1] above 0 up to 1."]
    section = None
    for doc in field_docs():
        if doc.section != section:
            section = doc.section
            out += ["", f"# --- {section}"]
        value, was = getattr(cfg, doc.name), getattr(default, doc.name)
        allowed = f" {RANGES[doc.name]}" if doc.name in RANGES else ""
        changed = f" (default: {shown(was)})" if value != was else ""
        out.append(f"{doc.name} = {shown(value)}  # {doc.comment}{allowed}{changed}")
    return "\n".join(out) + "\n"
