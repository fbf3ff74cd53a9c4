"""A 1-axis linear drive as a continuous System: a motor carriage driven by the effort `F`
[N] (limited to +-force_limit), viscous and one-sided Coulomb friction (smooth over
coulomb_width), a cogging force of the magnet pitch, and a load on a spring-damper mount (a
resonance); the encoder reads the carriage in steps of `encoder` metres, with optional white
noise. Effects a user's prior rarely holds, each off at its default 0 (the example
machines/examples/drive-rough.toml sets them): Stribeck friction, Coulomb friction that
varies along the travel, a motor force ripple of its own period, a cable carrier's linear and
cubic spring, and the current loop's first-order lag between the command and the force
(state F_motor). Outputs: the measured position `x`, and for evaluation only the true
carriage position `x_true`, its velocity `v_true` and the load's position `x_load`.

The numbers are a small linear-motor stage's (DRIVE: 2 kg moving, 250 Hz mount, 1 um
encoder); every one is a tunable FMU parameter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import casadi as ca

from flexff.fmu.errors import InputError
from flexff.fmu.system import Parameter, System, Variable
from flexff.machines.effects import encoder


@dataclass(frozen=True)
class DriveParameters:
    """The drive's physics [SI]."""

    m_motor: float = 1.6  # carriage and coil [kg]
    m_load: float = 0.4  # load on the mount [kg]
    mount_hz: float = 250.0  # the load's resonance on its mount (carriage held) [Hz]
    mount_damping: float = 0.02  # its damping ratio
    viscous: float = 20.0  # [N s/m]
    coulomb_positive: float = 1.5  # friction while moving forward [N]
    coulomb_negative: float = 1.2  # friction while moving back [N]
    coulomb_width: float = 1e-3  # velocity over which the friction turns [m/s]
    cogging: float = 0.5  # amplitude of the cogging force [N]
    pitch: float = 0.016  # the magnets' pitch [m]
    force_limit: float = 200.0  # the amplifier's limit [N]
    encoder: float = 1e-6  # encoder resolution [m]; 0: exact
    noise_std: float = 0.0  # white measurement noise [m]
    stribeck: float = 0.0  # the friction's excess at low speed [N] (Stribeck)
    stribeck_velocity: float = 0.01  # the speed over which that excess falls away [m/s]
    friction_ripple: float = 0.0  # Coulomb friction varying along the travel, its peak [N]
    friction_period: float = 0.037  # that variation's period [m]
    force_ripple: float = 0.0  # the motor force's relative ripple [1]
    ripple_pitch: float = 0.023  # its period [m]
    spring: float = 0.0  # a cable carrier's stiffness about x = 0 [N/m]
    spring_cubic: float = 0.0  # its cubic stiffness [N/m^3]
    current_lag: float = 0.0  # the current loop's time constant [s]; 0: none

    @property
    def mass(self) -> float:
        """The moving mass below the mount's resonance [kg]."""
        return self.m_motor + self.m_load


DRIVE = DriveParameters()
UNITS = {"m_motor": "kg", "m_load": "kg", "mount_hz": "Hz", "mount_damping": "1",
         "viscous": "N.s/m", "coulomb_positive": "N", "coulomb_negative": "N",
         "coulomb_width": "m/s", "cogging": "N", "pitch": "m", "force_limit": "N",
         "encoder": "m", "noise_std": "m", "stribeck": "N", "stribeck_velocity": "m/s",
         "friction_ripple": "N", "friction_period": "m", "force_ripple": "1",
         "ripple_pitch": "m", "spring": "N/m", "spring_cubic": "N/m3", "current_lag": "s"}
POSITIVE = ("m_motor", "m_load", "mount_hz", "coulomb_width", "pitch", "force_limit",
            "stribeck_velocity", "friction_period", "ripple_pitch")


def effort_of(p: Any, position: Any, velocity: Any, acceleration: Any, backend: Any = ca) -> Any:
    """The rigid drive's inverse dynamics (the mount's load moving with the carriage, the
    current loop's lag left out): the effort a feedforward needs, for tests and as the truth
    identification is checked against."""
    needed = (p.mass * acceleration + friction(p, position, velocity, backend)
              + p.cogging * backend.sin(2 * math.pi * position / p.pitch)
              + p.spring * position + p.spring_cubic * position**3)
    return needed / (1 + p.force_ripple * backend.sin(2 * math.pi * position / p.ripple_pitch))


def friction(p: Any, position: Any, velocity: Any, backend: Any = ca) -> Any:
    """Viscous, one-sided Coulomb, Stribeck and position-dependent friction [N]."""
    tanh = backend.tanh(velocity / p.coulomb_width)
    stribeck = p.stribeck * backend.exp(-(velocity / p.stribeck_velocity) ** 2)
    along = p.friction_ripple * 0.5 * (1 + backend.sin(2 * math.pi * position
                                                       / p.friction_period))
    return p.viscous * velocity + coulomb(p, velocity, backend) + (stribeck + along) * tanh


def coulomb(p: Any, velocity: Any, backend: Any = ca) -> Any:
    """One-sided Coulomb friction, smooth over coulomb_width and zero at rest: the positive
    level moving forward, minus the negative one moving back."""
    tanh = backend.tanh(velocity / p.coulomb_width)
    return 0.5 * (p.coulomb_positive * (tanh + tanh**2) + p.coulomb_negative * (tanh - tanh**2))


def drive_system(parameters: DriveParameters = DRIVE, x_start: float = 0.0) -> System:
    """The drive as a continuous System, every physical parameter tunable."""
    names = list(asdict(parameters))
    p = ca.SX.sym("p", len(names) + 1)
    q = DriveParameters(*(p[k] for k in range(len(names))))  # type: ignore[arg-type]
    start = p[len(names)]
    x = ca.SX.sym("x", 5)  # carriage position, velocity, load position, velocity, motor force
    force = ca.SX.sym("F")
    w = ca.SX.sym("w")
    position, velocity, load, load_velocity, motor = (x[k] for k in range(5))
    stiffness = q.m_load * (2 * math.pi * q.mount_hz) ** 2
    damping = 2 * q.mount_damping * q.m_load * 2 * math.pi * q.mount_hz
    mount = stiffness * (position - load) + damping * (velocity - load_velocity)
    commanded = ca.fmin(ca.fmax(force, -q.force_limit), q.force_limit)
    lagging = q.current_lag > 0
    applied = ca.if_else(lagging, motor, commanded) \
        * (1 + q.force_ripple * ca.sin(2 * math.pi * position / q.ripple_pitch))
    cogging = q.cogging * ca.sin(2 * math.pi * position / q.pitch)
    spring = q.spring * position + q.spring_cubic * position**3
    acceleration = (applied - friction(q, position, velocity) - cogging - spring
                    - mount) / q.m_motor
    motor_rate = ca.if_else(lagging, (commanded - motor) / ca.fmax(q.current_lag, 1e-12), 0)
    dx = ca.vertcat(velocity, acceleration, load_velocity, mount / q.m_load, motor_rate)
    measured = encoder(position, q.encoder, q.noise_std, w)
    return System(
        name="drive",
        description="1-axis linear drive: mass, viscous and one-sided Coulomb friction, "
                    "cogging, a load on a resonant mount, effort limit, encoder; optional "
                    "Stribeck and position-dependent friction, force ripple, a cable "
                    "carrier's spring and a current loop's lag",
        kind="continuous",
        states=(Variable("x_carriage", "m"), Variable("v_carriage", "m/s"),
                Variable("x_mount", "m"), Variable("v_mount", "m/s"),
                Variable("F_motor", "N", "the force the current loop gives")),
        inputs=(Variable("F", "N", "commanded force"),),
        outputs=(Variable("x", "m", "measured position (encoder)"),
                 Variable("x_true", "m", "true carriage position (evaluation only)"),
                 Variable("v_true", "m/s", "true carriage velocity (evaluation only)"),
                 Variable("x_load", "m", "load position")),
        parameters=(*(Parameter(n, UNITS[n], n.replace("_", " "), float(getattr(parameters, n)),
                                positive=n in POSITIVE) for n in names),
                    Parameter("x_start", "m", "initial position (at rest)", x_start, fixed=True)),
        initial_state=ca.Function("initial_state", [p], [ca.vertcat(start, 0, start, 0, 0)]),
        dynamics=ca.Function("dynamics", [x, force, p], [dx]),
        output=ca.Function("output", [x, force, p, w],
                           [ca.vertcat(measured, position, velocity, load)]),
        n_noise=1,
        max_substep=1e-4,
    )


def drive_from_options(options: Mapping[str, Any], step: float) -> System:
    """The drive of a configuration's options (none: the FMU's parameters set the physics)."""
    if options:
        raise InputError(f"{sorted(options)[0]}: the drive has no options; set its physics as "
                         f"parameters")
    return drive_system()
