"""The one PID block (blocks.pid) under its two built-in names: "pid-gains" is
"pid" in the parallel form, axis tables are the per-axis options by name, and the options the
forms cannot run are refused naming the key. Evaluated through CasADi (no FMU build)."""

import math

import casadi as ca
import numpy as np
import pytest

from flexff.blocks.filters import lowpass
from flexff.blocks.options import OptionError
from flexff.blocks.pid_options import pid_from_options, pid_gains_from_options
from flexff.cosim.builtins import registered

STEP = 1e-3
STAGE = {"axes": ["x", "y"], "crossover_hz": 20.0, "mass": {"x": 8.0, "y": 2.0},
         "notch_hz": {"y": 150.0}, "effort_limit": {"x": 200.0, "y": 80.0}}


def evaluate(system, inputs, steps=400, **parameters):
    """Outputs (steps x outputs) and states of `system` for constant `inputs`."""
    p = ca.DM([parameters.get(q.name, q.start) for q in system.parameters])
    x, w = system.initial_state(p), ca.DM.zeros(0)
    u = ca.DM([inputs.get(v.name, 0.0) for v in system.inputs])
    ys, xs = [], []
    for _ in range(steps):
        ys.append(np.array(system.output(x, u, p, w)).ravel())
        x = system.dynamics(x, u, p)
        xs.append(np.array(x).ravel())
    return np.array(ys), np.array(xs)


def same(a, b):
    """The two systems have the same signals and give bit-equal outputs."""
    assert [v.name for v in a.inputs] == [v.name for v in b.inputs]
    assert [v.name for v in a.outputs] == [v.name for v in b.outputs]
    assert [(q.name, q.start) for q in a.parameters] == [(q.name, q.start) for q in b.parameters]
    inputs = {"x_ref": 0.3, "y_ref": -0.1, "x_ff": 0.5}
    assert np.array_equal(evaluate(a, inputs)[0], evaluate(b, inputs)[0])


def test_pid_gains_is_the_pid_block_in_the_parallel_form():
    same(pid_gains_from_options(STAGE, STEP), pid_from_options({**STAGE, "form": "parallel"},
                                                               STEP))
    assert registered()["pid"].factory != registered()["pid-gains"].factory
    assert {o.key: o.default for o in registered()["pid-gains"].options}["form"] == "parallel"


def test_axis_tables_are_the_per_axis_options_by_name():
    tables = {"axes": [{"name": "x", "crossover_hz": 20.0, "mass": 8.0, "effort_limit": 200.0},
                       {"name": "y", "crossover_hz": 20.0, "mass": 2.0, "notch_hz": 150.0,
                        "effort_limit": 80.0}]}
    for read in (pid_from_options, pid_gains_from_options):
        same(read(tables, STEP), read(STAGE, STEP))


def test_series_form_scales_one_loop_shaped_controller_and_holds_it_at_the_limit():
    series = pid_from_options({"axes": ["x"], "crossover_hz": 20.0, "mass": 2.0,
                               "effort_limit": 50.0}, STEP)
    assert [q.name for q in series.parameters] == ["kp_x", "effort_limit_x"]
    y, x = evaluate(series, {"x_ref": 1.0}, 1500)
    assert np.max(y[:, 0]) == 50.0 and np.all(np.diff(x[-500:], axis=0) == 0.0)
    doubled, _ = evaluate(series, {"x_ref": 1e-6}, 50, kp_x=2.0)
    single, _ = evaluate(series, {"x_ref": 1e-6}, 50)
    np.testing.assert_allclose(doubled[:, 1], 2 * single[:, 1], rtol=1e-12)


def test_parallel_conditional_integration_holds_the_integral():
    """e = +1 saturates the effort at 2: the integral stops a step past where the limit was
    reached (kp e + I = 2, I = 1; ki step e = 0.1 a step) instead of winding up to ki t."""
    options = {"axes": ["x"], "kp": 1.0, "ki": 100.0, "effort_limit": 2.0,
               "anti_windup": "conditional"}
    system = pid_gains_from_options(options, STEP)
    assert "tracking_gain_x" not in {q.name for q in system.parameters}
    y, states = evaluate(system, {"x_ref": 1.0}, 1000)
    assert np.max(y[:, 0]) == 2.0
    assert np.all(states[-900:, 0] == states[-1, 0]) and 1.0 < states[-1, 0] <= 1.1 + 1e-12


@pytest.mark.parametrize(("order", "low", "high"), [(1, 0.05, 0.1), (2, 0.005, 0.01)])
def test_lowpass_orders_fall_off_above_the_corner(order, low, high):
    """1 / sqrt(2) at the corner (prewarped), a decade above -20 or -40 dB (a little more:
    Tustin's zero at Nyquist)."""
    hz = 20.0
    response = lowpass(hz, STEP, order).response(2 * math.pi * np.array([hz, 10 * hz]))
    assert abs(response[0]) == pytest.approx(1 / math.sqrt(2), rel=1e-9)
    assert low < abs(response[1]) < high


@pytest.mark.parametrize(("read", "options", "key"), [
    (pid_from_options, {"axes": ["x"], "kp": 1.0}, "'form'"),
    (pid_from_options, {"axes": ["x"], "crossover_hz": 20.0, "mass": 2.0, "effort_limit": 5.0,
                        "anti_windup": "clamp"}, "'anti_windup'"),
    (pid_gains_from_options, {"axes": ["x"], "kp": 1.0, "effort_limit": 5.0,
                              "anti_windup": "clamp", "tracking_gain": 3.0}, "'tracking_gain'"),
    (pid_gains_from_options, {"axes": ["x"], "kp": 1.0, "lowpass_hz": 50.0, "lowpass_order": 1,
                              "lowpass_zeta": 0.5}, "'lowpass_zeta'"),
    (pid_gains_from_options, {"axes": ["x"], "kp": 1.0, "lowpass_order": 3}, "'lowpass_order'"),
    (pid_from_options, {"axes": ["x"], "crossover_hz": 20.0, "mass": 2.0, "form": "ideal"},
     "'form'"),
    (pid_from_options, {"axes": [{"name": "x", "mass": 2.0, "crossover_hz": 9.0, "speed": 1}]},
     r"axes\[0\]\.speed"),
    (pid_from_options, {"axes": [{"name": "x", "mass": 2.0, "crossover_hz": 9.0}],
                        "mass": 3.0}, "'mass'"),
    (pid_from_options, {"axes": [{"name": "x", "mass": 2.0, "crossover_hz": 9.0}, "y"]},
     "'axes'"),
    (pid_from_options, {"axes": [{"name": "x", "mass": -2.0, "crossover_hz": 9.0}]}, "'mass.x'"),
])
def test_options_the_forms_cannot_run_name_the_key(read, options, key):
    with pytest.raises(OptionError, match=key):
        read(options, STEP)


def test_pid_takes_explicit_gains_in_the_parallel_form():
    system = pid_from_options({"axes": ["x"], "kp": 2.0, "form": "parallel"}, STEP)
    y, _ = evaluate(system, {"x_ref": 0.5}, 3)
    np.testing.assert_array_equal(y[:, 1], 1.0)
