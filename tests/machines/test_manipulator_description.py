"""The thesis's manipulator described as any machine: its short form's [machine] description
(controllers.manipulator_machine), written out by `flexff config expand`, is the same run, its
entries say what the loop does (the kinematic map, the commanded force), and any machine's
tools identify the manipulator from it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexff.cosim.config import config_examples, expanded, expanded_text, parse_config
from flexff.cosim.run import simulate_config
from flexff.fmu.expressions import evaluate
from flexff.learning.loop import is_manipulator_loop
from flexff.learning.machine_collect import collect_machine
from flexff.learning.machine_identify import identify_dataset
from flexff.plant.analysis import plant_info
from flexff.plant.kinematics import forward_kinematics_2
from flexff.plant.parameters import NOMINAL

SHORT = config_examples()["thesis-eval-pid"]
STOP = 1.5  # s: the line and the start of the first circle


def _short_and_explicit():
    short = parse_config(SHORT.replace("stop = 15.0", f"stop = {STOP}"), name="short")
    explicit = parse_config(expanded_text(short), name="explicit")
    return short, explicit


def test_the_short_form_describes_its_machine():
    short, explicit = _short_and_explicit()
    assert short.machine is not None and short.machine == explicit.machine
    assert [a.name for a in short.machine.axes] == ["x", "y"]
    assert [(a.feedforward, a.effort) for a in short.machine.axes] == [
        ("controller.Fx_ff", "controller.Fx"), ("controller.Fy_ff", "controller.Fy")]
    assert expanded(explicit) == expanded(short)
    # either way the manipulator's own tools take it; a [machine] of the user's overrides
    assert is_manipulator_loop(short) and is_manipulator_loop(explicit)
    table = expanded(short)
    table["machine"] = {"axis": table["machine"]["axis"][:1]}
    assert [a.name for a in parse_config(table).machine.axes] == ["x"]


def test_short_form_and_explicit_description_give_bit_equal_records():
    short, explicit = _short_and_explicit()
    first, second = simulate_config(short, progress=False), simulate_config(explicit,
                                                                            progress=False)
    assert list(first.signals) == list(second.signals)
    for name in first.signals:
        np.testing.assert_array_equal(first[name], second[name], err_msg=name)


def test_its_entries_are_what_the_loop_measures_and_commands():
    short, _ = _short_and_explicit()
    recording = simulate_config(short, progress=False)
    theta = [recording[f"plant.theta_s{k}"] for k in (1, 2)]
    kinematics = forward_kinematics_2(NOMINAL, *theta)  # the controller's, in CasADi
    for axis, controllers in zip(short.machine.axes, kinematics):
        measured = evaluate(axis.measured, {n: recording[n] for n in axis.measured.names},
                            axis.name)
        np.testing.assert_allclose(measured, np.asarray(controllers).ravel(), rtol=0,
                                   atol=1e-15)
        true = recording[axis.true.text]
        assert np.max(np.abs(true)) > 1e-3  # it moved
        assert np.max(np.abs(measured - true)) < 1e-4  # the flexures' deflection apart
        commanded = recording[axis.effort]
        feedback = recording[f"controller.F{axis.name}_fb"]
        np.testing.assert_array_equal(commanded, feedback + recording[f"F{axis.name}_ff"])


def test_the_machine_tools_identify_the_manipulator_from_its_description(tmp_path):
    """Any machine's collection and identification, on the manipulator's description: the
    identified inertia and flexure stiffness per axis give the plant's first modes at the
    centre (its linearization, plant.analysis), the commanded force explained to 3 %."""
    short, _ = _short_and_explicit()
    data = collect_machine(short, tmp_path / "data", 8, 2, 10.0, workers=1, progress=False)
    identified = identify_dataset(data).to_dict()["axes"]
    first_mode_hz = plant_info("nominal")["natural_frequencies_hz"][0]
    for axis, fitted in identified.items():
        values = dict(zip(fitted["terms"], fitted["parameters"]))
        mode_hz = math.sqrt(values["stiffness"] / values["inertia"]) / (2 * math.pi)
        assert mode_hz == pytest.approx(first_mode_hz, rel=0.01), axis
        assert fitted["relative_error"] < 0.03, axis
