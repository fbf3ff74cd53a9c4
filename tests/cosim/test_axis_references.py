"""Reference kinds for any number of axes (cosim.axis_references): each kind on 1, 3 and 5
axes in other units and rates stays within the description's limits, its derivatives agree
with its position, it starts where told; usable as a run's [reference] and refused by key."""

from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.axis_references import AXIS_KINDS, build_axis_reference
from flexff.cosim.config import parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import parse_machine
from flexff.cosim.run import simulate_config
from flexff.cosim.scenario import source_signals
from tests.learning.test_excitation import assert_integrates

AXES = [  # name, unit, range, velocity, acceleration, jerk
    ("x", "m", [-0.05, 0.05], 0.25, 2.5, None),
    ("q", "rad", [0.2, 1.0], 1.0, 20.0, 400.0),
    ("z", "mm", [0.0, 10.0], 20.0, 500.0, None),
    ("u", "m", [2.6, 3.4], 0.5, 3.0, 60.0),
    ("w", "deg", [-90.0, 90.0], 200.0, 4000.0, None),
]
RATES = {1: 1000.0, 3: 500.0, 5: 2000.0}
TOLERANCE = 1e-9  # relative, on the limits


def machine(count):
    axes = []
    for name, unit, span, velocity, acceleration, jerk in AXES[:count]:
        axes.append({"name": name, "unit": unit, "range": span, "velocity": velocity,
                     "acceleration": acceleration, **({"jerk": jerk} if jerk else {}),
                     "measured": f"p.{name}", "feedforward": f"c.{name}_ff",
                     "effort": f"c.{name}_u"})
    return parse_machine({"name": f"axes{count}", "axis": axes}, "m.toml")


def motion(reference, axis):
    return [reference.columns[n] for n in (axis.reference, *axis.derivatives)]


@pytest.mark.parametrize("kind", AXIS_KINDS)
@pytest.mark.parametrize("count", [1, 3, 5])
def test_each_kind_keeps_every_axis_within_its_limits_and_its_derivatives_agree(kind, count):
    described, rate = machine(count), RATES[count]
    share = 0.7
    reference = build_axis_reference(kind, {"duration": 6.0, "seed": count, "share": share},
                                     1 / rate, described)
    assert reference.duration == pytest.approx(6.0)
    assert set(reference.columns) == set(described.reference_signals)
    for axis in described.axes:
        x, v, a, j = motion(reference, axis)
        limits, where = axis.limits, f"{kind} {axis.name}"
        span = limits.high - limits.low
        assert limits.low - TOLERANCE * span <= x.min() and x.max() <= limits.high + \
            TOLERANCE * span, where
        assert np.abs(v).max() <= share * limits.velocity * (1 + TOLERANCE), where
        assert np.abs(a).max() <= share * limits.acceleration * (1 + TOLERANCE), where
        if limits.jerk is not None:
            assert np.abs(j).max() <= share * limits.jerk * (1 + TOLERANCE), where
        assert x[0] == pytest.approx(0.5 * (limits.low + limits.high)), where
        assert abs(v[0]) + abs(v[-1]) + abs(a[0]) + abs(a[-1]) <= 1e-9 * (
            limits.velocity + limits.acceleration), where  # at rest at both ends
        assert np.ptp(x) > 0.05 * span, where  # it moves
        step = 1 / rate
        np.testing.assert_allclose(np.gradient(x, step)[1:-1], v[1:-1],
                                   atol=1e-2 * np.abs(v).max(), err_msg=where)
        np.testing.assert_allclose(np.gradient(v, step)[1:-1], a[1:-1],
                                   atol=2e-2 * np.abs(a).max(), err_msg=where)
        assert_integrates(x, v, step, f"{where} velocity", np.abs(a).max())
        assert_integrates(v, a, step, f"{where} acceleration", np.abs(j).max())
        snap = np.abs(np.diff(j)).max() / step  # the jerk's own slope, where it turns
        assert_integrates(a, j, step, f"{where} jerk", snap)


@pytest.mark.parametrize("kind", AXIS_KINDS)
def test_a_start_off_the_centre_leads_there_smoothly(kind):
    """An axis resting at 2.9 in [2.6, 3.4] starts there, at rest, within its limits."""
    described = machine(4)
    reference = build_axis_reference(kind, {"duration": 5.0, "start": {"u": 2.9}},
                                     1e-3, described)
    x, v, a, j = motion(reference, described.axis("u"))
    assert x[0] == 2.9 and v[0] == 0.0 and a[0] == pytest.approx(0.0, abs=1e-12)
    assert np.abs(v).max() <= 0.8 * 0.5 * (1 + TOLERANCE)
    assert np.abs(a).max() <= 0.8 * 3.0 * (1 + TOLERANCE)
    assert np.abs(np.diff(x)).max() <= 0.5 * 1e-3  # no step
    assert_integrates(x, v, 1e-3, "velocity", np.abs(a).max())
    assert_integrates(v, a, 1e-3, "acceleration", np.abs(j).max())
    assert_integrates(a, j, 1e-3, "jerk", np.abs(np.diff(j)).max() / 1e-3)


def test_point_to_point_visits_the_given_points_and_the_seed_draws_the_rest():
    described = machine(3)
    reference = build_axis_reference("point-to-point", {
        "duration": 4.0, "points": {"x": [0.04, -0.03]}, "rest": 0.3}, 1e-3, described)
    x = reference.columns["x_ref"]
    held = x[np.flatnonzero(reference.columns["vx_ref"] == 0)]
    assert {0.0, 0.04, -0.03} <= set(np.round(held, 12)) and x[-1] == pytest.approx(-0.03)
    same = build_axis_reference("point-to-point", {"duration": 4.0, "seed": 3}, 1e-3,
                                described)
    again = build_axis_reference("point-to-point", {"duration": 4.0, "seed": 3}, 1e-3,
                                 described)
    other = build_axis_reference("point-to-point", {"duration": 4.0, "seed": 4}, 1e-3,
                                 described)
    np.testing.assert_array_equal(same.columns["q_ref"], again.columns["q_ref"])
    assert not np.array_equal(same.columns["q_ref"], other.columns["q_ref"])


def three_drives(reference):
    """Three drives under one PID, axes x, y, z, on the [reference] table `reference`."""
    axes = ("x", "y", "z")
    return parse_config({
        "run": {"step": 0.001},
        "reference": reference,
        "fmu": {"pid": {"builtin": "pid", "axes": [
            {"name": a, "mass": 2.0, "crossover_hz": 20.0} for a in axes]},
            **{f"d{a}": {"builtin": "drive", "parameters": {"cogging": 0.0}} for a in axes}},
        "connection": [c for a in axes for c in (
            {"from": f"pid.{a}_effort", "to": f"d{a}.F"}, {"from": f"d{a}.x", "to": f"pid.{a}"})],
        "source": [{"kind": "constant", "values": {f"{a}_ff": 0.0 for a in axes}}],
        "machine": {"name": "gantry", "axis": [
            {"name": a, "measured": f"d{a}.x", "true": f"d{a}.x_true",
             "feedforward": f"pid.{a}_ff", "effort": f"pid.{a}_effort", "range": [-0.04, 0.04],
             "velocity": 0.2, "acceleration": 2.0} for a in axes]}}, name="gantry")


def test_a_run_s_reference_drives_every_axis_of_its_machine(tmp_path):
    loop = three_drives({"kind": "sine", "duration": 1.5, "frequency_hz": {"y": 1.0}})
    assert loop.stop == pytest.approx(1.5)
    signals = source_signals(loop)
    for axis in ("x", "y", "z"):
        assert all(f"{d}{axis}_ref" in signals for d in ("", "v", "a", "j"))
    recording = simulate_config(loop, progress=False)
    for axis in ("x", "y", "z"):
        error = recording[f"{axis}_ref"] - recording[f"d{axis}.x_true"]
        assert np.abs(error).max() < 0.05 * np.ptp(recording[f"{axis}_ref"])


@pytest.mark.parametrize("reference, key, message", [
    ({"kind": "random"}, "reference.duration", "required"),
    ({"kind": "sine", "duration": 1.0, "share": 1.5}, "reference.share", "lies in"),
    ({"kind": "sine", "duration": 1.0, "points": {"x": [0.0]}}, "reference.points",
     "unknown key"),
    ({"kind": "point-to-point", "duration": 1.0, "points": {"x": [0.5]}}, "reference.",
     "axis x: the point 0.5 lies outside its range"),
    ({"kind": "multisine", "duration": 1.0, "start": {"v": 0.0}}, "reference.",
     "reference.start.v: the machine has no axis 'v'"),
])
def test_bad_axis_references_are_refused_by_key(reference, key, message):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.") + ".*" + message):
        three_drives(reference)


def test_an_axis_reference_needs_a_machine():
    fmu = Path(__file__).parents[1] / "machines"  # any folder: the reference fails first
    with pytest.raises(ConfigError, match=r"reference\.duration: a 'sine' reference is made "
                                          r"for the axes of a machine: add a \[machine\]"):
        parse_config({"reference": {"kind": "sine", "duration": 1.0},
                      "fmu": {"a": {"path": str(fmu / "none.fmu")}}})
