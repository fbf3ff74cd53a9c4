"""The plant as CasADi Functions of (state, currents, parameters), per variant.

`nominal` is the ideal model the controllers are designed on: rotors rigid on the arms, no
friction, no noise. `hardware` stands in for the real machine: mismatched parameters, motor
friction, a compliant rotor-to-arm coupling (a parasitic resonance; three rotor angles and
speeds join the state) and encoder noise. Friction acts at the shoulder joints. Each effect
is a parameter: zero friction or noise switches it off; the coupling is structural
(`parasitic_mode`).
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from flexff.plant.actuator import encoder_reading, friction_torque, motor_torque
from flexff.plant.dynamics import reduced_dynamics
from flexff.plant.kinematics import (
    flexure_deflections,
    forward_kinematics_2,
    forward_kinematics_3,
    generalized_coordinates,
    shoulder_angles,
)
from flexff.plant.parameters import NOMINAL, PlantParameters
from flexff.plant.signals import CURRENTS, ENCODERS, TORQUES, TRUE_POSITION, TRUE_VELOCITY
from flexff.plant.variants import Variant, get_variant


class PlantModel:
    """Symbolic plant of one variant; every Function takes the flat parameter vector last.

    Functions (inputs -> outputs):
      forward_dynamics (x, i, p) -> dx/dt         output (x, i, p, w) -> y
      inverse_dynamics (pos, vel, acc, p) -> F    terms (pos, vel, p) -> M, C, Q, D, A
      energy (x, p) -> E                          coordinates (pos, p) -> q (21)
      fk2 (theta_s1..2, p) -> pos                 fk3 (theta_s1..3, p) -> pos
      initial_state (pos, p) -> x (at rest)
    """

    def __init__(self, variant: Variant | str = "nominal") -> None:
        self.variant = get_variant(variant) if isinstance(variant, str) else variant
        self.p = ca.vertcat(*[ca.SX.sym(n) for n in PlantParameters.names()])
        self.params = PlantParameters.from_vector(self.p)
        self.rigid = reduced_dynamics(self.params)

    # -- signals ------------------------------------------------------------------------------
    @property
    def state_names(self) -> list[str]:
        names = ["q_x", "q_y", "qd_x", "qd_y"]
        if self.variant.parasitic_mode:
            names += ["tool_dx", "tool_dy", "tool_vx", "tool_vy"]
        return names

    inputs = CURRENTS
    outputs = (*ENCODERS, *TRUE_POSITION, *TRUE_VELOCITY, *TORQUES)  # in the order of `output`

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    def parameter_values(self, **overrides: float) -> np.ndarray:
        """Flat numeric parameter vector of this variant, with validated overrides by name."""
        return np.array(self.variant.parameters.with_values(**overrides).vector())

    # -- symbolic building blocks -------------------------------------------------------------
    @cached_property
    def _x(self) -> ca.SX:
        return ca.SX.sym("x", self.n_states)

    @cached_property
    def _i(self) -> ca.SX:
        return ca.SX.sym("i", 3)

    def _substitute_state(self, expr: ca.SX) -> ca.SX:
        """Express terms written in (pos, vel) of the reduced dynamics in the state symbols."""
        dyn = self.rigid
        return ca.substitute(expr, ca.vertcat(dyn.pos, dyn.vel), self._x[:4])

    def _tool(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Tool deflection from the wrist, its rate, and the force the mount puts on the wrist."""
        pp, x = self.params, self._x
        deflection, rate = x[4:6], x[6:8]
        return deflection, rate, pp.k_tool * deflection + pp.d_tool * rate

    # -- Functions ----------------------------------------------------------------------------
    @cached_property
    def forward_dynamics(self) -> ca.Function:
        pp, x, i, dyn = self.params, self._x, self._i, self.rigid
        torque = motor_torque(pp, i) + friction_torque(pp, dyn.A @ dyn.vel)
        force = dyn.A.T @ torque
        if not self.variant.parasitic_mode:
            rhs = ca.vertcat(x[2:4], self._substitute_state(dyn.acceleration(force)))
        else:
            _, rate, mount = self._tool()
            acc = self._substitute_state(dyn.acceleration(force + mount))
            rhs = ca.vertcat(x[2:4], acc, rate, -mount / pp.m_tool - acc)
        return ca.Function("forward_dynamics", [x, i, self.p], [rhs],
                           ["x", "i", "p"], ["xdot"])

    @cached_property
    def output(self) -> ca.Function:
        pp, x, i = self.params, self._x, self._i
        noise = ca.SX.sym("w", 3)
        rotation = self._substitute_state(
            flexure_deflections(pp, self.rigid.pos[0], self.rigid.pos[1])[:3])
        home = ca.vertcat(*shoulder_angles(pp, 0.0, 0.0))
        theta = ca.vertcat(*[encoder_reading(pp, rotation[k], home[k], noise[k])
                             for k in range(3)])
        y = ca.vertcat(theta, x[0:4], motor_torque(pp, i))
        return ca.Function("output", [x, i, self.p, noise], [y], ["x", "i", "p", "w"], ["y"])

    @cached_property
    def initial_state(self) -> ca.Function:
        """The state at rest at wrist position pos (tool undeflected)."""
        pos = ca.SX.sym("pos", 2)
        x0 = ca.vertcat(pos, ca.SX.zeros(self.n_states - 2))
        return ca.Function("initial_state", [pos, self.p], [x0], ["pos", "p"], ["x0"])

    @cached_property
    def inverse_dynamics(self) -> ca.Function:
        """(pos, vel, acc, p) -> the end-effector force [N] to command for that motion: the
        force the motors must give (`required_force`) as the controller must command it
        (`commanded`)."""
        dyn, acc = self.rigid, ca.SX.sym("acc", 2)
        force = self.required_force(dyn.pos, dyn.vel, acc, self.p)
        return ca.Function("inverse_dynamics", [dyn.pos, dyn.vel, acc, self.p],
                           [self.commanded(dyn.pos, force, self.p)],
                           ["pos", "vel", "acc", "p"], ["F"])

    @cached_property
    def required_force(self) -> ca.Function:
        """Eq. (2.4) plus motor friction: the end-effector force [N] the motors must give for
        position, velocity, acceleration (rigid model), linear in the inertias, flexures and
        frictions. The motors' own friction torque is mapped through A^T, as in
        `forward_dynamics`; the nominal parameters have none."""
        pp, dyn, acc = self.params, self.rigid, ca.SX.sym("acc", 2)
        force = dyn.inverse(acc) - dyn.A.T @ friction_torque(pp, dyn.A @ dyn.vel)
        return ca.Function("required_force", [dyn.pos, dyn.vel, acc, self.p], [force],
                           ["pos", "vel", "acc", "p"], ["F"])

    @cached_property
    def commanded(self) -> ca.Function:
        """(pos, F, p) -> the force to command [N] for the motors to give F at pos. The
        controller shares a commanded force among the motors by the nominal torque constants
        (controllers.allocation), so the motors give A^T G A (A^T A)^-1 times it, G the
        torque constants over the nominal ones: the force to command is (A^T A)
        (A^T G A)^-1 F, F itself where G = I."""
        dyn, force = self.rigid, ca.SX.sym("F", 2)
        a, gain = dyn.A, ca.diag(ca.vertcat(*self.params.k_t) / ca.DM(NOMINAL.k_t))
        return ca.Function("commanded", [dyn.pos, force, self.p],
                           [a.T @ a @ _inverse_2x2(a.T @ gain @ a) @ force],
                           ["pos", "F", "p"], ["F_commanded"])

    @cached_property
    def terms(self) -> ca.Function:
        dyn = self.rigid
        return ca.Function("terms", [dyn.pos, dyn.vel, self.p],
                           [dyn.M, dyn.C, dyn.Q, dyn.D, dyn.A],
                           ["pos", "vel", "p"], ["M", "C", "Q", "D", "A"])

    @cached_property
    def energy(self) -> ca.Function:
        """Total mechanical energy [J]: bodies, rotors, flexures (and the tool and its mount)."""
        dyn = self.rigid
        energy = self._substitute_state(dyn.kinetic + dyn.potential)
        if self.variant.parasitic_mode:
            pp, (deflection, rate, _) = self.params, self._tool()
            tool_speed = self._x[2:4] + rate
            energy += 0.5 * pp.m_tool * ca.sumsqr(tool_speed)
            energy += 0.5 * pp.k_tool * ca.sumsqr(deflection)
        return ca.Function("energy", [self._x, self.p], [energy], ["x", "p"], ["E"])

    @cached_property
    def coordinates(self) -> ca.Function:
        pos = ca.SX.sym("pos", 2)
        return ca.Function("coordinates", [pos, self.p],
                           [generalized_coordinates(self.params, pos[0], pos[1])],
                           ["pos", "p"], ["q"])

    @cached_property
    def fk2(self) -> ca.Function:
        theta = ca.SX.sym("theta", 2)
        pos = ca.vertcat(*forward_kinematics_2(self.params, theta[0], theta[1]))
        return ca.Function("fk2", [theta, self.p], [pos], ["theta", "p"], ["pos"])

    @cached_property
    def fk3(self) -> ca.Function:
        theta = ca.SX.sym("theta", 3)
        pos = ca.vertcat(*forward_kinematics_3(self.params, theta))
        return ca.Function("fk3", [theta, self.p], [pos], ["theta", "p"], ["pos"])


def _inverse_2x2(m: ca.SX) -> ca.SX:
    """The inverse of a 2x2 matrix by its adjugate: plain arithmetic, which every target of
    the generated model (C, PyTorch) evaluates alike."""
    determinant = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    inverse: ca.SX = ca.vertcat(ca.horzcat(m[1, 1], -m[0, 1]),
                                ca.horzcat(-m[1, 0], m[0, 0])) / determinant
    return inverse

