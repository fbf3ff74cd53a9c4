"""PID loop shaping against independent references: the per-axis plant, transfer functions and
margins recomputed with scipy.signal, Tustin against the continuous controller, and closed-loop
eigenvalues of the built controller System around the linearized nominal and hardware plants."""

import math

import casadi as ca
import numpy as np
import pytest
from scipy import signal

from flexff.blocks.loop_shaping import design_pid, loop_margins
from flexff.controllers.axis_plant import axis_plant
from flexff.controllers.feedback import controller_design, controller_system, parasitic_mode_hz
from flexff.plant.analysis import FRICTION_FREE, linearization
from flexff.plant.model import PlantModel

STEP = 1e-3


@pytest.fixture(scope="module")
def designs():
    return {"nominal": controller_design("nominal"), "hardware": controller_design("hardware")}


def transfer_function(design):
    """The controller (and notch) as numerator/denominator polynomials, from the formulas."""
    num = design.kp * np.polymul([1 / design.wd, 1], [1, design.wi])
    den = np.polymul([1 / design.wt, 1], [1, 0])
    if design.notch_hz:
        wn, (z1, z2) = 2 * math.pi * design.notch_hz, design.notch_zeta
        num = np.polymul(num, [1, 2 * z1 * wn, wn**2])
        den = np.polymul(den, [1, 2 * z2 * wn, wn**2])
    return num, den


def plant_tf():
    p = axis_plant()
    return np.array([1.0]), np.array([p.mass, p.damping, p.stiffness])


def test_axis_plant_is_the_centre_linearization(nominal):
    plant = axis_plant(nominal)
    p = nominal.parameter_values()
    m = np.array(nominal.terms([0, 0], [0, 0], p)[0])
    assert np.allclose(m, plant.mass * np.eye(2), atol=1e-12)
    # stiffness and damping by finite differences of the force terms Q and D
    h = 1e-7
    q_plus = np.array(nominal.terms([h, 0], [0, 0], p)[2]).ravel()
    d_plus = np.array(nominal.terms([0, 0], [0, h], p)[3]).ravel()
    assert q_plus / h == pytest.approx([plant.stiffness, 0], abs=1e-5 * plant.stiffness)
    assert d_plus / h == pytest.approx([0, plant.damping], abs=1e-5 * plant.damping)
    # the thesis's 1.7 Hz lowest natural frequency
    assert math.sqrt(plant.stiffness / plant.mass) / (2 * math.pi) == pytest.approx(1.70, abs=1e-3)


@pytest.mark.parametrize("variant, crossover_hz", [("nominal", 2.66), ("hardware", 2.0)])
def test_continuous_loop_crosses_over_at_the_request_with_healthy_phase_margin(
        designs, variant, crossover_hz):
    design = designs[variant]
    wc = 2 * math.pi * crossover_hz
    assert (design.wd, design.wt, design.wi) == pytest.approx((wc / 3, 3 * wc, wc / 10))
    num, den = transfer_function(design)
    loop_num, loop_den = np.polymul(num, plant_tf()[0]), np.polymul(den, plant_tf()[1])
    _, loop = signal.freqs(loop_num, loop_den, worN=[wc])
    assert abs(loop[0]) == pytest.approx(1.0, abs=1e-6)
    phase_margin = 180 + math.degrees(np.angle(loop[0]))
    assert 30 < phase_margin < 60
    # the state-space realization is that transfer function
    w = np.geomspace(0.1, 1e3, 50)
    realization = signal.StateSpace(*[getattr(design.continuous, k) for k in "ABCD"])
    _, ours = signal.freqresp(realization, w)
    _, reference = signal.freqs(num, den, worN=w)
    assert np.allclose(ours, reference, rtol=1e-9)
    # and loop_margins agrees on the continuous loop
    margins = loop_margins(design.continuous, design.plant)
    assert margins.crossover_hz == pytest.approx(crossover_hz, rel=1e-9)
    assert margins.phase_margin_deg == pytest.approx(phase_margin, abs=1e-6)


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_discrete_loop_margins_against_scipy_and_eigenvalues(designs, variant):
    design = designs[variant]
    pnum, pden = plant_tf()
    pz_num, pz_den, _ = signal.cont2discrete((pnum, pden), STEP, method="zoh")
    cz = signal.ss2tf(*[getattr(design.discrete, k) for k in "ABCD"])
    # polynomials in z (descending powers); np.polymul drops the ZOH numerator's leading zero
    loop_num, loop_den = np.polymul(cz[0].ravel(), pz_num.ravel()), np.polymul(cz[1], pz_den)
    wc = 2 * math.pi * design.margins.crossover_hz
    z = np.exp(1j * wc * STEP)
    loop = np.polyval(loop_num, z) / np.polyval(loop_den, z)
    assert abs(loop) == pytest.approx(1.0, abs=1e-6)  # polynomial form loses some digits
    assert design.margins.crossover_hz == pytest.approx(design.crossover_hz, rel=1e-3)
    phase_margin = 180 + math.degrees(np.angle(loop))
    assert design.margins.phase_margin_deg == pytest.approx(phase_margin, abs=1e-3)
    assert 30 < phase_margin < 60

    def spectral_radius(gain):
        closed = np.polyadd(loop_den, gain * np.pad(loop_num, (len(loop_den) - len(loop_num), 0)))
        return np.abs(np.roots(closed)).max()

    limit = 10 ** (design.margins.gain_margin_db / 20)
    assert design.margins.gain_margin_db > 20
    assert spectral_radius(1.0) < 1 and spectral_radius(0.98 * limit) < 1
    assert spectral_radius(1.02 * limit) > 1
    assert design.margins.lower_gain_margin_db == -math.inf  # the plant is stable on its own
    assert spectral_radius(1e-3) < 1


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_discrete_controller_matches_the_continuous_one(designs, variant):
    design = designs[variant]
    low = 2 * math.pi * np.geomspace(0.01, 10, 40)
    cont, disc = design.continuous.response(low), design.discrete.response(low)
    assert np.abs(disc / cont - 1).max() < 0.01
    wc = 2 * math.pi * design.crossover_hz  # prewarped: exact at the crossover
    assert design.discrete.response(wc)[0] == pytest.approx(design.continuous.response(wc)[0],
                                                            rel=1e-3 if design.notch_hz else 1e-10)
    if design.notch_hz:  # and the notch exact at its centre: depth z1 / z2
        wn = 2 * math.pi * design.notch_hz
        depth = abs(design.discrete.response(wn)[0] / design.continuous.response(wn)[0])
        assert depth == pytest.approx(1.0, rel=1e-3)
        z1, z2 = design.notch_zeta
        pid_only = design_pid(design.crossover_hz, STEP, plant=design.plant)
        ratio = design.discrete.response(wn)[0] / pid_only.discrete.response(wn)[0]
        assert abs(ratio) * pid_only.kp / design.kp == pytest.approx(z1 / z2, rel=1e-9)
    # step responses agree once the first (derivative) transient is over
    t = np.arange(0, 3.0, STEP)
    _, y_cont = signal.step(signal.StateSpace(*[getattr(design.continuous, k) for k in "ABCD"]),
                            T=t)
    _, y_disc = signal.dstep(signal.dlti(*[getattr(design.discrete, k) for k in "ABCD"], dt=STEP),
                             n=len(t))
    late = t > 0.2
    assert np.allclose(y_disc[0].ravel()[late], y_cont[late], rtol=2e-3)


def test_design_numbers_and_arguments():
    assert parasitic_mode_hz() == pytest.approx(40.0, abs=0.1)
    plant = axis_plant()
    with pytest.raises(ValueError, match="Nyquist"):
        design_pid(2.0, STEP, notch_hz=600.0, plant=plant)
    with pytest.raises(ValueError, match="positive"):
        design_pid(-1.0, STEP, plant=plant)
    with pytest.raises(ValueError, match="unknown controller variant"):
        controller_design("prototype")
    with pytest.raises(ValueError, match="z1 < z2"):
        design_pid(2.0, STEP, notch_hz=40.0, notch_zeta=(0.5, 0.02), plant=plant)


def linearized_plant(variant):
    """(A, B, C, home): currents -> encoder angles, linearized at rest at the centre.

    Coulomb friction is left out, as in plant.analysis.modes: its smooth tanh would act as a
    large viscous damper at rest and flatter the margin. C comes from central differences of
    the plant's own output with a practically continuous encoder (1e12 counts/rev).
    """
    model = PlantModel(variant)
    p = model.parameter_values(encoder_counts=1e12,
                               **(FRICTION_FREE if variant == "hardware" else {}))
    x, i = ca.SX.sym("x", model.n_states), ca.SX.sym("i", 3)
    x0 = np.array(model.initial_state([0, 0], p)).ravel()
    a = linearization(model, p)
    b = np.array(ca.Function("b", [x, i], [ca.jacobian(model.forward_dynamics(x, i, p), i)])(
        x0, [0, 0, 0]))

    def encoders(state):
        return np.array(model.output(state, [0, 0, 0], p, [0, 0, 0])).ravel()[:3]

    h, eye = 1e-6, np.eye(model.n_states)
    c = np.column_stack([(encoders(x0 + h * e) - encoders(x0 - h * e)) / (2 * h) for e in eye])
    return a, b, c, encoders(x0)


def closed_loop_spectral_radius(variant, system, gain=1.0):
    """Largest |eigenvalue| of the ZOH plant in closed loop with the built controller System."""
    a, b, c, home = linearized_plant(variant)
    ad, bd, *_ = signal.cont2discrete((a, b, c, np.zeros((3, 3))), system.sample_time, "zoh")
    nc = len(system.states)
    xc, u = ca.SX.sym("xc", nc), ca.SX.sym("u", len(system.inputs))
    kp = [gain * v.start for v in system.parameters]
    currents = system.output(xc, u, kp, ca.SX(0, 1))[:3]
    x_next = system.dynamics(xc, u, kp)
    theta = u[2:5]
    jac = ca.Function("linear_controller", [xc, u],
                      [ca.jacobian(currents, xc), ca.jacobian(currents, theta),
                       ca.jacobian(x_next, xc), ca.jacobian(x_next, theta)])
    d_x, d_theta, a_c, b_theta = (np.array(m) for m in jac(np.zeros(nc),
                                                           np.r_[0, 0, home, 0, 0]))
    closed = np.block([[ad + bd @ d_theta @ c, bd @ d_x], [b_theta @ c, a_c]])
    return np.abs(np.linalg.eigvals(closed)).max()


@pytest.mark.parametrize("variant, encoders", [("nominal", 2), ("nominal", 3), ("hardware", 2),
                                               ("hardware", 3)])
def test_closed_loop_is_stable(variant, encoders):
    system = controller_system(variant, encoders=encoders)
    assert closed_loop_spectral_radius(variant, system) < 1


def test_notch_cuts_the_controller_gain_at_the_parasitic_mode():
    """The hardware controller's notch sits on the tool mode: the discrete controller's gain
    there drops by more than 20 dB against the same PID without the notch, and the loop on the
    hardware plant stays stable with four times the designed gain."""
    with_notch, without = controller_design("hardware"), controller_design("nominal", 2.0)
    w = np.array([2 * math.pi * parasitic_mode_hz()])
    ratio = abs(with_notch.discrete.response(w)[0]) / abs(without.discrete.response(w)[0])
    assert 20 * np.log10(float(np.squeeze(ratio))) < -20
    assert closed_loop_spectral_radius("hardware", controller_system("hardware"), gain=4.0) < 1
