"""Excitation for any machine: every class within the limits on every sample, derivatives that
agree with the position, the same set for the same seed, a test split drawn apart, limits no
move fits refused by key, the table read back by a run's CSV source, and its plot."""

import math
import re
import shutil

import numpy as np
import pytest

from flexff.cosim.config import load_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import parse_machine
from flexff.cosim.motion_shapes import PiecewiseJerk
from flexff.cosim.run import simulate_config
from flexff.cosim.scenario import source_signals
from flexff.cosim.schema import RunConfig, SourceConfig
from flexff.learning.excitation import CLASSES, EVERY_CLASS, excitation_set, write_table
from flexff.learning.excitation_plot import plot_excitation
from flexff.learning.machine_loop import loop_machine, on_references, record_signals
from tests.learning.test_machine_loop import EXAMPLES, LOOP

RATE = 1000.0
TOLERANCE = 1e-9  # relative, on the limits


def machine(jerk=None, **changes):
    """Three axes in different units and scales; `changes` replaces keys of axis q."""
    axes = [{"name": "x", "range": [-0.05, 0.05], "velocity": 0.25, "acceleration": 2.5},
            {"name": "q", "unit": "rad", "range": [0.2, 1.0], "velocity": 1.0,
             "acceleration": 20.0, **({"jerk": jerk} if jerk else {}), **changes},
            {"name": "z", "unit": "mm", "range": [0.0, 10.0], "velocity": 20.0,
             "acceleration": 500.0}]
    for axis in axes:
        axis |= {"measured": f"p.{axis['name']}", "feedforward": f"c.{axis['name']}_ff",
                 "effort": f"c.{axis['name']}_u"}
    return parse_machine({"name": "three", "axis": axes}, "m.toml")


def motion(excitation, axis):
    return [excitation.signals[n] for n in (axis.reference, *axis.derivatives)]


@pytest.mark.parametrize("jerk", [None, 400.0])  # 400 rad/s^3 binds the S-curves and splines
def test_every_class_keeps_every_axis_within_its_limits(jerk):
    three, jerk_reached = machine(jerk), 0.0
    for k, excitation in enumerate(excitation_set(three, 12, 0, 8.0, RATE, seed=1,
                                                  classes=EVERY_CLASS)):
        for index, axis in enumerate(three.axes):
            x, v, a, j = motion(excitation, axis)
            limits = axis.limits
            span = limits.high - limits.low
            assert limits.low - TOLERANCE * span <= x.min()
            assert x.max() <= limits.high + TOLERANCE * span
            assert np.abs(v).max() <= limits.velocity * (1 + TOLERANCE)
            assert np.abs(a).max() <= limits.acceleration * (1 + TOLERANCE)
            if limits.jerk is not None:
                assert np.abs(j).max() <= limits.jerk * (1 + TOLERANCE)
                jerk_reached = max(jerk_reached, np.abs(j).max() / limits.jerk)
            assert x[0] == pytest.approx(0.5 * (limits.low + limits.high))
            assert abs(v[0]) + abs(v[-1]) <= 1e-9 * limits.velocity  # at rest at both ends
            solo = excitation.kind == "solo"  # the k // 6-th solo moves axis k // 6 alone
            moves = excitation.kind != "rest" and (not solo or index == k // len(EVERY_CLASS))
            sines = excitation.kind in ("multisine", "sine", "random")  # scaled, not moves
            least = 0.05 if sines else 0.15  # of the range
            assert (np.ptp(x) > least * span) == moves
            if moves and not sines:  # moves reach for the limits
                assert max(np.abs(v).max() / limits.velocity,
                           np.abs(a).max() / limits.acceleration) > 0.3
    assert jerk is None or jerk_reached > 0.5  # the jerk limit binds


def assert_integrates(values, derivative, step, what, bend=0.0):
    """Each sample-to-sample increment of `values` lies between `step` times the derivative
    at its two ends (the mean of a derivative that is monotonic or steps between samples),
    give or take what a derivative turning at `bend` (its own slope's bound) adds between."""
    increments = np.diff(values)
    ends = step * np.stack([derivative[:-1], derivative[1:]])
    slack = 1e-4 * step * np.abs(derivative).max() + step**2 * bend / 4
    outside = (increments < ends.min(0) - slack) | (increments > ends.max(0) + slack)
    assert not outside.any(), f"{what}: {outside.sum()} samples, first {np.argmax(outside)}"


@pytest.mark.parametrize("jerk", [None, 400.0])
def test_derivatives_agree_with_the_position(jerk):
    """Velocity against the position's central differences, and every signal's increments
    against its derivative (exact through the trapezoid's acceleration steps)."""
    three = machine(jerk)
    for excitation in excitation_set(three, 8, 0, 8.0, RATE, seed=2):
        for axis in three.axes:
            x, v, a, j = motion(excitation, axis)
            where = f"{excitation.name} {axis.name}"
            np.testing.assert_allclose(np.gradient(x, 1 / RATE)[1:-1], v[1:-1],
                                       atol=1e-2 * np.abs(v).max(), err_msg=where)
            assert_integrates(x, v, 1 / RATE, f"{where} velocity", np.abs(a).max())
            assert_integrates(v, a, 1 / RATE, f"{where} acceleration", np.abs(j).max())
            if excitation.kind == "bang-bang" and axis.limits.jerk is None:
                assert not j.any()  # piecewise-constant acceleration: its steps are no samples
                continue
            assert_integrates(a, j, 1 / RATE, f"{where} jerk")


def test_every_phase_of_a_move_shows_on_the_samples():
    """An acceleration that would reach the velocity within a sample is lowered so that the
    bang-bang's phases last samples (else velocity would step between them, acceleration 0)."""
    sharp = machine(**{"range": [0.0, 0.02], "velocity": 0.012, "acceleration": 200.0})
    for excitation in excitation_set(sharp, 2, 0, 6.0, 100.0, seed=8, classes=["bang-bang"]):
        _, v, a, j = motion(excitation, sharp.axes[1])
        assert np.count_nonzero(a) >= 2 * 4 * np.count_nonzero(np.diff(v != 0) & (v[1:] != 0))
        assert_integrates(v, a, 1 / 100.0, excitation.name, np.abs(j).max())


def test_the_set_is_the_same_for_a_seed_and_its_test_split_is_drawn_apart():
    one, again = (excitation_set(machine(), 4, 3, 4.0, RATE, seed=3) for _ in range(2))
    other = excitation_set(machine(), 4, 3, 4.0, RATE, seed=4)
    more_training = excitation_set(machine(), 6, 3, 4.0, RATE, seed=3)
    assert [e.name for e in one] == [e.name for e in again]
    for a, b in zip(one, again):
        assert all(np.array_equal(a.signals[n], b.signals[n]) for n in a.signals)
    assert not any(np.array_equal(a.signals["x_ref"], b.signals["x_ref"])
                   for a, b in zip(one, other) if a.kind != "rest")
    assert [e.split for e in one] == ["train"] * 4 + ["test"] * 3
    assert {e.kind for e in one} == set(CLASSES)
    assert len({e.name for e in one}) == len(one)
    train, test = one[:4], one[4:]
    assert not any(np.array_equal(a.signals["z_ref"], b.signals["z_ref"])
                   for a in train for b in test)
    for a, b in zip(test, more_training[6:]):  # the test split does not move with n_train
        assert a.name == b.name and np.array_equal(a.signals["q_ref"], b.signals["q_ref"])


def test_each_axis_moves_on_its_own():
    three = machine()
    for excitation in excitation_set(three, 3, 0, 6.0, RATE, seed=5):
        still = [motion(excitation, axis)[1] == 0 for axis in three.axes]
        velocity = [v / np.abs(v).max() for v in (motion(excitation, a)[1] for a in three.axes)]
        assert np.corrcoef(velocity).max(initial=0, where=~np.eye(3, dtype=bool)) < 0.9
        assert excitation.kind == "multisine" or not np.array_equal(still[0], still[2])


def test_synchronised_moves_start_and_end_together_within_the_limits():
    three = machine(400.0)
    for excitation in excitation_set(three, 3, 0, 8.0, RATE, seed=7, synchronised=True):
        moving = []
        for axis in three.axes:
            x, v, a, j = motion(excitation, axis)
            limits = axis.limits
            assert limits.low <= x.min() and x.max() <= limits.high
            for value, bound in ((v, limits.velocity), (a, limits.acceleration),
                                 (j, limits.jerk or np.inf)):
                assert np.abs(value).max() <= bound * (1 + TOLERANCE)
            assert_integrates(x, v, 1 / RATE, f"{excitation.name} {axis.name}", np.abs(a).max())
            moving.append(v != 0)
        assert np.array_equal(moving[0], moving[1]) and np.array_equal(moving[0], moving[2])
        assert 0.3 < moving[0].mean() < 1


@pytest.mark.parametrize(("changes", "duration", "key", "message"), [
    ({"range": [-1.0, 1.0], "velocity": 0.01}, 8.0, "velocity",
     r"a move over 20% of the range \(0\.38 rad\) takes 76 s at this velocity, longer than the "
     r"8 s trajectory: raise velocity or the duration"),
    ({"acceleration": 0.001}, 8.0, "acceleration", r"takes .* s at this acceleration"),
    ({"jerk": 0.01}, 8.0, "jerk", r"takes .* s at this jerk"),
    ({"jerk": 2.0}, 8.0, "jerk", r"2 rad/s\^3 is so low that a move across the range reaches "
     r"0\.785 rad/s\^2, under 10% of the acceleration 20: raise jerk or lower acceleration"),
    ({"range": [0.0, 0.0005]}, 8.0, "range", r"0 \.\. 0\.0005 rad is too short for these limits: "
     r"a move across it reaches 0\.0\d+ rad/s, under 10% of the velocity 1"),
])
def test_limits_no_move_fits_are_refused_by_key(changes, duration, key, message):
    with pytest.raises(ConfigError) as refused:
        excitation_set(machine(**changes), 1, 0, duration, RATE)
    assert refused.value.key == f"machine.axis[1].{key}"
    assert "\n" not in str(refused.value)
    assert re.search(message, str(refused.value))


@pytest.mark.parametrize(("arguments", "key"), [
    ({"n_train": 0}, "n_train"), ({"n_test": -1}, "n_test"), ({"duration": 0.0}, "duration"),
    ({"rate_hz": 0.1}, "rate_hz"), ({"seed": -1}, "seed"), ({"classes": ("lines",)}, "classes"),
])
def test_a_request_that_makes_no_set_is_refused_by_name(arguments, key):
    request = {"n_train": 1, "n_test": 0, "duration": 4.0, "rate_hz": RATE} | arguments
    with pytest.raises(ConfigError) as refused:
        excitation_set(machine(), **request)
    assert refused.value.key == key


def test_the_table_is_what_a_run_reads_from_its_csv_source(tmp_path):
    excitation = excitation_set(machine(400.0), 1, 0, 3.0, RATE)[0]
    table = write_table(excitation, tmp_path / "moves.csv")
    run = RunConfig("excitation", 1 / RATE, 3.0, (), sources=(SourceConfig("csv", path=table),))
    read = source_signals(run)
    assert list(read) == list(excitation.machine.reference_signals)
    for name, values in excitation.signals.items():
        np.testing.assert_allclose(read[name], values, rtol=0, atol=1e-12 * np.abs(values).max())


def test_a_loop_runs_on_the_table(tmp_path):
    """The machine loop's path (learning.machine_loop.on_references): a feedthrough FMU whose
    measured position is twice the reference it receives."""
    shutil.copy(EXAMPLES / "reference-fmus" / "fmi2" / "Feedthrough.fmu", tmp_path)
    (tmp_path / "loop.toml").write_text(LOOP)
    loop = load_config(tmp_path / "loop.toml")
    excitation = excitation_set(loop_machine(loop), 1, 0, 3.0, 100.0, classes=("spline",))[0]
    table = write_table(excitation, tmp_path / "references" / "spline-000.csv")
    columns = record_signals(simulate_config(on_references(loop, table, 3.0, "spline")),
                             loop_machine(loop))
    for name, values in excitation.signals.items():
        np.testing.assert_allclose(columns[name], values, atol=1e-12)
    np.testing.assert_allclose(columns["x_measured"], 2 * excitation.signals["x_ref"],
                               atol=1e-12)


def test_the_plot_is_a_png(tmp_path):
    excitation = excitation_set(machine(400.0), 2, 0, 3.0, RATE, seed=6)[1]
    path = plot_excitation(excitation, tmp_path / "bang-bang.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 20_000


def test_a_move_ends_at_its_end_where_duration_rounds_past_its_segments(monkeypatch):
    """From Python 3.12 sum() adds floats exactly rounded: a move's duration (0.1 + 0.4 + 0.1:
    0.6000000000000001) may lie an ulp past where its segments add up (0.6). Its last
    segment still holds the end, at rest at the full distance (not a sample of zeros)."""
    move = PiecewiseJerk(((0.1, 10.0, 0.0), (0.4, 0.0, 0.0), (0.1, -10.0, 0.0)))
    monkeypatch.setattr(PiecewiseJerk, "duration", property(
        lambda shape: math.fsum(s[0] for s in shape.segments)))  # Python 3.12's sum()
    x, v, a, _ = move(np.array([move.duration]))[:, 0]
    assert x == pytest.approx(0.5) and v == pytest.approx(0.0, abs=1e-12) and a == -10.0


def test_the_cli_s_classes_are_the_module_s():
    from flexff.cli import shared

    assert (shared.EXCITATION, shared.EVERY_EXCITATION) == (CLASSES, EVERY_CLASS)
