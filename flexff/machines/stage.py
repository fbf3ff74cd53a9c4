"""A 2-axis gantry stage as a continuous System: coupled axes through the beam's yaw.

The gantry axis (`axes[0]`, default "x") moves the beam (mass_beam, yaw inertia inertia_beam,
held in yaw by yaw_stiffness / yaw_damping); the cross axis (`axes[1]`, default "y") moves the
carriage (mass_carriage) along the beam. The carriage sits at (x - y sin(yaw), y cos(yaw)), so
an x force rotates the beam when the carriage is off centre (coupled inertia, a ~145 Hz yaw
mode): the Lagrangian equations M(q) q'' = Q - (dM/dt) q' + dT/dq - dV/dq in q = (x, y, yaw).
Each axis has viscous and asymmetric Coulomb friction, a force limit and a 1 um encoder.
Signals for axis a: input Fa [N]; outputs a [m] (encoder), a_true [m], va_true [m/s] (the
tool, evaluation only), Fa_applied [N], and yaw [rad]. `parameters(axes)` holds the true values.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import casadi as ca

from flexff.blocks import options as opt
from flexff.fmu.system import Parameter, System, Variable
from flexff.machines.builtins import STAGE_OPTIONS
from flexff.machines.effects import coulomb_friction, encoder, saturated

AXES = ("x", "y")
MAX_SUBSTEP = 1e-4  # RK4 sub-step [s]: resolves the yaw mode and the Coulomb slope
# per axis (gantry, cross): viscous, Coulomb +, Coulomb - (magnitude), force limit
_AXIS_VALUES = ((30.0, 2.0, 1.6, 200.0), (15.0, 0.9, 0.7, 80.0))


def parameters(axes: Sequence[str] = AXES) -> tuple[Parameter, ...]:
    """The stage's parameters, true values as starts, for the axis names `axes`."""
    gantry, cross = axes
    per_axis = tuple(p for a, (viscous, pos, neg, limit) in zip(axes, _AXIS_VALUES) for p in (
        Parameter(f"viscous_{a}", "N.s/m", f"viscous friction, {a} axis", viscous),
        Parameter(f"coulomb_positive_{a}", "N", f"Coulomb friction moving +, {a} axis", pos),
        Parameter(f"coulomb_negative_{a}", "N",
                  f"Coulomb friction moving - (magnitude), {a} axis", neg),
        Parameter(f"force_limit_{a}", "N", f"amplifier force limit, {a} axis", limit, True)))
    return (
        Parameter("mass_beam", "kg", f"beam with the {gantry} carriages", 6.0, True),
        Parameter("mass_carriage", "kg", f"{cross} carriage", 2.0, True),
        Parameter("inertia_beam", "kg.m2", "beam yaw inertia about its centre", 0.18, True),
        Parameter("yaw_stiffness", "N.m/rad", "yaw stiffness of the gantry guides", 1.5e5, True),
        Parameter("yaw_damping", "N.m.s/rad", "yaw damping", 5.0),
        *per_axis,
        Parameter("coulomb_width", "m/s", "velocity over which Coulomb friction turns", 1e-3,
                  True),
        Parameter("encoder", "m", "encoder resolution (both axes); 0: exact", 1e-6),
        Parameter("noise_std", "m", "encoder noise standard deviation", 0.0),
        Parameter(f"{gantry}_start", "m", f"initial {gantry} (at rest)", 0.0, fixed=True),
        Parameter(f"{cross}_start", "m", f"initial {cross} (at rest)", 0.0, fixed=True),
    )


def true_parameters(axes: Sequence[str] = AXES) -> dict[str, float]:
    """The stage's true parameter values by name."""
    return {p.name: p.start for p in parameters(axes)}


def _kinetic_energy(q: ca.SX, qd: ca.SX, v: Mapping[str, ca.SX]) -> ca.SX:
    carriage = ca.vertcat(q[0] - q[1] * ca.sin(q[2]), q[1] * ca.cos(q[2]))
    speed = ca.jacobian(carriage, q) @ qd
    return 0.5 * (v["mass_beam"] * qd[0] ** 2 + v["inertia_beam"] * qd[2] ** 2
                  + v["mass_carriage"] * ca.dot(speed, speed))


def stage_system(axes: Sequence[str] = AXES) -> System:
    """The stage with the signal names of `axes` (gantry axis first)."""
    if len(axes) != 2 or len(set(axes)) != 2:
        raise opt.OptionError(f"option 'axes' must name two distinct axes, got {list(axes)}")
    gantry, cross = axes
    pars = parameters(axes)
    p = ca.SX.sym("p", len(pars))
    v = {par.name: p[k] for k, par in enumerate(pars)}
    state, u, w = ca.SX.sym("state", 6), ca.SX.sym("u", 2), ca.SX.sym("w", 2)
    q, qd = state[:3], state[3:]
    forces = [saturated(u[k], v[f"force_limit_{a}"]) for k, a in enumerate(axes)]
    friction = [-v[f"viscous_{a}"] * qd[k] + coulomb_friction(
        qd[k], v[f"coulomb_positive_{a}"], v[f"coulomb_negative_{a}"], v["coulomb_width"])
        for k, a in enumerate(axes)]
    generalized = ca.vertcat(forces[0] + friction[0], forces[1] + friction[1],
                             -v["yaw_damping"] * qd[2])
    kinetic = _kinetic_energy(q, qd, v)
    potential = 0.5 * v["yaw_stiffness"] * q[2] ** 2
    mass = ca.hessian(kinetic, qd)[0]
    rhs = (generalized - ca.jacobian(mass @ qd, q) @ qd + ca.gradient(kinetic, q)
           - ca.gradient(potential, q))
    tool = ca.vertcat(q[0] - q[1] * ca.sin(q[2]), q[1] * ca.cos(q[2]))
    tool_velocity = ca.jacobian(tool, q) @ qd
    measured = [encoder(q[k], v["encoder"], v["noise_std"], w[k]) for k in range(2)]
    outputs = tuple(o for k, a in enumerate(axes) for o in (
        (Variable(a, "m", f"measured {a} (encoder)"),
          Variable(f"{a}_true", "m", f"true tool {a} (evaluation only)"),
         Variable(f"v{a}_true", "m/s", f"true tool {a} velocity (evaluation only)"),
         Variable(f"F{a}_applied", "N", f"applied (saturated) force, {a} axis"))))
    values = [y for k in range(2) for y in (measured[k], tool[k], tool_velocity[k], forces[k])]
    return System(
        name=f"stage_{gantry}_{cross}",
        description=f"2-axis gantry stage ({gantry} moves the beam, {cross} the carriage on "
                    "it) with yaw compliance, friction, force limits and encoders",
        kind="continuous",
        states=(Variable(f"{gantry}_pos", "m", f"beam position ({gantry})"),
                Variable(f"{cross}_pos", "m", f"carriage position along the beam ({cross})"),
                Variable("yaw_angle", "rad", "beam yaw"),
                Variable(f"{gantry}_vel", "m/s", "beam velocity"),
                Variable(f"{cross}_vel", "m/s", "carriage velocity along the beam"),
                Variable("yaw_rate", "rad/s", "beam yaw rate")),
        inputs=tuple(Variable(f"F{a}", "N", f"commanded force, {a} axis") for a in axes),
        outputs=(*outputs, Variable("yaw", "rad", "beam yaw (evaluation only)")),
        parameters=pars,
        initial_state=ca.Function("initial_state", [p], [ca.vertcat(
            v[f"{gantry}_start"], v[f"{cross}_start"], 0, 0, 0, 0)]),
        dynamics=ca.Function("dynamics", [state, u, p], [ca.vertcat(qd, ca.solve(mass, rhs))]),
        output=ca.Function("output", [state, u, p, w], [ca.vertcat(*values, q[2])]),
        n_noise=2,
        max_substep=MAX_SUBSTEP,
    )


def stage_from_options(options: Mapping[str, Any], step: float) -> System:
    """The `stage` machine from a configuration's options (STAGE_OPTIONS: axes, default
    ["x", "y"]); its physical parameters are FMU parameters, set in `parameters`."""
    opt.check_keys(options, STAGE_OPTIONS, "stage")
    return stage_system(opt.names(options, "axes", AXES))
