"""The import contract, read from the source with `ast`: which package may import which (the
layer order of DESIGN.md, drawn in docs/explanation/architecture.md), cosim never imports
torch, and no import cycle between files. Every import counts, also one inside a function or
under TYPE_CHECKING; cycles count the imports run when a module loads. Each offence is named
as file:line, importer -> imported."""

import ast
import os
import re
from dataclasses import dataclass
from functools import cache
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

import pytest

from tests.helpers import REPOSITORY

ROOT = REPOSITORY / "flexff"
TOP = "flexff"  # the command line, flexff.api and the benches: may import every package
# package -> the packages it may import, lowest first (DESIGN.md: no floor imports one above
# it; cosim and learning import neither the manipulator, plant and controllers, nor its
# controllers; the generic blocks know no machine; a machine reaches the floors only as a
# user's machine does)
ALLOWED = {
    "fmu": (),
    "cosim": ("fmu",),
    "blocks": ("fmu", "cosim"),
    "learning": ("fmu", "cosim", "blocks"),
    "plant": ("fmu", "cosim"),
    "machines": ("fmu", "cosim", "blocks", "learning"),
    "controllers": ("fmu", "cosim", "blocks", "learning", "plant"),
}
# arrows against the order that the code still has (issue 59: the manipulator's collection,
# features and labels inside learning); each must still occur, so the list only shrinks
KNOWN_AGAINST_ORDER = {("learning", "plant"), ("learning", "controllers")}
NEVER = {"cosim": ("torch",)}  # third-party packages a package must not import, in any way


@dataclass(frozen=True)
class Import:
    """One import statement's target as found in module `source` at `path`:`line`; `when`:
    "load" (runs when the module loads), "call" (inside a function) or "typing" (under
    TYPE_CHECKING)."""

    source: str
    target: str
    path: Path
    line: int
    when: str

    def __str__(self) -> str:
        where = self.path.resolve().relative_to(REPOSITORY).as_posix()
        kind = "" if self.when == "load" else f" ({self.when})"
        return f"{where}:{self.line}{kind}: {self.source} -> {self.target}"


def module_files() -> dict[str, Path]:
    """Every module of every flexff package by dotted name: flexff/ and the folders its
    links (or subpackages) point to, each file once."""
    found: dict[str, Path] = {}
    for folder, subfolders, files in os.walk(ROOT, followlinks=True):
        subfolders[:] = sorted(s for s in subfolders if s != "__pycache__")
        parts = Path(folder).relative_to(ROOT).parts
        for name in sorted(f for f in files if f.endswith(".py")):
            stem = name.removesuffix(".py")
            found[".".join((TOP, *parts, *(() if stem == "__init__" else (stem,))))] = \
                Path(folder) / name
    return found


def package(module: str) -> str:
    """The layer of a dotted module name: its floor, or TOP for the rest of flexff."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in ALLOWED else TOP


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _statements(body: list[ast.stmt], when: str):
    """(import statement, when) for every import under `body`, however deeply nested."""
    for node in body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node, when
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield from _statements(node.body, "call")
        elif isinstance(node, ast.If) and _is_type_checking(node.test):
            yield from _statements(node.body, "typing")
            yield from _statements(node.orelse, when)
        else:
            for field in ("body", "orelse", "finalbody", "handlers", "cases"):
                children = getattr(node, field, None)
                if isinstance(children, list):
                    yield from _statements(children, when)


def _targets(node: ast.Import | ast.ImportFrom, source: str, is_package: bool,
             modules: dict[str, Path]) -> list[str]:
    """The dotted names `node` imports in module `source`: a relative import resolved, and
    `from package import name` the submodule `name` where there is one."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        anchor = source.split(".")[: len(source.split(".")) - node.level + is_package]
        base = ".".join(anchor + ([base] if base else []))
    names = [f"{base}.{alias.name}" for alias in node.names]
    submodules = [name for name in names if name in modules]
    return submodules + ([base] if len(submodules) < len(names) else [])


@cache
def imports() -> tuple[Import, ...]:
    """Every import of every flexff module."""
    modules = module_files()
    found = []
    for source, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        for node, when in _statements(tree.body, "load"):
            for target in _targets(node, source, path.name == "__init__.py", modules):
                found.append(Import(source, target, path, node.lineno, when))
    return tuple(found)


def against_order(found: tuple[Import, ...]) -> list[Import]:
    """The imports of a flexff package that ALLOWED does not let it make."""
    return [i for i in found if i.target.split(".")[0] == TOP
            and package(i.source) != TOP and package(i.target) != package(i.source)
            and package(i.target) not in ALLOWED[package(i.source)]
            and (package(i.source), package(i.target)) not in KNOWN_AGAINST_ORDER]


def forbidden(found: tuple[Import, ...]) -> list[Import]:
    """Imports of what NEVER names."""
    return [i for i in found if i.target.split(".")[0] in NEVER.get(package(i.source), ())]


def file_cycles(found: tuple[Import, ...]) -> list[list[Import]]:
    """Each import cycle between files among the imports run at load, as its imports."""
    modules = module_files()
    edges: dict[str, dict[str, Import]] = {}
    for i in found:
        if i.when == "load" and i.target in modules and i.target != i.source:
            edges.setdefault(i.source, {}).setdefault(i.target, i)
    cycles, seen = [], set()
    while True:
        graph = {m: set(targets) - seen for m, targets in edges.items() if m not in seen}
        try:
            tuple(TopologicalSorter(graph).static_order())
            return cycles
        except CycleError as error:
            loop = error.args[1]  # [a, b, ..., a], each importing the one before it
            cycles.append([edges[loop[k + 1]][loop[k]] for k in range(len(loop) - 1)])
            seen.add(loop[0])


def test_the_walk_finds_every_package_and_the_command_line():
    found = {package(name) for name in module_files()}
    assert found == {*ALLOWED, TOP}
    assert {"flexff.cosim.master", "flexff.blocks.pid", "flexff.api"} <= set(module_files())


def test_the_layer_order_has_no_cycle():
    tuple(TopologicalSorter({k: set(v) for k, v in ALLOWED.items()}).static_order())


def test_no_package_imports_one_it_may_not():
    offences = against_order(imports())
    assert not offences, "imports against the layer order:\n" + "\n".join(map(str, offences))


def test_each_known_arrow_against_the_order_still_occurs():
    arrows = {(package(i.source), package(i.target)) for i in imports()}
    assert arrows >= KNOWN_AGAINST_ORDER, "gone, so leave it out of KNOWN_AGAINST_ORDER: " + \
        str(KNOWN_AGAINST_ORDER - arrows)


def test_cosim_never_imports_torch():
    offences = forbidden(imports())
    assert not offences, "forbidden imports:\n" + "\n".join(map(str, offences))


def test_no_import_cycle_between_files():
    cycles = file_cycles(imports())
    assert not cycles, "import cycles:\n" + "\n\n".join(
        "\n".join(map(str, cycle)) for cycle in cycles)


def test_the_architecture_page_draws_the_order():
    """Its table "may import" row per package matches ALLOWED."""
    page = (REPOSITORY / "docs" / "explanation" / "architecture.md").read_text()
    rows = dict(re.findall(r"^\| `(\w+)/` \|.*\| ([^|\n]*) \|$", page, re.MULTILINE))
    drawn = {name: tuple(re.findall(r"`(\w+)`", imported)) for name, imported in rows.items()}
    assert drawn == ALLOWED


# the checks must be able to fail: each fed one offending import


def _fake(source: str, target: str, when: str = "load") -> Import:
    return Import(source, target, REPOSITORY / "x.py", 1, when)


@pytest.mark.parametrize("source, target", [
    ("flexff.cosim.run", "flexff.plant.signals"),
    ("flexff.blocks.pid", "flexff.controllers.feedback"),
    ("flexff.fmu.build", "flexff.cosim.master"),
    ("flexff.machines.drive", "flexff.plant.model"),
])
def test_an_import_against_the_order_is_named(source, target):
    [offence] = against_order((_fake(source, target, "call"),))
    assert str(offence) == f"x.py:1 (call): {source} -> {target}"


def test_torch_in_cosim_is_named_even_under_type_checking():
    assert len(forbidden((_fake("flexff.cosim.run", "torch.nn", "typing"),
                          _fake("flexff.learning.train", "torch")))) == 1


def test_a_cycle_is_named_by_its_imports():
    pair = (_fake("flexff.fmu.build", "flexff.fmu.cache"),
            _fake("flexff.fmu.cache", "flexff.fmu.build"))
    assert [sorted(map(str, c)) for c in file_cycles(pair)] == [sorted(map(str, pair))]
    assert file_cycles((pair[0], _fake("flexff.fmu.cache", "flexff.fmu.build", "call"))) == []


def test_relative_imports_resolve():
    tree = ast.parse("from . import options\nfrom .pid import x\nfrom .. import fmu\n")
    modules = {"flexff.blocks.options": Path(), "flexff.blocks.pid": Path(),
               "flexff.fmu": Path()}
    targets = [_targets(node, "flexff.blocks.sum_gain", False, modules) for node in tree.body]
    assert targets == [["flexff.blocks.options"], ["flexff.blocks.pid"], ["flexff.fmu"]]
