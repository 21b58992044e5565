"""Layering: the evaluation subpackage imports the pipeline, never the reverse.

Only the front end may reach ``sena_warp.evaluation``: the command line (lazily, for ``eval`` and
``bench``) and the jobs it and ``batch`` run (the figures of an image's report, and those of
``video --figures``).
"""

from __future__ import annotations

import ast

import pytest

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


def test_every_benchmark_script_imports_and_answers_help(monkeypatch, capsys):
    """benchmarks/ are commands a user runs, outside the package: an import that moved (video_figures.py
    imported a ``write_report`` that had become ``report.write_json``) breaks them without any other
    test noticing. Each answers ``--help`` (exit 0) without doing its work. They run as ``__main__`` in
    this process, one after another, so the libraries are imported once rather than once a script."""
    import runpy
    import sys

    scripts = sorted((REPO / "benchmarks").glob("*.py"))
    assert len(scripts) >= 10
    for script in scripts:
        monkeypatch.setattr(sys, "argv", [str(script), "--help"])
        monkeypatch.setattr(sys, "path", [str(script.parent), *sys.path])
        with pytest.raises(SystemExit) as done:
            runpy.run_path(str(script), run_name="__main__")
        out = capsys.readouterr().out
        assert done.value.code in (0, None) and "usage" in out.lower(), (script.name, out[-500:])


def class_attributes(node: ast.ClassDef) -> set[str]:
    """The attributes a class's instances hold: its annotated fields (a dataclass's) and every
    ``self.NAME`` its methods assign."""
    names = {stmt.target.id for stmt in node.body if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)
             and "ClassVar" not in ast.unparse(stmt.annotation)}
    for method in (stmt for stmt in node.body if isinstance(stmt, ast.FunctionDef)):
        for sub in ast.walk(method):
            targets = sub.targets if isinstance(sub, ast.Assign) else [sub.target] if isinstance(
                sub, (ast.AnnAssign, ast.AugAssign)) else []
            for target in targets:
                for leaf in ast.walk(target):
                    if isinstance(leaf, ast.Attribute) and isinstance(leaf.value, ast.Name) and leaf.value.id == "self":
                        names.add(leaf.attr)
    return names


def test_no_class_of_the_frame_path_holds_more_than_15_attributes():
    """The video path is values and small parts, not an object that remembers everything (a compositor
    once held 37 attributes, its per-frame seam 46)."""
    paths = [*sorted((REPO / "video").glob("*.py")), REPO / "sena_warp" / "composite.py"]
    sizes = {f"{path.name}:{node.name}": len(class_attributes(node)) for path in paths
             for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ClassDef)}
    assert len(sizes) > 20 and sizes["stitch.py:SenaFrameCompositor"] > 10  # the count sees them
    assert sizes["reader.py:DecodeLog"] == 15 and sizes["reader.py:FrameReader"] > 10
    assert {name: size for name, size in sizes.items() if size > 15} == {}


def test_no_kernel_takes_more_than_12_parameters():
    """What travels together is one typed argument (``@wp.struct``): a frame kernel once took 29."""
    import warp as wp

    from sena_warp.kernels import runtime

    kernels = [kernel for modules in runtime.kernel_modules("cuda").values() for module in modules
               for kernel in module.kernels.values()]
    assert len(kernels) >= 25
    assert {kernel.key: len(kernel.adj.args) for kernel in kernels if len(kernel.adj.args) > 12} == {}
    assert all(isinstance(kernel, wp.Kernel) for kernel in kernels)


TRANSFER_CALLS = {"numpy", "assign", "synchronize", "synchronize_device", "synchronize_stream", "copy", "clone",
                  "from_numpy", "array", "to"}


def test_every_transfer_and_wait_goes_through_the_counting_module():
    """A copy between the host and the device, or a wait for the device, anywhere in the pipeline but
    ``kernels/transfer.py`` would be one the per-frame counts do not see (``test_video_stitch.py``)."""
    found = {}
    for path in PIPELINE:
        if path.name == "transfer.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in TRANSFER_CALLS:
                owner = ast.unparse(node.func.value)
                annotation = node.func.attr == "array" and not node.args and {k.arg for k in node.keywords} <= {
                    "dtype", "ndim"}  # a kernel's parameter type
                if (node.func.attr in ("numpy", "assign", "to") or owner in ("wp", "warp")) and not annotation:
                    found.setdefault(path.relative_to(REPO).as_posix(), []).append(ast.unparse(node)[:60])
    assert found == {}
