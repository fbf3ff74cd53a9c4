"""The generic floors name no machine (DESIGN.md): no code of fmu/ and cosim/ names the
manipulator, its workspace or one of its signals (plant.signals). Read with `ast`: identifiers
and string constants count, docstrings and comments do not (one may name the manipulator as an
example); libcosimpy's own CosimManipulator (its API's word for an override) is no offence."""

import ast
import re
from pathlib import Path

from flexff.plant import signals
from tests.helpers import REPOSITORY

FLOORS = ("fmu", "cosim")
WORDS = ("manipulator", "workspace")  # within identifiers and strings, any case
LIBCOSIM_API = {"CosimManipulator", "add_manipulator"}
# the manipulator's signals, but the one- and two-letter ones (x, vx, i1, Fx) that any
# machine or a CasADi symbol may be called
SIGNALS = {v.name for group in vars(signals).values()
           if isinstance(group, tuple) and group and isinstance(group[0], signals.Variable)
           for v in group if len(v.name) > 2}


def _docstrings(tree: ast.Module) -> set[int]:
    """The ids of the docstring constants of the module, its classes and functions."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) \
                and node.body and isinstance(node.body[0], ast.Expr) \
                and isinstance(node.body[0].value, ast.Constant):
            found.add(id(node.body[0].value))
    return found


def _words(node: ast.AST) -> list[str]:
    """The identifiers and string pieces `node` names itself."""
    if isinstance(node, ast.Name):
        return [node.id]
    if isinstance(node, ast.Attribute):
        return [node.attr]
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
        return [node.name]
    if isinstance(node, ast.arg):
        return [node.arg]
    if isinstance(node, ast.alias):
        return [node.asname or node.name]
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return re.findall(r"\w+", node.value)
    return []


def offences(source: str, where: str) -> list[str]:
    """`where:line: word` for each identifier or string piece of `source` (not a docstring)
    that names the manipulator, its workspace or one of its signals."""
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if id(node) in docstrings:
            continue
        for word in _words(node):
            if word in SIGNALS or (word not in LIBCOSIM_API
                                   and any(w in word.lower() for w in WORDS)):
                found.append(f"{where}:{getattr(node, 'lineno', '?')}: {word}")
    return found


def test_the_signals_to_look_for_are_the_manipulators():
    assert {"x_ref", "ay_ref", "theta_s1", "Fx_ff", "tau3"} <= SIGNALS
    assert not {"x", "vx", "i1"} & SIGNALS


def test_fmu_and_cosim_name_no_manipulator():
    found = []
    for floor in FLOORS:
        for path in sorted((REPOSITORY / "flexff" / floor).rglob("*.py")):
            found += offences(path.read_text(), str(Path(path).relative_to(REPOSITORY)))
    assert not found, "the generic floors name the manipulator:\n" + "\n".join(found)


def test_the_check_finds_each_kind_of_offence():
    source = '''"""A docstring may say manipulator and x_ref."""
# a comment may say theta_s1
REFERENCE = ("x_ref", "y_ref")
def check_workspace(x): return x
manipulator_axes = 2
observer = CosimManipulator.create_override()
'''
    words = [line.rpartition(": ")[2] for line in offences(source, "f.py")]
    assert sorted(words) == ["check_workspace", "manipulator_axes", "x_ref", "y_ref"]
