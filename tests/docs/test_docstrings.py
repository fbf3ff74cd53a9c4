"""Every module of the package has a docstring of at most 15 lines: what the module is for and
which docs page holds the detail (issue 42). The detail lives in docs/, not in the code."""

import ast

from tests.helpers import REPOSITORY

MAX_LINES = 15


def _modules():
    yield from sorted((REPOSITORY / "flexff").rglob("*.py"))


def test_the_walk_finds_the_package():
    names = {p.relative_to(REPOSITORY).as_posix() for p in _modules()}
    assert {"flexff/cosim/master.py", "flexff/learning/evaluate.py", "flexff/cli/__init__.py",
            "flexff/machines/__init__.py"} <= names


def test_every_module_docstring_is_present_and_short():
    missing, long = [], []
    for path in _modules():
        name = path.relative_to(REPOSITORY).as_posix()
        docstring = ast.get_docstring(ast.parse(path.read_text(), filename=name))
        if not docstring:
            missing.append(name)
        elif len(docstring.splitlines()) > MAX_LINES:
            long.append(f"{name}: {len(docstring.splitlines())} lines")
    assert not missing, "modules without a docstring: " + ", ".join(missing)
    assert not long, f"module docstrings over {MAX_LINES} lines: " + ", ".join(long)
