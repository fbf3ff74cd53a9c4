"""Measured position from the encoders, and control allocation from forces to motor currents.

The controller only knows the nominal machine: kinematics, actuation Jacobian and torque
constants all come from `plant.parameters.NOMINAL` (numbers folded into the expressions), never
from the true plant. With three motors for two forces, eq. (2.7) with lambda = 0 picks the
torques of least 2-norm: tau = pinv(A^T) F = A (A^T A)^-1 F, with A = d theta_s / d(x, y)
(3x2) evaluated at the measured position.
"""

from __future__ import annotations

import casadi as ca

from flexff.fmu.errors import InputError
from flexff.plant.kinematics import forward_kinematics_2, forward_kinematics_3, shoulder_angles
from flexff.plant.parameters import NOMINAL, PlantParameters

ENCODER_CHOICES = (2, 3)


def measured_position(theta: ca.SX, encoders: int = 2,
                      params: PlantParameters = NOMINAL) -> ca.SX:
    """End-effector position [m] (2x1) from the shoulder encoder angles theta_s1..3 [rad].

    `encoders=2` intersects chains 1 and 2 as the thesis does; `encoders=3` is the
    least-squares fit to all three (less sensitive to quantization).
    """
    if encoders not in ENCODER_CHOICES:
        raise InputError(f"encoders must be one of {ENCODER_CHOICES}, got {encoders!r}")
    if encoders == 2:
        x, y = forward_kinematics_2(params, theta[0], theta[1])
    else:
        x, y = forward_kinematics_3(params, theta)
    position: ca.SX = ca.vertcat(x, y)
    return position


def actuation_jacobian(pos: ca.SX, params: PlantParameters = NOMINAL) -> ca.SX:
    """A(q) = d(theta_s1..3) / d(x, y) at `pos` (3x2): end-effector force = A^T tau."""
    z = ca.SX.sym("z", 2)
    jacobian = ca.jacobian(ca.vertcat(*shoulder_angles(params, z[0], z[1])), z)
    return ca.substitute(jacobian, z, pos)


def allocate_torques(force: ca.SX, pos: ca.SX, params: PlantParameters = NOMINAL) -> ca.SX:
    """Least-norm shoulder torques [N m] (3x1) with A(pos)^T tau = force [N]."""
    a = actuation_jacobian(pos, params)
    return a @ ca.solve(a.T @ a, force)


def motor_currents(force: ca.SX, pos: ca.SX, params: PlantParameters = NOMINAL) -> ca.SX:
    """Motor currents [A] (3x1) that produce `force` at `pos`: allocated torques / k_t."""
    return allocate_torques(force, pos, params) / ca.vertcat(*params.k_t)
