"""Generic loop blocks as discrete Systems, free of any machine: a PID per axis (loop-shaped on
the axis's mass, optional notch and low-pass, anti-windup), a summing junction and a gain.

PID signals per axis `a`: inputs `a_ref` (reference position), `a` (measured position),
`a_ff` (feedforward effort, added after the PID); outputs `a_effort` (the commanded effort,
feedback plus feedforward, limited to +-effort_limit: the labels a feedforward learns) and
`a_fb` (its feedback part). Each axis's controller is controllers.loop_shaping's design for a
mass (damper, spring) plant, discretised at the run's step; the tunable parameter `kp_a`
scales its output. Anti-windup: while the effort is at its limit and the error drives it
further, the controller's states hold (conditional integration).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from flexff.controllers.loop_shaping import (
    AxisPlant,
    StateSpace,
    design_pid,
    from_polynomials,
    series,
    tustin,
)
from flexff.fmu.errors import InputError
from flexff.fmu.system import Parameter, System, Variable


@dataclass(frozen=True)
class AxisLoop:
    """One axis's feedback: the plant seen from the effort (mass, damping, stiffness), the
    crossover, an optional notch and output low-pass [Hz] and the effort limit (None: none)."""

    name: str
    mass: float
    crossover_hz: float
    damping: float = 0.0
    stiffness: float = 0.0
    notch_hz: float | None = None
    lowpass_hz: float | None = None
    effort_limit: float | None = None
    unit: str = "m"
    effort_unit: str = "N"

    def controller(self, step: float) -> StateSpace:
        """The discrete controller from error to feedback effort."""
        if not self.mass > 0:
            raise InputError(f"axis {self.name}: the mass must be positive, got {self.mass}")
        pid = design_pid(self.crossover_hz, step, self.notch_hz,
                         plant=AxisPlant(self.mass, self.damping, self.stiffness)).discrete
        if self.lowpass_hz is None:
            return pid
        if not 0 < self.lowpass_hz < 0.5 / step:
            raise InputError(f"axis {self.name}: low-pass {self.lowpass_hz} Hz must lie below "
                             f"the Nyquist frequency {0.5 / step:g} Hz")
        w = 2 * math.pi * self.lowpass_hz
        return series(pid, tustin(from_polynomials(np.array([w]), np.array([1.0, w])), step, w))


def pid_system(axes: Sequence[AxisLoop], step: float) -> System:
    """A PID per axis in one discrete System sampled at `step`."""
    if not axes:
        raise InputError("the PID needs at least one axis")
    names = [a.name for a in axes]
    if len(set(names)) != len(names):
        raise InputError(f"axis names repeat: {names}")
    inputs, outputs, states, parameters = [], [], [], []
    updates, efforts, feedbacks = [], [], []
    for axis in axes:
        n = axis.name
        inputs += [Variable(f"{n}_ref", axis.unit, f"reference position of axis {n}"),
                   Variable(n, axis.unit, f"measured position of axis {n}"),
                   Variable(f"{n}_ff", axis.effort_unit, f"feedforward effort of axis {n}")]
        outputs += [Variable(f"{n}_effort", axis.effort_unit,
                             f"commanded effort of axis {n} (feedback plus feedforward)"),
                    Variable(f"{n}_fb", axis.effort_unit, f"feedback effort of axis {n}")]
        parameters.append(Parameter(f"kp_{n}", "1", f"gain scaling axis {n}'s feedback", 1.0))
        ss = axis.controller(step)
        states += [Variable(f"{n}_pid{k}", "", f"PID state {k} of axis {n}")
                   for k in range(ss.A.shape[0])]
    x = ca.SX.sym("x", len(states))
    u = ca.SX.sym("u", len(inputs))
    p = ca.SX.sym("p", len(parameters))
    offset = 0
    for k, axis in enumerate(axes):
        ss = axis.controller(step)
        size = ss.A.shape[0]
        state = x[offset:offset + size]
        offset += size
        reference, measured, feedforward = u[3 * k], u[3 * k + 1], u[3 * k + 2]
        error = reference - measured
        feedback = p[k] * (ca.mtimes(ca.DM(ss.C), state) + float(ss.D[0, 0]) * error)
        effort = feedback + feedforward
        advance = ca.mtimes(ca.DM(ss.A), state) + ca.DM(ss.B) * error
        if axis.effort_limit is not None:
            limit = float(axis.effort_limit)
            limited = ca.fmin(ca.fmax(effort, -limit), limit)
            winding = ca.logic_and(ca.fabs(effort) > limit, effort * error > 0)
            advance = ca.if_else(winding, state, advance)
            effort = limited
        updates.append(advance)
        efforts.append(effort)
        feedbacks.append(effort - feedforward)
    w = ca.SX.sym("w", 0)
    out = ca.vertcat(*(v for pair in zip(efforts, feedbacks) for v in pair))
    return System(
        name="pid", description=f"PID per axis ({', '.join(names)}), loop-shaped, discrete at "
                                f"{step:g} s, with anti-windup",
        kind="discrete", states=tuple(states), inputs=tuple(inputs), outputs=tuple(outputs),
        parameters=tuple(parameters),
        initial_state=ca.Function("initial_state", [p], [ca.DM.zeros(len(states))]),
        dynamics=ca.Function("dynamics", [x, u, p], [ca.vertcat(*updates)]),
        output=ca.Function("output", [x, u, p, w], [out]),
        sample_time=step)


def pid_from_options(options: Mapping[str, Any], step: float) -> System:
    """The PID of a configuration's options: {"axes": [{name, mass, crossover_hz, ...}]}."""
    tables = options.get("axes")
    if not isinstance(tables, list) or not tables:
        raise InputError("axes: give each axis as a table {name, mass, crossover_hz, ...}")
    fields = AxisLoop.__dataclass_fields__
    axes = []
    for k, table in enumerate(tables):
        unknown = sorted(set(table) - set(fields))
        if unknown:
            raise InputError(f"axes[{k}].{unknown[0]}: unknown key (known: {', '.join(fields)})")
        try:
            axes.append(AxisLoop(**table))
        except TypeError as error:
            raise InputError(f"axes[{k}]: {error}") from None
    return pid_system(axes, step)

