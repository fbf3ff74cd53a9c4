"""Lagrangian dynamics of the manipulator in the minimal coordinates (x_ee, y_ee).

Kinetic energy of the seven rigid bodies plus the flexures' potential energy, written in the 21
coordinates of eq. (2.1) and reduced through the inverse kinematics q = phi(x_ee, y_ee) (the
minimal-coordinate formulation the thesis adopts). Euler-Lagrange then gives eqs. (2.2)-(2.4):

    M(q) qdd + C(q, qd) qd + Q(q) + D(q, qd) = A(q)^T tau

with D the flexures' (Rayleigh) damping and A = d theta_s / d(x_ee, y_ee), so that A^T maps the
three shoulder torques to end-effector forces (eq. 2.3). All Jacobians come from CasADi's
algorithmic differentiation.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from flexff.plant.kinematics import (
    EE_INDEX,
    ELBOW_INDEX,
    N_COORDINATES,
    SHOULDER_INDEX,
    flexure_deflections,
    generalized_coordinates,
)
from flexff.plant.parameters import PlantParameters


def body_mass_matrix(p: PlantParameters) -> ca.SX:
    """Constant 21x21 mass matrix: T = 1/2 qd^T M21 qd for the coordinates of eq. (2.1).

    Arm positions are centres of mass; the lower arm turns at theta_s + theta_e, which couples
    the two angles. The motor rotor turns rigidly with the upper arm (direct drive).
    """
    m = ca.SX.zeros(N_COORDINATES, N_COORDINATES)
    for i, (s, e) in enumerate(zip(SHOULDER_INDEX, ELBOW_INDEX)):
        for k in (s - 2, s - 1):
            m[k, k] = p.m_up[i]
        for k in (e - 2, e - 1):
            m[k, k] = p.m_low[i]
        m[s, s] = p.j_up[i] + p.j_rotor[i]
        lower = ca.SX.zeros(1, N_COORDINATES)
        lower[s], lower[e] = 1, 1  # angular velocity of the lower arm
        m += p.j_low[i] * (lower.T @ lower)
    x, y, th = EE_INDEX
    m[x, x], m[y, y], m[th, th] = p.m_ee, p.m_ee, p.j_ee
    return m


def flexure_stiffness(p: PlantParameters) -> ca.SX | ca.DM:
    """The nine flexure stiffnesses: SX for symbolic parameters, DM for numbers."""
    return ca.vertcat(*p.k_s, *p.k_e, *p.k_w)


def flexure_damping(p: PlantParameters) -> ca.SX | ca.DM:
    """The nine flexure dampings: SX for symbolic parameters, DM for numbers."""
    return ca.vertcat(*p.d_s, *p.d_e, *p.d_w)


@dataclass(frozen=True)
class ReducedDynamics:
    """Symbolic terms of eq. (2.2) in pos = (x_ee, y_ee), vel = d pos / dt and parameters."""

    pos: ca.SX
    vel: ca.SX
    M: ca.SX  # mass matrix, 2x2
    C: ca.SX  # Coriolis matrix J^T M21 dJ/dt (so dM/dt - 2C is skew), 2x2
    coriolis: ca.SX  # C @ vel, formed as J^T M21 (dJ/dt vel): one directional derivative
    Q: ca.SX  # flexure stiffness force dV/dpos, 2
    D: ca.SX  # flexure damping force dR/dvel, 2
    A: ca.SX  # d theta_s / d pos, 3x2: end-effector force = A^T tau
    kinetic: ca.SX
    potential: ca.SX

    def inverse(self, acc: ca.SX) -> ca.SX:
        """Eq. (2.4) with flexure damping: the end-effector force for pos, vel, acc."""
        return self.M @ acc + self.coriolis + self.Q + self.D

    def acceleration(self, force: ca.SX) -> ca.SX:
        """Eq. (2.2) solved for the acceleration under an end-effector force."""
        return ca.solve(self.M, force - self.coriolis - self.Q - self.D)


def reduced_dynamics(p: PlantParameters) -> ReducedDynamics:
    """Euler-Lagrange on the reduced kinetic and potential energy."""
    pos, vel = ca.SX.sym("pos", 2), ca.SX.sym("vel", 2)
    q = generalized_coordinates(p, pos[0], pos[1])
    jac = ca.jacobian(q, pos)
    body_mass = body_mass_matrix(p)
    mass = jac.T @ body_mass @ jac
    deflection = flexure_deflections(p, pos[0], pos[1])
    potential = 0.5 * ca.dot(flexure_stiffness(p), deflection**2)
    deflection_rate = ca.jtimes(deflection, pos, vel)
    rayleigh = 0.5 * ca.dot(flexure_damping(p), deflection_rate**2)
    return ReducedDynamics(
        pos=pos, vel=vel, M=mass, C=jac.T @ body_mass @ ca.jtimes(jac, pos, vel),
        coriolis=jac.T @ (body_mass @ ca.jtimes(jac @ vel, pos, vel)),
        Q=ca.gradient(potential, pos), D=ca.gradient(rayleigh, vel),
        A=ca.jacobian(ca.vertcat(*[q[s] for s in SHOULDER_INDEX]), pos),
        kinetic=0.5 * vel.T @ mass @ vel, potential=potential,
    )
