"""Excitation for any machine: every class within the limits, derivatives that agree with the
position, the same set for the same seed, and limits no move fits refused by key."""

import numpy as np
import pytest

from flexff.cosim.csv_text import read_time_table
from flexff.cosim.machine import parse_machine
from flexff.cosim.schema import ConfigError
from flexff.learning.excitation import CLASSES, excitation_set, write_table

RATE = 1000.0


def machine(jerk=None):
    axes = [{"name": "x", "range": [-0.05, 0.05], "velocity": 0.25, "acceleration": 2.5},
            {"name": "q", "unit": "rad", "range": [0.2, 1.0], "velocity": 1.0,
             "acceleration": 20.0, **({"jerk": jerk} if jerk else {})},
            {"name": "z", "range": [0.0, 0.01], "velocity": 0.02, "acceleration": 0.5}]
    for axis in axes:
        axis |= {"measured": f"p.{axis['name']}", "feedforward": f"c.{axis['name']}_ff",
                 "effort": f"c.{axis['name']}_u"}
    return parse_machine({"axis": axes}, "m.toml")


@pytest.mark.parametrize("jerk", [None, 2000.0])
def test_every_class_keeps_every_axis_within_its_limits(jerk):
    three = machine(jerk)
    for excitation in excitation_set(three, 6, 3, 12.0, RATE, seed=1):
        for axis in three.axes:
            x, v, a, j = (excitation.signals[n] for n in (axis.reference, *axis.derivatives))
            limits = axis.limits
            assert limits.low - 1e-12 <= x.min() and x.max() <= limits.high + 1e-12
            assert np.abs(v).max() <= limits.velocity * (1 + 1e-9)
            assert np.abs(a).max() <= limits.acceleration * (1 + 1e-9)
            if limits.jerk is not None:
                assert np.abs(j).max() <= limits.jerk * (1 + 1e-9)
            assert abs(v[0]) + abs(v[-1]) < 1e-9  # at rest at both ends
            assert np.ptp(x) > 0.05 * (limits.high - limits.low)  # it moves


def test_derivatives_agree_with_the_position():
    for excitation in excitation_set(machine(2000.0), 3, 0, 12.0, RATE, seed=2):
        x, v, a = (excitation.signals[n] for n in ("q_ref", "vq_ref", "aq_ref"))
        dt = 1 / RATE
        np.testing.assert_allclose(np.gradient(x, dt)[1:-1], v[1:-1],
                                   atol=2e-3 * np.abs(v).max())
        if excitation.kind != "bang-bang":  # its acceleration steps
            np.testing.assert_allclose(np.gradient(v, dt)[1:-1], a[1:-1],
                                       atol=2e-2 * np.abs(a).max())


def test_the_set_is_the_same_for_a_seed_and_splits_apart():
    one, again = (excitation_set(machine(), 4, 2, 12.0, RATE, seed=3) for _ in range(2))
    other = excitation_set(machine(), 4, 2, 12.0, RATE, seed=4)
    assert [e.name for e in one] == [e.name for e in again]
    assert all(np.array_equal(a.signals["x_ref"], b.signals["x_ref"]) for a, b in zip(one, again))
    assert not np.array_equal(one[0].signals["x_ref"], other[0].signals["x_ref"])
    assert [e.split for e in one] == ["train"] * 4 + ["test"] * 2
    assert {e.kind for e in one} == set(CLASSES)


def test_limits_no_move_fits_are_refused_by_key():
    slow = parse_machine({"axis": [
        {"name": "x", "measured": "p.x", "feedforward": "c.x_ff", "effort": "c.x_u",
         "range": [-1.0, 1.0], "velocity": 0.01, "acceleration": 0.1}]}, "m.toml")
    with pytest.raises(ConfigError, match=r"machine\.axis\[0\]\.velocity: a move over half "
                                          r"the range .* takes .* longer than the 5 s"):
        excitation_set(slow, 1, 0, 5.0, RATE)


def test_the_table_reads_back(tmp_path):
    excitation = excitation_set(machine(), 1, 0, 5.0, RATE)[0]
    table = read_time_table(write_table(excitation, tmp_path / "x.csv"))
    assert list(table.columns)[1:] == list(excitation.signals)
    np.testing.assert_array_equal(table.columns["vz_ref"], excitation.signals["vz_ref"])
