"""The PID block: a discrete PID per axis (blocks.pid_design) in one System, free of any
machine; built-ins "pid" and "pid-gains" (blocks.pid_options).

Signals per axis `a`: inputs a_ref (reference), a (measured position) [position_unit], a_ff
(feedforward) [effort_unit]; outputs a_effort = limit(a_fb + a_ff), the commanded effort (the
label a feedforward learns), and a_fb, the feedback part: the PID's output (parallel form) or
a_effort - a_ff (series form; the same until the limit). Tunable parameters: kp_a, ki_a, kd_a
(parallel form) or kp_a, a scale of the loop-shaped controller (series form); with an effort
limit effort_limit_a and, with back-calculation, tracking_gain_a [1/s]. Anti-windup, while the
effort is at its limit: "conditional" holds the integrator (in the series form, whose states
mix the terms, every controller state) while the error drives the effort further;
"back-calculation" adds tracking_gain step (a_effort - (a_fb + a_ff)) to the integral;
"clamp" keeps the integral within +-effort_limit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict
from typing import Any

import casadi as ca

from flexff.blocks.filters import step_symbolic
from flexff.blocks.options import OptionError
from flexff.blocks.pid_design import AxisPid
from flexff.fmu.system import Parameter, System, Variable

Symbol = Callable[[str], ca.SX]


def _parameters(a: str, axis: AxisPid, step: float) -> tuple[Parameter, ...]:
    unit, position = axis.effort_unit, axis.position_unit
    if axis.form == "series":
        gains: tuple[Parameter, ...] = (
            Parameter(f"kp_{a}", "1", f"gain scaling axis {a}'s feedback", 1.0),)
    else:
        g = axis.parallel_gains(step)
        gains = (Parameter(f"kp_{a}", f"{unit}/{position}", f"proportional gain, {a} axis", g.kp),
                 Parameter(f"ki_{a}", f"{unit}/({position}.s)", f"integral gain, {a} axis", g.ki),
                 Parameter(f"kd_{a}", f"{unit}.s/{position}", f"derivative gain, {a} axis", g.kd))
    if axis.effort_limit is None:
        return gains
    limit = Parameter(f"effort_limit_{a}", unit, f"largest |effort|, {a} axis",
                      axis.effort_limit, positive=True)
    if axis.windup != "back-calculation":
        return (*gains, limit)
    return (*gains, limit, Parameter(f"tracking_gain_{a}", "1/s", "back-calculation gain "
                                     f"(1 / tracking time), {a} axis",
                                     axis.tracking(step)))


def _states(a: str, axis: AxisPid, step: float) -> tuple[Variable, ...]:
    if axis.form == "series":
        return tuple(Variable(f"{a}_pid{k}", "", f"PID state {k} of axis {a}")
                     for k in range(axis.series_controller(step).A.shape[0]))
    unit, position = axis.effort_unit, axis.position_unit
    terms = (Variable(f"{a}_integral", unit, f"integral term, {a} axis"),
             Variable(f"{a}_error_prev", position, f"previous error, {a} axis"),
             Variable(f"{a}_rate", f"{position}/s", f"filtered error rate, {a} axis"))
    return (*terms, *(Variable(f"{a}_{n}_{k + 1}", "", f"{n} filter state {k + 1}, {a} axis")
                      for n, f in axis.filters(step).items() for k in range(f.A.shape[0])))


def _axis(a: str, axis: AxisPid, step: float, sym: Symbol, states: tuple[Variable, ...]
          ) -> tuple[list[ca.SX], list[ca.SX]]:
    """The axis's outputs [a_effort, a_fb] and its next states."""
    e, feedforward = sym(f"{a}_ref") - sym(a), sym(f"{a}_ff")
    others: list[ca.SX] = []
    if axis.form == "series":  # the whole state acts as the integrator
        integral = ca.vertcat(*(sym(s.name) for s in states))
        out, integral_next = step_symbolic(axis.series_controller(step), integral, e)
        fb = sym(f"kp_{a}") * out
    else:
        pole = axis.parallel_gains(step).rate_pole(step)
        rate = pole * sym(f"{a}_rate") + (1 - pole) * (e - sym(f"{a}_error_prev")) / step
        integral = sym(f"{a}_integral")
        fb = sym(f"kp_{a}") * e + integral + sym(f"kd_{a}") * rate
        others += [e, rate]
        for n, f in axis.filters(step).items():
            fb, following = step_symbolic(f, ca.vertcat(*(sym(f"{a}_{n}_{k + 1}")
                                                          for k in range(f.A.shape[0]))), fb)
            others.append(following)
        integral_next = integral + sym(f"ki_{a}") * step * e
    wanted = fb + feedforward
    effort = wanted
    if axis.effort_limit is not None:
        limit = sym(f"effort_limit_{a}")
        effort = ca.fmin(ca.fmax(wanted, -limit), limit)
        if axis.windup == "conditional":
            winding = ca.logic_and(ca.fabs(wanted) > limit, wanted * e > 0)
            integral_next = ca.if_else(winding, integral, integral_next)
        elif axis.windup == "clamp":
            integral_next = ca.fmin(ca.fmax(integral_next, -limit), limit)
        else:
            integral_next += sym(f"tracking_gain_{a}") * step * (effort - wanted)
    feedback = effort - feedforward if axis.form == "series" else fb
    return [effort, feedback], [integral_next, *others]


def pid_system(axes: Mapping[str, AxisPid], step: float) -> System:
    """A discrete PID per axis (the keys of `axes`, in order), sampled at `step`."""
    if not axes:
        raise OptionError("option 'axes' is empty: the PID needs at least one axis")
    if not (step > 0 and math.isfinite(step)):
        raise OptionError(f"step {step} must be a positive number of seconds")
    names = tuple(axes)
    inputs = tuple(v for a in names for v in (
        Variable(f"{a}_ref", axes[a].position_unit, f"reference position, {a} axis"),
        Variable(a, axes[a].position_unit, f"measured position, {a} axis"),
        Variable(f"{a}_ff", axes[a].effort_unit, f"feedforward effort, {a} axis")))
    outputs = tuple(v for a in names for v in (
        Variable(f"{a}_effort", axes[a].effort_unit, f"commanded effort (feedback + "
                 f"feedforward, limited), {a} axis"),
        Variable(f"{a}_fb", axes[a].effort_unit, f"feedback effort, {a} axis")))
    parameters = tuple(p for a in names for p in _parameters(a, axes[a], step))
    states = {a: _states(a, axes[a], step) for a in names}
    flat = tuple(s for a in names for s in states[a])
    x, u = ca.SX.sym("x", len(flat)), ca.SX.sym("u", len(inputs))
    p, w = ca.SX.sym("p", len(parameters)), ca.SX.sym("w", 0)
    index = {v.name: k for k, v in enumerate((*inputs, *parameters, *flat))}

    def sym(name: str) -> ca.SX:
        k = index[name]
        if k < len(inputs):
            return u[k]
        k -= len(inputs)
        return p[k] if k < len(parameters) else x[k - len(parameters)]

    y, x_next = [], []
    for a in names:
        out, following = _axis(a, axes[a], step, sym, states[a])
        y += out
        x_next += following
    limited = sorted({axes[a].windup for a in names if axes[a].effort_limit is not None})
    return System(
        name=f"pid_{'_'.join(names)}",
        description=f"discrete PID per axis ({', '.join(names)}) at {step:g} s with feedforward "
                    "input" + (f", effort limit and {' / '.join(limited)} anti-windup"
                               if limited else ""),
        kind="discrete", states=flat, inputs=inputs, outputs=outputs, parameters=parameters,
        initial_state=ca.Function("initial_state", [p], [ca.SX.zeros(len(flat), 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [ca.vertcat(*x_next)]),
        output=ca.Function("output", [x, u, p, w], [ca.vertcat(*y)]),
        sample_time=step,
        extra={"design": json.dumps({a: _design(axes[a], step) for a in names})})


def _design(axis: AxisPid, step: float) -> dict[str, Any]:
    """The axis's design numbers for the FMU's annotation."""
    numbers: dict[str, Any] = {"form": axis.form, "notch_hz": axis.notch_hz,
                               "lowpass_hz": axis.lowpass_hz}
    if axis.form == "series":
        return {**numbers, **asdict(axis.gains)}
    g = axis.parallel_gains(step)
    return {**numbers, "kp": g.kp, "ki": g.ki, "kd": g.kd,
            "derivative_filter_pole": g.rate_pole(step)}
