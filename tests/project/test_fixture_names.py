"""No two fixtures of the test tree share a name.

A module's fixture of the same name as a conftest's silently shadows it for that
module only: a test reads "tiny_patches" and gets another dataset than its
neighbours. Fixtures are found with ``ast`` (a function decorated with
``pytest.fixture`` or ``fixture``, called or not, or named by ``name=``).
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]


def _is_fixture(decorator: ast.expr) -> bool:
    target = decorator.func if isinstance(decorator, ast.Call) else decorator
    if isinstance(target, ast.Attribute):
        return target.attr == "fixture"
    return isinstance(target, ast.Name) and target.id == "fixture"


def _fixture_name(node: ast.FunctionDef, decorator: ast.expr) -> str:
    if isinstance(decorator, ast.Call):
        for kw in decorator.keywords:
            if kw.arg == "name" and isinstance(kw.value, ast.Constant):
                return str(kw.value.value)
    return node.name


def fixtures(source: str) -> list[tuple[str, int]]:
    """``(name, line)`` of every fixture a module's source defines, at any depth."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            found += [
                (_fixture_name(node, d), node.lineno) for d in node.decorator_list if _is_fixture(d)
            ]
    return found


def test_the_finder_sees_every_spelling_of_a_fixture():
    source = (
        "import pytest\nfrom pytest import fixture\n"
        "@pytest.fixture\ndef a(): ...\n"
        "@pytest.fixture(scope='session')\ndef b(): ...\n"
        "@fixture\ndef c(): ...\n"
        "@pytest.fixture(name='d')\ndef _d(): ...\n"
        "class TestX:\n    @pytest.fixture\n    def e(self): ...\n"
        "def helper(): ...\n"
    )
    assert sorted(name for name, _ in fixtures(source)) == ["a", "b", "c", "d", "e"]


def test_no_two_fixtures_of_the_test_tree_share_a_name():
    where = defaultdict(list)
    for path in sorted(TESTS.rglob("*.py")):
        if path.name == "conftest.py" or path.name.startswith("test_"):
            for name, line in fixtures(path.read_text(encoding="utf-8")):
                where[name].append(f"{path.relative_to(TESTS)}:{line}")
    shared = {name: places for name, places in where.items() if len(places) > 1}
    assert not shared, f"fixtures defined more than once: {shared}"
