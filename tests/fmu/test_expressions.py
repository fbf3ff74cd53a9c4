"""User expressions: the same tree on NumPy and CasADi, and one-line refusals."""

import casadi as ca
import numpy as np
import pytest

from flexff.fmu.expressions import ExpressionError, evaluate, parse_expression, to_casadi


def test_numpy_and_casadi_give_the_same_values():
    expression = parse_expression("gain * plant.vir - 0.5 * sin(2 * pi * x / 0.016) ** 2", "k")
    assert expression.names == {"gain", "plant.vir", "x"}
    x = np.linspace(-0.02, 0.02, 7)
    values = {"gain": 2.5, "plant.vir": np.cos(x), "x": x}
    by_numpy = evaluate(expression, values, "k")
    symbols = {name: ca.SX.sym(name.replace(".", "_")) for name in ("gain", "plant.vir", "x")}
    function = ca.Function("f", list(symbols.values()), [to_casadi(expression, symbols, "k")])
    by_casadi = np.array([float(function(2.5, np.cos(v), v)) for v in x])
    np.testing.assert_allclose(by_numpy, by_casadi, rtol=1e-14)
    expected = 2.5 * np.cos(x) - 0.5 * np.sin(2 * np.pi * x / 0.016) ** 2
    np.testing.assert_allclose(by_numpy, expected, rtol=1e-14)


def test_functions_of_two_arguments_and_unary_minus():
    expression = parse_expression("-atan2(y, x) + max(x, y) + abs(-x)", "k")
    assert evaluate(expression, {"x": 1.0, "y": 1.0}, "k") == pytest.approx(-np.pi / 4 + 2.0)


@pytest.mark.parametrize("text, words", [
    ("__import__('os')", "calls __import__()"),
    ("x if y else z", "an expression may use"),
    ("x[i]", "no FMI array element .*whole numbers"),
    ("x[1 + 1]", "no FMI array element"),
    ("lambda: 1", "an expression may use"),
    ("1 +", "is not an expression"),
    ("", "non-empty string"),
    ('"a"', "a quoted text, not a name .*plant.'a b'"),
    ("'a", "is not an expression .*FMI names such as `plant.pos\\[1\\]`"),
])
def test_anything_but_arithmetic_is_refused_naming_the_key(text, words):
    with pytest.raises(ExpressionError, match=rf"^machine\.axis\[0\]\.measured: .*{words}"):
        parse_expression(text, "machine.axis[0].measured")


def test_a_missing_name_is_named():
    expression = parse_expression("gain * vir", "columns.F")
    with pytest.raises(ExpressionError, match=r"columns\.F: .* names gain, which is not among vir"):
        evaluate(expression, {"vir": np.zeros(3)}, "columns.F")


@pytest.mark.parametrize("text, names", [
    ("plant.pos[1]", {"plant.pos[1]"}),
    ("plant.a.b[2,3] - plant.c.d", {"plant.a.b[2,3]", "plant.c.d"}),
    ("plant.der(x) * 2e-3", {"plant.der(x)"}),
    ("plant.der(body.v[2],2) + 1.5E+2", {"plant.der(body.v[2],2)"}),
    ("plant.'my var' / .5", {"plant.'my var'"}),
    ("'tip speed'", {"'tip speed'"}),
    ("sin(plant.pos[1]) + der(q)", {"plant.pos[1]", "der(q)"}),
])
def test_fmi_structured_names_are_single_names(text, names):
    """FMI array elements, derivatives and quoted names (spec 2.2.9) stand as one name each,
    on NumPy and on CasADi alike."""
    expression = parse_expression(text, "k")
    assert expression.names == names
    values = {name: 0.25 * (k + 1) for k, name in enumerate(sorted(names))}
    by_numpy = evaluate(expression, values, "k")
    symbols = {name: ca.SX.sym(f"s{k}") for k, name in enumerate(sorted(names))}
    function = ca.Function("f", list(symbols.values()), [to_casadi(expression, symbols, "k")])
    assert float(function(*[values[n] for n in sorted(names)])) == pytest.approx(by_numpy)
