"""Layering: the evaluation subpackage imports the pipeline, never the reverse.

Only the front end may reach ``sena_warp.evaluation``: the command line (lazily, for ``eval`` and
``bench``) and the jobs it and ``batch`` run (the figures of an image's report, and those of
``video --figures``).
"""

from __future__ import annotations

import ast

from conftest import REPO

PIPELINE = [*sorted((REPO / "sena_warp").glob("*.py")), *sorted((REPO / "kernels").glob("*.py")),
            *sorted((REPO / "video").glob("*.py"))]
FRONT_END = (REPO / "sena_warp" / "cli.py", REPO / "sena_warp" / "jobs.py", REPO / "sena_warp" / "batch.py")


def imported_modules(path) -> set[str]:
    """Every module an ``import`` or ``from ... import`` of ``path`` names (relative ones with their dots)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            names.add("." * node.level + (node.module or ""))
    return names


def test_no_pipeline_module_imports_the_evaluation():
    assert len(PIPELINE) > 30 and set(FRONT_END) <= set(PIPELINE)
    offenders = {path.relative_to(REPO).as_posix(): sorted(name for name in imported_modules(path)
                                                          if "evaluation" in name.split("."))
                 for path in PIPELINE if path not in FRONT_END}
    assert {path: names for path, names in offenders.items() if names} == {}


def test_the_check_sees_the_front_ends_lazy_imports():
    cli, jobs, _ = FRONT_END
    assert {"sena_warp.evaluation.figures", "sena_warp.evaluation.video_figures"} <= imported_modules(jobs)
    assert {"evaluation.bench", "evaluation.evaluate"} <= set(_lazy_modules(cli))


def _lazy_modules(path) -> list[str]:
    """The modules the CLI names for ``_lazy`` (its subcommands imported only when run)."""
    return [node.args[0].value for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "_lazy"]


def test_every_benchmark_script_imports_and_answers_help():
    """benchmarks/ are commands a user runs, outside the package: an import that moved (video_figures.py
    imported a ``write_report`` that had become ``report.write_json``) breaks them without any other
    test noticing. Each answers ``--help`` (exit 0) without doing its work."""
    import subprocess
    import sys

    scripts = sorted((REPO / "benchmarks").glob("*.py"))
    assert len(scripts) >= 10
    for script in scripts:
        done = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0 and "usage" in done.stdout.lower(), (script.name, done.stderr[-500:])
