"""Motor, amplifier and encoder models: what lies between the controller's numbers and the arm."""

from __future__ import annotations

import math
from typing import Any

import casadi as ca

from flexff.plant.parameters import PlantParameters


def saturated_current(p: PlantParameters, current: Any) -> Any:
    """The amplifier delivers the commanded current clipped to +-i_max [A]."""
    return ca.fmin(ca.fmax(current, -p.i_max), p.i_max)


def motor_torque(p: PlantParameters, current: Any) -> ca.SX:
    """Shoulder torques [N m] = torque constant * saturated current, per motor."""
    torques: ca.SX = ca.vertcat(*[p.k_t[i] * saturated_current(p, current[i]) for i in range(3)])
    return torques


def friction_torque(p: PlantParameters, speed: Any) -> ca.SX:
    """Motor friction [N m] opposing the rotor speed: smooth Coulomb (tanh) plus viscous.

    The tanh keeps the right-hand side smooth for fixed-step RK4; w_stribeck sets how sharp.
    """
    torques: ca.SX = ca.vertcat(*[
        -p.tau_coulomb[i] * ca.tanh(speed[i] / p.w_stribeck) - p.b_viscous[i] * speed[i]
        for i in range(3)])
    return torques


def encoder_resolution(p: PlantParameters) -> Any:
    """Angle of one encoder count [rad]."""
    return 2 * math.pi / p.encoder_counts


def encoder_reading(p: PlantParameters, rotation: Any, home: Any, noise: Any) -> Any:
    """Encoder angle [rad]: the home angle plus the rotation from home, counted in whole
    counts when `encoder_quantization` is on (> 0.5), exact when it is off.

    The incremental encoder is zeroed at the home pose (wrist at the centre); `noise` is a
    standard normal sample, scaled by noise_std and added before counting.
    """
    resolution = encoder_resolution(p)
    measured = rotation + p.noise_std * noise
    counted = resolution * ca.floor(measured / resolution + 0.5)
    return home + ca.if_else(p.encoder_quantization > 0.5, counted, measured)
