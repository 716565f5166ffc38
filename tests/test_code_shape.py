"""The code's shape: module and function sizes, and no unnamed threshold in the pipeline."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "houghcad"
#: The modules of the pipeline after preprocessing: every threshold there is a
#: named tolerance (houghcad.tolerances) or a named module constant.
PIPELINE_MODULES = ("recognize", "clusters", "splitting", "ransac", "growth", "boundaries", "adjacency", "consolidation",
                    "planes", "scales", "blend", "associate", "pipeline", "output", "context", "state", "noise")
#: Literals that are not thresholds: nothing, one, two (halves, pairs, squares),
#: minus one, and three (the dimension of space, in array shapes).
PLAIN = {0, 1, 2, -1, 3}


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_over_550_lines(path):
    assert len(path.read_text().splitlines()) <= 550


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_function_over_80_lines(path):
    tree = ast.parse(path.read_text())
    long = [f"{n.name} ({n.end_lineno - n.lineno + 1} lines)" for n in ast.walk(tree)
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > 80]
    assert not long


class _Literals(ast.NodeVisitor):
    """Numeric literals outside subscripts and named module constants."""

    def __init__(self) -> None:
        self.found: list[tuple[int, object]] = []

    def visit_Subscript(self, node: ast.Subscript) -> None:  # indices and slices are shapes
        self.visit(node.value)

    def visit_Assign(self, node: ast.Assign) -> None:
        named = all(isinstance(t, ast.Name) and t.id.lstrip("_").isupper() for t in node.targets)
        if not named:
            self.generic_visit(node)

    def visit_Constant(self, node: ast.Constant) -> None:
        v = node.value
        if isinstance(v, (int, float)) and not isinstance(v, bool) and v not in PLAIN:
            self.found.append((node.lineno, v))


@pytest.mark.parametrize("name", PIPELINE_MODULES)
def test_no_unnamed_threshold_in_the_pipeline_modules(name):
    v = _Literals()
    v.visit(ast.parse((SRC / f"{name}.py").read_text()))
    assert not v.found, f"{name}.py: unnamed numbers at lines {v.found}"


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_comment_names_a_benchmark_cloud(path):
    # Comments explain the geometry; a cloud's name in the code is a rule fitted to one file.
    import re

    names = [m.group(0) for m in re.finditer(r"\bPC\d+\b(?!_primitives)", path.read_text())]
    assert not names


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_kd_tree_query_on_scipys_own_threads(path):
    # scipy's query threads outlive a Ctrl-C that cuts their join short, and the interpreter then
    # exits under them (a segmentation fault): threaded queries go through normals.tree_query.
    calls = [node.lineno for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
             and node.func.attr.startswith("query") and any(k.arg == "workers" for k in node.keywords)]
    assert not calls, f"{path.name}: KD-tree queries with workers= at lines {calls}"
