"""The tests' own layout: helpers are imported from tests/helpers, never from conftest.py or
from another test module (importing one runs its module-level code and its fixtures' imports,
and ties a fast tier to a slow one); tests/helpers holds no tests."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]


def _imported(path: Path) -> list[str]:
    """Every module ``path`` imports (``from tests.x import y`` -> ``tests.x``, and
    ``tests.x.y`` too when y is a module)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.append(node.module)
            out += [f"{node.module}.{a.name}" for a in node.names]
    return out


def bad_imports(root: Path = TESTS) -> list[str]:
    """``file: module`` for every import of conftest or of a test module under ``root``."""
    bad = []
    for path in sorted(root.rglob("*.py")):
        for mod in _imported(path):
            last = mod.rsplit(".", 1)[-1]
            if last == "conftest" or (mod.startswith("tests.") and last.startswith("test_")):
                bad.append(f"{path.relative_to(root)}: {mod}")
    return bad


def test_no_test_imports_conftest_or_another_test_module():
    assert bad_imports() == []


def test_helpers_hold_no_tests():
    for path in (TESTS / "helpers").rglob("*.py"):
        assert not path.name.startswith("test_"), path
        tree = ast.parse(path.read_text(encoding="utf-8"))
        assert not [n.name for n in tree.body if isinstance(n, ast.FunctionDef)
                    and n.name.startswith("test_")], path


def test_the_check_sees_both_kinds(tmp_path):
    (tmp_path / "test_a.py").write_text("from tests.conftest import run_rows\n"
                                        "from tests.system.test_linear_reference import x\n"
                                        "from tests.helpers.batch import run_rows\n")
    assert bad_imports(tmp_path) == ["test_a.py: tests.conftest",
                                     "test_a.py: tests.system.test_linear_reference"]
