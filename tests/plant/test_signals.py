"""The manipulator's signals, declared once (plant/signals.py), and what takes them."""

import casadi as ca
import pytest

from flexff.controllers.feedback import INPUTS, OUTPUTS
from flexff.controllers.feedforward import rigid_body_feedforward_system
from flexff.plant.signals import (
    CURRENTS,
    ENCODERS,
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    FORCES,
    REFERENCE,
    TRUE_POSITION,
    TRUE_VELOCITY,
    names,
    pick,
    reference_motion,
    units,
)
from flexff.plant.system import plant_system


def test_the_names_and_units_of_design_md():
    assert names(REFERENCE) == ("x_ref", "y_ref", "vx_ref", "vy_ref", "ax_ref", "ay_ref")
    assert units(REFERENCE) == ("m", "m", "m/s", "m/s", "m/s2", "m/s2")
    assert names(CURRENTS, ENCODERS) == ("i1", "i2", "i3", "theta_s1", "theta_s2", "theta_s3")
    assert units(CURRENTS, ENCODERS) == ("A",) * 3 + ("rad",) * 3
    assert names(TRUE_POSITION, TRUE_VELOCITY) == ("x", "y", "vx", "vy")
    assert names(FEEDFORWARD_FORCES, FEEDBACK_FORCES) == ("Fx_ff", "Fy_ff", "Fx_fb", "Fy_fb")
    assert set(units(FEEDFORWARD_FORCES, FEEDBACK_FORCES)) == {"N"}


def test_the_fmus_take_their_signals_from_there():
    plant = plant_system("nominal")
    assert plant.inputs == CURRENTS
    assert names(plant.outputs) == ("theta_s1", "theta_s2", "theta_s3", "x", "y", "vx", "vy",
                                    "tau1", "tau2", "tau3")
    assert names(INPUTS) == names(REFERENCE[:2], ENCODERS, FEEDFORWARD_FORCES)
    assert [v.unit for v in INPUTS] == [*units(REFERENCE[:2], ENCODERS, FEEDFORWARD_FORCES)]
    assert (*CURRENTS, *FEEDBACK_FORCES, *FORCES) == OUTPUTS
    feedforward = rigid_body_feedforward_system()
    assert feedforward.inputs == REFERENCE and feedforward.outputs == FEEDFORWARD_FORCES


def test_signals_are_picked_by_name_in_any_layout():
    u = ca.SX.sym("u", 6)
    shuffled = REFERENCE[::-1]  # ay_ref ... x_ref
    picked = pick(u, shuffled, REFERENCE[:2])
    assert [str(e) for e in ca.vertsplit(picked)] == ["u_5", "u_4"]
    position, velocity, acceleration = reference_motion(u)
    assert [str(e) for e in ca.vertsplit(ca.vertcat(position, velocity, acceleration))] == [
        f"u_{k}" for k in range(6)]
    with pytest.raises(ValueError, match=r"\['Fx_ff'\] are not among"):
        pick(u, REFERENCE, FEEDFORWARD_FORCES[:1])
