"""Faults of an FMU's model description, in two classes, decided in one list (RULES).

*Fatal* faults would make a run's record or wiring wrong: a run stops before it starts. The
*warnings* are faults that change nothing at run time: the FMU runs as FMPy, libcosim and Ecos
run it, and the run says so once (`strict = true` on an `[fmu.NAME]`, or `flexff run
--strict`, refuses them too). Many exporters write such descriptions (an empty or partial
`<InitialUnknowns>`, an Enumeration declared continuous, an input without a start value).

The faults are fmpy's checks (the XML schema, then `fmpy.validation`: names, model structure,
start values, causality and variability, units), each classified by its text, and flexff's own
checks of what it relies on: unique names, and value references that address one variable of
one type. A fault of fmpy's that no rule knows is a warning: flexff reads what it needs itself.

Docs: "Validate and compare third-party FMUs" (docs/how-to/validate-compare.md).
"""

from __future__ import annotations

import functools
import re
import warnings
import zipfile
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import fmpy
import fmpy.validation
from lxml import etree

VALUE_REFERENCES = 2**32  # fmi2ValueReference and fmi3ValueReference: unsigned 32-bit


class DescriptionWarning(UserWarning):
    """An FMU that runs although its description has faults (the warnings), said once."""


@dataclass(frozen=True)
class Rule:
    """One class of fault: what it is, whether it stops a run, and why."""

    name: str
    fatal: bool
    why: str
    pattern: re.Pattern[str] | None = None  # fmpy's text it classifies; None: flexff's check


@dataclass(frozen=True)
class Fault:
    """One fault found in a description: its sentence and the rule it falls under."""

    text: str
    rule: Rule

    @property
    def fatal(self) -> bool:
        return self.rule.fatal

    def __str__(self) -> str:
        return f"{self.text.rstrip('.')}: {self.rule.why}"


def _fmpy(name: str, pattern: str, why: str) -> Rule:
    """A warning that classifies fmpy's problems matching `pattern`."""
    return Rule(name, False, why, re.compile(pattern))


DUPLICATE_NAME = Rule(
    "duplicate name", True,
    "two variables share this name, so its values would be set, connected and recorded under "
    "the other's")
REFERENCE_RANGE = Rule(
    "value reference out of range", True,
    "a value reference is an unsigned 32-bit integer: no FMI call can address this variable")
REFERENCE_TYPES = Rule(
    "value reference shared across types", True,
    "in FMI 3.0 a value reference names one variable: a get or set of one type would read or "
    "write the other's value as the wrong type")
REFERENCE_ALIAS = Rule(
    "undeclared alias", False,
    "both variables read and write one value, as an alias does; flexff records each under its "
    "own name")
SCHEMA = _fmpy(
    "XML schema", r"^(ERROR|WARNING|FATAL)\b.*\(line \d+, column \d+\)",
    "flexff reads the description with fmpy's parser, which takes what a run needs, and checks "
    "that itself (names, value references, causalities)")

RULES: tuple[Rule, ...] = (
    DUPLICATE_NAME, REFERENCE_RANGE, REFERENCE_TYPES, REFERENCE_ALIAS, SCHEMA,
    _fmpy("variability of a non-real", r'must have variability != "continuous"',
          "the variability is a hint to the importer: flexff exchanges the value at every "
          "communication step whatever it says"),
    _fmpy("missing start value", r"has no start value",
          "flexff sets only the start values a configuration gives; otherwise the FMU keeps "
          "its own initial value, as in FMPy"),
    _fmpy("causality and variability", r"The combination causality=.* is not allowed",
          "flexff takes the causality alone to decide what it sets, connects and records"),
    _fmpy("start of a calculated variable",
          r'(initial="calculated"|causality="independent") but provides a start value',
          "flexff never sets the start value of a calculated or independent variable"),
    _fmpy("undefined unit", r"unit .* is not defined",
          "a unit is a label in the record; flexff converts no units"),
    _fmpy("independent variable", r"Exactly one independent variable",
          "flexff passes the time in the FMI calls, not through the independent variable"),
    _fmpy("dependency kinds", r"dependenciesKind",
          "flexff reads the dependencies, not their kinds"),
    _fmpy("outputs list", r"ModelStructure/Outputs must have exactly one entry",
          "an output without an entry is taken to depend on every input (a continuous state "
          "on none), as the standard says: at worst an ordering is refused as an algebraic "
          "loop (feedthrough = false declares none), never run wrongly"),
    _fmpy("initial unknowns", r"ModelStructure/InitialUnknowns",
          "flexff reads no initial unknown: it reads the outputs it needs after initialization"),
    _fmpy("state derivative", r"continuous state derivative",
          "flexff's model-exchange solver counts the states from the ModelStructure's "
          "derivatives; co-simulation does not read them"),
    _fmpy("variable name", r"(is not a legal variable name|contains an illegal)",
          "the naming convention is a hint; flexff records the name as written"),
    _fmpy("file path", r"contains a backslash",
          "flexff unpacks each member under its name as written; a binary it then misses is "
          "an error when the FMU is loaded"),
)
UNKNOWN = Rule("other", False, "a fault of fmpy's that is not known to change a run")
OWN_CHECKS = re.compile(r"is not unique|has the same value reference as")  # fmpy's twins


def _classified(problem: str) -> Fault | None:
    """fmpy's `problem` as a Fault under the first rule whose pattern it matches (UNKNOWN
    where none does); None where flexff's own checks make it, more precisely."""
    if OWN_CHECKS.search(problem):
        return None
    return Fault(problem, next((r for r in RULES if r.pattern and r.pattern.search(problem)),
                               UNKNOWN))


@functools.cache
def _schema(version: str) -> etree.XMLSchema:
    """fmpy's XML schema of FMI `version` ("2.0" or "3.0"), parsed once per process."""
    folder = Path(fmpy.__file__).parent / "schema" / f"fmi{version[0]}"
    return etree.XMLSchema(file=str(folder / f"fmi{version[0]}ModelDescription.xsd"))


def _schema_problems(path: Path, version: str) -> list[str]:
    with zipfile.ZipFile(path) as zf, zf.open("modelDescription.xml") as xml:
        root = etree.parse(xml).getroot()
    schema = _schema(version)
    if schema.validate(root):
        return []
    return [f"{e.level_name} (line {e.line}, column {e.column}): {e.message}"
            for e in schema.error_log]


def _fmpy_problems(path: Path, md: Any) -> list[str]:
    """Every problem fmpy's validation lists (fmpy.validation.validate_fmu's, all of them: it
    stops at the schema's), as its sentences."""
    with zipfile.ZipFile(path) as zf:
        problems = [f'The file path "{m.orig_filename}" contains a backslash.'
                    for m in zf.filelist if "\\" in m.orig_filename]
    problems += _schema_problems(path, md.fmiVersion)
    try:
        problems += fmpy.validation.validate_model_description(
            md, validate_variable_names=True, validate_model_structure=True)
    except Exception as error:  # fmpy's checks stop on some faults (a display unit of none)
        problems.append(f"fmpy's checks stopped: {error}")
    return problems


def _own_faults(md: Any) -> list[Fault]:
    """flexff's checks of what a run relies on: unique names, value references in range and,
    in FMI 3.0, each naming variables of one type."""
    faults = []
    variables = [v for v in md.modelVariables if not getattr(v, "alias", None)]
    for name, count in Counter(v.name for v in md.modelVariables).items():
        if count > 1:
            faults.append(Fault(f'the variable name "{name}" is given {count} times',
                                DUPLICATE_NAME))
    faults += [Fault(f'the variable "{v.name}" has the value reference {v.valueReference}',
                     REFERENCE_RANGE)
               for v in variables if not 0 <= int(v.valueReference) < VALUE_REFERENCES]
    if md.fmiVersion == "2.0":  # each base type has value references of its own (FMI 2.0)
        return faults
    shared: defaultdict[int, list[Any]] = defaultdict(list)
    for v in variables:
        shared[int(v.valueReference)].append(v)
    for vr, group in shared.items():
        if len(group) > 1:
            names = ", ".join(f'"{v.name}" ({v.type})' for v in group)
            rule = REFERENCE_TYPES if len({v.type for v in group}) > 1 else REFERENCE_ALIAS
            faults.append(Fault(f"the variables {names} share the value reference {vr}", rule))
    return faults


def description_faults(path: Path, md: Any) -> list[Fault]:
    """Every fault of the description `md` read (unvalidated) from the FMU at `path`: the
    fatal ones first, each class in the order found."""
    faults = _own_faults(md) + [f for p in _fmpy_problems(path, md)
                                if (f := _classified(p)) is not None]
    return sorted(faults, key=lambda f: not f.fatal)


def summary(faults: Sequence[Fault]) -> str:
    """The first fault and how many more, for one line."""
    more = f" (and {len(faults) - 1} more)" if len(faults) > 1 else ""
    return f"{faults[0]}{more}"


def warn(where: str, path: Path, faults: Sequence[Fault]) -> None:
    """Say once that the FMU at `path` (`where`: its table) runs despite `faults`, if any."""
    if faults:
        warnings.warn(DescriptionWarning(
            f"{where}: {path.name}: its model description has faults that change no run, "
            f"so it runs as FMPy runs it: {summary(faults)}; strict = true refuses it, flexff "
            f"fmu validate lists every fault"), stacklevel=3)
