"""Control allocation, encoder kinematics, the rigid-body feedforward and the controller System's
signals, against numpy's least squares, the plant model and scipy's discrete simulation."""

import json

import casadi as ca
import numpy as np
import pytest
from scipy import signal

from flexff.controllers.allocation import (
    actuation_jacobian,
    allocate_torques,
    measured_position,
    motor_currents,
)
from flexff.controllers.feedback import HOME_ANGLES, controller_design, controller_system
from flexff.controllers.feedforward import rigid_body_feedforward_system
from flexff.plant.kinematics import shoulder_angles
from flexff.plant.parameters import NOMINAL
from tests.helpers import workspace_points

POS, FORCE = ca.SX.sym("pos", 2), ca.SX.sym("force", 2)
ALLOCATION = ca.Function("allocation", [POS, FORCE],
                         [actuation_jacobian(POS), allocate_torques(FORCE, POS),
                          motor_currents(FORCE, POS)])


def exact_angles(pos):
    return np.array([float(a) for a in shoulder_angles(NOMINAL, pos[0], pos[1])])


def test_actuation_jacobian_is_the_plant_models(nominal, rng):
    p = nominal.parameter_values()
    for pos in workspace_points(rng, 20).T:
        ours = np.array(ALLOCATION(pos, [0, 0])[0])
        assert np.allclose(ours, np.array(nominal.terms(pos, [0, 0], p)[4]), atol=1e-12)


def test_allocation_is_the_least_norm_solution(rng):
    for pos in workspace_points(rng, 30).T:
        force = rng.normal(0, 1.0, 2)
        a, tau, currents = (np.array(v) for v in ALLOCATION(pos, force))
        tau, currents = tau.ravel(), currents.ravel()
        assert np.allclose(a.T @ tau, force, rtol=0, atol=1e-12)  # the forces are produced
        assert np.allclose(tau, np.linalg.pinv(a.T) @ force, atol=1e-12)
        assert np.allclose(tau, np.linalg.lstsq(a.T, force, rcond=None)[0], atol=1e-12)
        # least norm: no component along the null space of A^T (the internal preload)
        null = np.linalg.svd(a.T)[2][-1]
        assert abs(null @ tau) < 1e-12 * np.linalg.norm(tau)
        assert np.allclose(currents, tau / np.array(NOMINAL.k_t), rtol=1e-14)


@pytest.mark.parametrize("encoders", [2, 3])
def test_measured_position_from_exact_angles(rng, encoders):
    theta = ca.SX.sym("theta", 3)
    fk = ca.Function("fk", [theta], [measured_position(theta, encoders)])
    for pos in workspace_points(rng, 40).T:
        assert np.allclose(np.array(fk(exact_angles(pos))).ravel(), pos, rtol=0, atol=1e-10)


def test_measured_position_rejects_other_encoder_counts():
    with pytest.raises(ValueError, match="encoders must be one of"):
        measured_position(ca.SX.sym("theta", 3), 4)


def test_rigid_body_feedforward_is_the_nominal_inverse_dynamics(nominal, rng):
    system = rigid_body_feedforward_system()
    assert system.kind == "discrete" and system.sample_time == 1e-3
    assert system.states == () and system.parameters == ()
    assert [v.name for v in system.inputs] == ["x_ref", "y_ref", "vx_ref", "vy_ref", "ax_ref",
                                               "ay_ref"]
    assert [v.name for v in system.outputs] == ["Fx_ff", "Fy_ff"]
    assert system.initial_state([]).shape == (0, 1)
    p = nominal.parameter_values()
    for pos in workspace_points(rng, 20).T:
        vel, acc = rng.normal(0, 0.2, 2), rng.normal(0, 3.0, 2)
        ours = np.array(system.output([], np.r_[pos, vel, acc], [], [])).ravel()
        assert np.allclose(ours, np.array(nominal.inverse_dynamics(pos, vel, acc, p)).ravel(),
                           rtol=1e-12, atol=1e-14)
        assert system.dynamics([], np.r_[pos, vel, acc], []).shape == (0, 1)


@pytest.mark.parametrize("variant, n_states", [("nominal", 2), ("hardware", 4)])
def test_controller_system_signals(variant, n_states):
    system = controller_system(variant)
    assert system.kind == "discrete" and system.sample_time == 1e-3 and system.n_noise == 0
    assert [v.name for v in system.inputs] == ["x_ref", "y_ref", "theta_s1", "theta_s2",
                                               "theta_s3", "Fx_ff", "Fy_ff"]
    assert [v.name for v in system.outputs] == ["i1", "i2", "i3", "Fx_fb", "Fy_fb", "Fx",
                                                "Fy"]
    assert len(system.states) == 2 * n_states
    assert [v.name for v in system.parameters] == ["kp_x", "kp_y"]
    assert system.parameters[0].start == pytest.approx(controller_design(variant).kp)
    numbers = json.loads(system.extra["design"], parse_constant=pytest.fail)  # strict JSON
    assert numbers["kp"] == system.parameters[0].start and numbers["variant"] == variant
    # at rest at the centre with no error: no feedback, and the currents carry F_ff alone
    kp = [v.start for v in system.parameters]
    x0 = np.array(system.initial_state(kp)).ravel()
    force_ff = np.array([0.3, -0.2])
    out = np.array(system.output(x0, np.r_[0, 0, HOME_ANGLES, force_ff], kp, [])).ravel()
    assert np.allclose(out[3:5], 0, atol=1e-12)  # no feedback
    assert np.allclose(out[5:], force_ff, rtol=1e-12)  # the commanded force: F_ff alone
    expected = np.array(ALLOCATION([0, 0], force_ff)[2]).ravel()
    assert np.allclose(out[:3], expected, rtol=1e-12)


def test_controller_system_runs_the_designed_filter(rng):
    """Driven with encoder angles of a moving wrist, the System's feedback forces are the
    discrete design's response (scipy dlsim) to the position error, per axis, times kp."""
    design = controller_design("hardware")
    system = controller_system("hardware", encoders=3)
    n = 400
    t = np.arange(n) * 1e-3
    pos = 0.01 * np.vstack([np.sin(7 * t), np.cos(3 * t) - 1])
    ref = pos + 1e-3 * rng.normal(size=(2, n))
    kp = [1.5 * design.kp, 0.5 * design.kp]  # the gains are live parameters
    x = np.array(system.initial_state(kp)).ravel()
    forces = []
    for k in range(n):
        u = np.r_[ref[:, k], exact_angles(pos[:, k]), 0, 0]
        forces.append(np.array(system.output(x, u, kp, [])).ravel()[3:])
        x = np.array(system.dynamics(x, u, kp)).ravel()
    forces = np.array(forces)
    dlti = signal.dlti(design.discrete.A, design.discrete.B, design.discrete.C, design.discrete.D,
                       dt=1e-3)
    for axis, gain in enumerate((1.5, 0.5)):
        _, expected, _ = signal.dlsim(dlti, ref[axis] - pos[axis])
        assert np.allclose(forces[:, axis], gain * expected.ravel(), rtol=1e-8, atol=1e-9)


def test_controller_system_arguments():
    with pytest.raises(ValueError, match="encoders must be one of"):
        controller_system(encoders=1)
    with pytest.raises(ValueError, match="unknown controller variant"):
        controller_system("prototype")
    assert "notch" in controller_system("hardware").description
