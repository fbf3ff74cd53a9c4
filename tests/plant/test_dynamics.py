"""Dynamics against independent references: a constrained 21-coordinate formulation, energy,
power balance, finite differences and free-vibration simulation."""

import casadi as ca
import numpy as np
import pytest

from flexff.plant.analysis import FRICTION_FREE, modes
from flexff.plant.parameters import HARDWARE, MOTOR_FRICTION, NOMINAL
from tests.helpers import simulate, workspace_points

NO_DAMPING = {f"{d}{i}": 0.0 for d in ("d_s", "d_e", "d_w") for i in (1, 2, 3)} | {"d_tool": 0.0}


def random_states(model, rng, n, p):
    """n states at random workspace positions with random velocities (and tool deflections)."""
    states = []
    for pos in workspace_points(rng, n, radius=0.045).T:
        x = np.array(model.initial_state(pos, p)).ravel()
        x[2:4] = rng.normal(0, 0.1, 2)
        if model.n_states > 4:
            x[4:6] = rng.normal(0, 1e-4, 2)
            x[6:8] = rng.normal(0, 0.02, 2)
        states.append(x)
    return states


def test_mass_matrix_symmetric_positive_definite_over_the_workspace(nominal, rng):
    p = nominal.parameter_values()
    grid = np.linspace(-0.05, 0.05, 21)
    points = [(x, y) for x in grid for y in grid if np.hypot(x, y) <= 0.05]
    points += list(workspace_points(rng, 64).T)
    for pos in points:
        m = np.array(nominal.terms(pos, [0, 0], p)[0])
        assert np.allclose(m, m.T, rtol=1e-13, atol=1e-15)
        assert np.linalg.eigvalsh(m).min() > 0.1  # kg: well away from singular


def test_coriolis_matrix_makes_mdot_minus_2c_skew(nominal, rng):
    """Christoffel form: d/dt M - 2 C is skew-symmetric (dM/dt by finite differences)."""
    p, h = nominal.parameter_values(), 1e-6
    for pos in workspace_points(rng, 10).T:
        vel = rng.normal(0, 0.2, 2)
        m_plus = np.array(nominal.terms(pos + h * vel, vel, p)[0])
        m_minus = np.array(nominal.terms(pos - h * vel, vel, p)[0])
        mdot = (m_plus - m_minus) / (2 * h)
        c = np.array(nominal.terms(pos, vel, p)[1])
        n = mdot - 2 * c
        assert np.allclose(n, -n.T, atol=1e-8)


def test_stiffness_and_dynamics_jacobians_match_finite_differences(nominal, hardware, rng):
    for model in (nominal, hardware):
        p = model.parameter_values()
        x, i = ca.SX.sym("x", model.n_states), ca.SX.sym("i", 3)
        f = model.forward_dynamics(x, i, p)
        jac = ca.Function("fj", [x, i], [ca.jacobian(f, x), ca.jacobian(f, i)])
        h = 1e-6
        for x0 in random_states(model, rng, 4, p):
            u0 = rng.normal(0, 1, 3)
            jx, ju = (np.array(j) for j in jac(x0, u0))
            fd_x = np.column_stack([
                (np.array(model.forward_dynamics(x0 + h * e, u0, p)) -
                 np.array(model.forward_dynamics(x0 - h * e, u0, p))).ravel() / (2 * h)
                for e in np.eye(model.n_states)])
            fd_u = np.column_stack([
                (np.array(model.forward_dynamics(x0, u0 + h * e, p)) -
                 np.array(model.forward_dynamics(x0, u0 - h * e, p))).ravel() / (2 * h)
                for e in np.eye(3)])
            assert np.allclose(jx, fd_x, rtol=1e-5, atol=1e-4 * np.abs(jx).max())
            assert np.allclose(ju, fd_u, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("friction", [{}, HARDWARE.flat_values(*MOTOR_FRICTION)],
                         ids=["frictionless", "friction"])
def test_inverse_dynamics_inverts_forward_dynamics(nominal, rng, friction):
    p = nominal.parameter_values(**friction)
    for x0 in random_states(nominal, rng, 10, p):
        current = rng.uniform(-3, 3, 3)
        acc = np.array(nominal.forward_dynamics(x0, current, p)).ravel()[2:4]
        force = np.array(nominal.inverse_dynamics(x0[:2], x0[2:4], acc, p)).ravel()
        a_mat = np.array(nominal.terms(x0[:2], x0[2:4], p)[4])
        assert np.allclose(force, a_mat.T @ (NOMINAL.k_t[0] * current), rtol=1e-10, atol=1e-12)


class ConstrainedModel:
    """The second formulation: all 21 coordinates of eq. (2.1) with 19 holonomic constraints
    and Lagrange multipliers, written from the geometry alone (no use of plant.dynamics)."""

    def __init__(self, prm):
        q, qd = ca.SX.sym("q", 21), ca.SX.sym("qd", 21)
        cons, kinetic, deflections, lower_rates = [], 0, [], []
        for i, angle in enumerate((90, -30, 210)):
            m = prm.r_mount * np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
            xu, yu, ts, xl, yl, te = (q[6 * i + k] for k in range(6))
            vxu, vyu, ws, vxl, vyl, we = (qd[6 * i + k] for k in range(6))
            elbow = m + prm.l_up * ca.vertcat(ca.cos(ts), ca.sin(ts))
            direction = ca.vertcat(ca.cos(ts + te), ca.sin(ts + te))
            cons += [ca.vertcat(xu, yu) - m - prm.c_up[i] * ca.vertcat(ca.cos(ts), ca.sin(ts)),
                     ca.vertcat(xl, yl) - elbow - prm.c_low[i] * direction,
                     q[18:20] - elbow - prm.l_low * direction]
            kinetic += 0.5 * prm.m_up[i] * (vxu**2 + vyu**2)
            kinetic += 0.5 * (prm.j_up[i] + prm.j_rotor[i]) * ws**2
            kinetic += 0.5 * prm.m_low[i] * (vxl**2 + vyl**2) + 0.5 * prm.j_low[i] * (ws + we)**2
            deflections.append((prm.k_s[i], prm.d_s[i], ts, ws))
            deflections.append((prm.k_e[i], prm.d_e[i], te, we))
            deflections.append((prm.k_w[i], prm.d_w[i], ts + te - q[20], ws + we - qd[20]))
            lower_rates.append(ts + te)
        cons.append(q[20] - (lower_rates[0] + lower_rates[1] + lower_rates[2]) / 3)
        kinetic += 0.5 * prm.m_ee * (qd[18]**2 + qd[19]**2) + 0.5 * prm.j_ee * qd[20]**2
        phi = ca.vertcat(*cons)
        q_rest = ca.SX.sym("q_rest", 21)
        rest = ca.substitute(ca.vertcat(*[d[2] for d in deflections]), q, q_rest)
        potential = sum(0.5 * k * (angle - r)**2 for (k, _, angle, _), r in
                        zip(deflections, ca.vertsplit(rest)))
        rayleigh = sum(0.5 * d * rate**2 for _, d, _, rate in deflections)
        tau = ca.SX.sym("tau", 3)
        applied = ca.SX.zeros(21)
        for k, s in enumerate((2, 8, 14)):
            applied[s] = tau[k]
        phi_q = ca.jacobian(phi, q)
        self.phi = ca.Function("phi", [q], [phi])
        self.phi_q = ca.Function("phi_q", [q], [phi_q])
        self.system = ca.Function("kkt", [q, qd, q_rest, tau], [
            ca.hessian(kinetic, qd)[0],
            applied - ca.gradient(potential, q) - ca.gradient(rayleigh, qd)
            + ca.gradient(kinetic, q),  # zero: constant mass matrix
            phi_q, -ca.jtimes(phi_q @ qd, q, qd)])

    def accelerations(self, q, qd, q_rest, tau):
        mass, rhs, phi_q, gamma = (np.array(a) for a in self.system(q, qd, q_rest, tau))
        n, m = 21, phi_q.shape[0]
        kkt = np.block([[mass, phi_q.T], [phi_q, np.zeros((m, m))]])
        return np.linalg.solve(kkt, np.concatenate([rhs.ravel(), gamma.ravel()]))[:n]

    def velocities(self, q, vel):
        """Full velocity from the wrist velocity: constraint rates zero, wrist rate given."""
        phi_q = np.array(self.phi_q(q))
        select = np.zeros((2, 21))
        select[0, 18] = select[1, 19] = 1
        return np.linalg.solve(np.vstack([phi_q, select]), np.concatenate([np.zeros(19), vel]))


def test_minimal_coordinates_agree_with_constrained_21_coordinate_form(nominal, rng):
    p = nominal.parameter_values()
    constrained = ConstrainedModel(NOMINAL)
    q_rest = np.array(nominal.coordinates([0, 0], p)).ravel()
    for x0 in random_states(nominal, rng, 20, p):
        q = np.array(nominal.coordinates(x0[:2], p)).ravel()
        assert np.abs(np.array(constrained.phi(q))).max() < 1e-13  # IK satisfies the constraints
        current = rng.uniform(-4, 4, 3)
        qdd = constrained.accelerations(q, constrained.velocities(q, x0[2:4]), q_rest,
                                        NOMINAL.k_t[0] * current)
        acc = np.array(nominal.forward_dynamics(x0, current, p)).ravel()[2:4]
        assert np.allclose(acc, qdd[18:20], rtol=1e-8, atol=1e-8 * np.abs(acc).max())


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_energy_is_conserved_without_input_damping_or_friction(variant, nominal, hardware):
    model = nominal if variant == "nominal" else hardware
    p = model.parameter_values(**NO_DAMPING, **FRICTION_FREE,
                               **{f"b_viscous{i}": 0.0 for i in (1, 2, 3)})
    x0 = np.array(model.initial_state([0.03, -0.02], p)).ravel()
    x0[2:4] = [0.05, 0.08]
    t_end = 10.0
    times = np.linspace(0, t_end, 201)
    states = simulate(model, x0, p, times)
    energy = np.array([float(model.energy(x, p)) for x in states.T])
    assert np.abs(energy - energy[0]).max() / energy[0] < 1e-6
    assert np.ptp(states[0]) > 0.02  # it really moved


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_power_balance(variant, nominal, hardware, rng):
    """dE/dt = motor power - flexure damping - friction losses, at random states and inputs."""
    model = nominal if variant == "nominal" else hardware
    p = model.parameter_values()
    x = ca.SX.sym("x", model.n_states)
    e_dot = ca.Function("e_dot", [x], [ca.gradient(model.energy(x, p), x)])
    for x0 in random_states(model, rng, 6, p):
        current = rng.uniform(-3, 3, 3)
        xdot = np.array(model.forward_dynamics(x0, current, p)).ravel()
        power = float(np.array(e_dot(x0)).ravel() @ xdot)
        prm = model.variant.parameters
        speed = np.array(model.terms(x0[:2], x0[2:4], p)[4]) @ x0[2:4]
        torque = np.array(prm.k_t) * current
        friction = -(np.array(prm.tau_coulomb) * np.tanh(speed / prm.w_stribeck)
                     + np.array(prm.b_viscous) * speed)
        damping = np.array(model.terms(x0[:2], x0[2:4], p)[3]).ravel() @ x0[2:4]
        if model.n_states > 4:
            damping += prm.d_tool * np.sum(x0[6:8] ** 2)
        expected = float(torque @ speed + friction @ speed - damping)
        assert power == pytest.approx(expected, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_linearized_frequency_matches_free_vibration(variant, nominal, hardware):
    model = nominal if variant == "nominal" else hardware
    p = model.parameter_values(**NO_DAMPING, **FRICTION_FREE)
    frequency, _, vector = modes(model, p)[0]
    x0 = (np.array(model.initial_state([0, 0], p)).ravel()
          + 1e-5 * np.real(vector) / np.abs(vector[:2]).max())
    t = np.linspace(0, 6, 6001)
    k = int(np.argmax(np.abs(x0[:2])))
    signal = simulate(model, x0, p, t, rtol=1e-11, atol=1e-16)[k]
    down = np.flatnonzero((signal[:-1] > 0) & (signal[1:] <= 0))
    exact = t[down] + signal[down] / (signal[down] - signal[down + 1]) * (t[1] - t[0])
    period = np.diff(exact).mean()
    assert 1 / period == pytest.approx(frequency, rel=1e-4)
    if variant == "nominal":
        assert frequency == pytest.approx(1.70, rel=1e-3)  # the thesis's lowest mode
