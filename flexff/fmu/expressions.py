"""Arithmetic expressions written by users (a kinematic map, a log's column `gain * vir`, an
identification term `sin(2*pi*x/0.016)`), read once and evaluated on numbers or CasADi symbols.

Python's own parser reads the text; only numbers, names (dotted ones such as `plant.theta`
are one name), + - * / **, unary minus and the functions of FUNCTIONS pass: nothing is
executed. A name may be an FMI structured name, which Python would not read as one (`a[1]`,
`b.c[2,3]`, `der(x)`, `'my var'`, after an instance: `plant.pos[1]`): such names are read
first (FMI_NAME) and stand in the tree as single names. The same tree evaluates on NumPy
arrays (`evaluate`) and on CasADi symbols (`to_casadi`), so a term that is fitted offline is
the term a generated FMU computes.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexff.fmu.errors import InputError

# name -> (NumPy function, CasADi method name); CasADi's are looked up on first use
FUNCTIONS: dict[str, tuple[Callable[..., Any], str]] = {
    "sin": (np.sin, "sin"), "cos": (np.cos, "cos"), "tan": (np.tan, "tan"),
    "asin": (np.arcsin, "asin"), "acos": (np.arccos, "acos"), "atan": (np.arctan, "atan"),
    "atan2": (np.arctan2, "atan2"), "sinh": (np.sinh, "sinh"), "cosh": (np.cosh, "cosh"),
    "tanh": (np.tanh, "tanh"), "exp": (np.exp, "exp"), "log": (np.log, "log"),
    "sqrt": (np.sqrt, "sqrt"), "abs": (np.abs, "fabs"), "sign": (np.sign, "sign"),
    "min": (np.minimum, "fmin"), "max": (np.maximum, "fmax"),
}
CONSTANTS = {"pi": math.pi}
_OPERATORS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b,
}


# FMI 2.0/3.0 structured names (specification 2.2.9): identifiers or 'quoted' parts with
# integer array indices, joined by dots; der(name) or der(name, order) as a part
_INDEX = r"\[\d+(?:,\d+)*\]"
_PART = rf"(?:[A-Za-z_][A-Za-z0-9_]*|'(?:[^'\\]|\\.)+')(?:{_INDEX})*"
_SEGMENT = rf"(?:der\({_PART}(?:\.{_PART})*(?:,\d+)?\)|{_PART})"
FMI_NAME = re.compile(rf"{_SEGMENT}(?:\.{_SEGMENT})*")
_PYTHON_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*\Z")
_NUMBER = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_STAND_IN = "__fmi_name_{}__"
NAMES_HELP = ("names (a signal, `instance.variable`, FMI names such as `plant.pos[1]`, "
              "`plant.der(x)`, `plant.'my var'`)")


class ExpressionError(InputError):
    """An expression that cannot be read or names what is not there; names its key."""


@dataclass(frozen=True)
class Expression:
    """A checked expression: its text, its tree and the names it reads (FUNCTIONS and
    CONSTANTS excluded); equal where their texts are."""

    text: str
    tree: ast.expr = field(compare=False, repr=False)
    names: frozenset[str] = field(compare=False)


def parse_expression(text: str, key: str) -> Expression:
    """`text` read and checked; ExpressionError naming `key` for anything but arithmetic."""
    if not isinstance(text, str) or not text.strip():
        raise ExpressionError(f"{key}: expected an expression as a non-empty string, "
                              f"got {text!r}")
    source, stand_ins = _fmi_names(text.strip())
    try:
        tree = _NamesRestored(stand_ins).visit(ast.parse(source, mode="eval").body)
    except SyntaxError as error:
        raise ExpressionError(f"{key}: {text!r} is not an expression ({error.msg}); it may use "
                              f"numbers, {NAMES_HELP}, + - * / ** and functions") from None
    names: set[str] = set()
    _check(tree, text, key, names)
    return Expression(text.strip(), tree, frozenset(names))


def _fmi_names(text: str) -> tuple[str, dict[str, str]]:
    """`text` with every FMI name that Python would not read as a name replaced by a stand-in
    identifier, and the stand-ins' names."""
    out: list[str] = []
    stand_ins: dict[str, str] = {}
    at = 0
    while at < len(text):
        number = _NUMBER.match(text, at)
        token = number or (None if text[at].isspace() else FMI_NAME.match(text, at))
        if token is None:
            out.append(text[at])
            at += 1
            continue
        found = token.group()
        if number is None and not _PYTHON_NAME.match(found):
            stand_in = _STAND_IN.format(len(stand_ins))
            stand_ins[stand_in] = found
            found = stand_in
        out.append(found)
        at = token.end()
    return "".join(out), stand_ins


class _NamesRestored(ast.NodeTransformer):
    """The tree with each stand-in identifier named by the FMI name it stands for."""

    def __init__(self, stand_ins: Mapping[str, str]) -> None:
        self.stand_ins = stand_ins

    def visit_Name(self, node: ast.Name) -> ast.Name:
        return ast.Name(self.stand_ins.get(node.id, node.id), node.ctx)


def _check(node: ast.expr, text: str, key: str, names: set[str]) -> None:
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float) \
            and not isinstance(node.value, bool):
        return
    if isinstance(node, ast.Name | ast.Attribute):
        name = _dotted(node, text, key)
        if name not in CONSTANTS:
            names.add(name)
        return
    if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
        _check(node.left, text, key, names)
        _check(node.right, text, key, names)
        return
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        _check(node.operand, text, key, names)
        return
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
        if node.func.id not in FUNCTIONS:
            raise ExpressionError(f"{key}: {text!r} calls {node.func.id}(), which is not one "
                                  f"of {', '.join(sorted(FUNCTIONS))}")
        for argument in node.args:
            _check(argument, text, key, names)
        return
    raise ExpressionError(f"{key}: {text!r} holds {ast.unparse(node)!r}, {_why(node)}; an "
                          f"expression may use numbers, {NAMES_HELP}, + - * / ** and "
                          f"{', '.join(sorted(FUNCTIONS))}")


def _why(node: ast.expr) -> str:
    """Why `node` is no part of an expression, in the user's terms."""
    if isinstance(node, ast.Subscript):
        return ("which is no FMI array element (its indices are whole numbers, as in "
                "pos[1] or a[1,2], with no spaces)")
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return "a quoted text, not a name (an FMI quoted name follows its instance: plant.'a b')"
    if isinstance(node, ast.Call):
        return "a call with keywords or of no function by name"
    return "which is no number, name, operation or function"


def _dotted(node: ast.expr, text: str, key: str) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return f"{_dotted(node.value, text, key)}.{node.attr}"
    raise ExpressionError(f"{key}: {text!r}: {ast.unparse(node)!r} is not a name")


def evaluate(expression: Expression, values: Mapping[str, Any], key: str) -> Any:
    """The expression on numbers or NumPy arrays (broadcast as NumPy does)."""
    return _evaluate(expression, values, key, lambda name, args: FUNCTIONS[name][0](*args))


def to_casadi(expression: Expression, symbols: Mapping[str, Any], key: str) -> Any:
    """The expression on CasADi symbols (SX or MX)."""
    import casadi as ca

    def call(name: str, args: list[Any]) -> Any:
        return getattr(ca, FUNCTIONS[name][1])(*args)

    return _evaluate(expression, symbols, key, call)


def _evaluate(expression: Expression, values: Mapping[str, Any], key: str,
              call: Callable[[str, list[Any]], Any]) -> Any:
    missing = sorted(expression.names - set(values))
    if missing:
        raise ExpressionError(f"{key}: {expression.text!r} names {', '.join(missing)}, which "
                              f"is not among {', '.join(sorted(values)) or 'no names'}")
    scope = {**CONSTANTS, **values}

    def walk(node: ast.expr) -> Any:
        if isinstance(node, ast.Constant):
            return float(node.value)  # type: ignore[arg-type]  # a number: _check's
        if isinstance(node, ast.Name | ast.Attribute):
            return scope[_dotted(node, expression.text, key)]
        if isinstance(node, ast.BinOp):
            return _OPERATORS[type(node.op)](walk(node.left), walk(node.right))
        if isinstance(node, ast.UnaryOp):
            operand = walk(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)  # _check's
        return call(node.func.id, [walk(a) for a in node.args])

    return walk(expression.tree)
