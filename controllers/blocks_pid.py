"""A PID per axis with tunable gains (built-in "pid-gains"): explicit kp, ki, kd or loop-shaped.

Signals per axis `a` (named after it; controllers.blocks's "pid" has the same, at a fixed shape):
  inputs  a_ref reference, a measured position [position_unit], a_ff feedforward [effort];
  outputs a_effort [effort] commanded effort = saturate(a_fb + a_ff), the label a feedforward
          learns; a_fb [effort] the feedback part;
  parameters (tunable) kp_a, ki_a, kd_a, and with an effort limit effort_limit_a and (with
          back-calculation) tracking_gain_a [1/s].
Per axis, with e = a_ref - a: pid = kp e + I + kd r, where I is the integral term (forward
Euler: I += ki step e) and r the error rate through a first-order filter at
derivative_filter_hz (backward Euler); a_fb = lowpass(notch(pid)), both optional. Anti-windup
with an effort limit: "back-calculation" adds tracking_gain step (a_effort - (a_fb + a_ff)) to I;
"clamp" keeps I within +-effort_limit. The gains come as kp, ki, kd or from loop shaping
(designed_pid: crossover and the axis's mass, as controllers.loop_shaping does).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import casadi as ca
import numpy as np

from flexff.controllers import block_options as opt
from flexff.controllers.block_filters import lowpass, notch, step_symbolic
from flexff.controllers.loop_shaping import (
    NOTCH_ZETA,
    AxisPlant,
    Margins,
    StateSpace,
    from_polynomials,
    loop_margins,
    series,
)
from flexff.fmu.system import Parameter, System, Variable

AntiWindup = Literal["back-calculation", "clamp"]
ANTI_WINDUP: tuple[AntiWindup, ...] = ("back-calculation", "clamp")
LOWPASS_ZETA = 1 / math.sqrt(2)  # Butterworth
DERIVATIVE_FILTER_NYQUIST_FRACTION = 0.2  # default derivative filter: a fifth of Nyquist


@dataclass(frozen=True)
class AxisPid:
    """One axis's gains and filters; None leaves a filter out (the derivative filter: default)."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    derivative_filter_hz: float | None = None
    notch_hz: float | None = None
    notch_zeta: tuple[float, float] = NOTCH_ZETA
    lowpass_hz: float | None = None
    lowpass_zeta: float = LOWPASS_ZETA
    effort_limit: float | None = None
    tracking_gain: float | None = None  # back-calculation [1/s]; None: ki / kp

    def rate_pole(self, step: float) -> float:
        """The derivative filter's discrete pole a: r_k = a r_k-1 + (1 - a)(e_k - e_k-1) / step."""
        hz = self.derivative_filter_hz or DERIVATIVE_FILTER_NYQUIST_FRACTION * 0.5 / step
        if not 0 < hz < 0.5 / step:
            raise opt.OptionError(f"derivative_filter_hz {hz} must lie in (0, {0.5 / step:g}) "
                                  f"Hz, below the Nyquist frequency of the {step} s step")
        time_constant = 1 / (2 * math.pi * hz)
        return time_constant / (time_constant + step)

    def filters(self, step: float) -> dict[str, StateSpace]:
        """Notch then low-pass, those that are on, by name."""
        chain = {}
        if self.notch_hz is not None:
            chain["notch"] = notch(self.notch_hz, self.notch_zeta, step)
        if self.lowpass_hz is not None:
            chain["lowpass"] = lowpass(self.lowpass_hz, self.lowpass_zeta, step)
        return chain

    def default_tracking_gain(self) -> float:
        """1 / Ti = ki / kp (Åström's tracking time Tt = Ti), unless given."""
        if self.tracking_gain is not None:
            return self.tracking_gain
        return self.ki / self.kp if self.kp else 0.0

    def state_space(self, step: float) -> StateSpace:
        """The linear map error -> a_fb (no saturation) as a discrete StateSpace."""
        a = self.rate_pole(step)
        den = np.polymul([1.0, -1.0], [1.0, -a])
        num = np.polyadd(self.kp * den + self.kd * (1 - a) / step * np.array([1.0, -2.0, 1.0]),
                         self.ki * step * np.array([1.0, -a]))
        chain = replace(from_polynomials(num, den), step=step)
        for f in self.filters(step).values():
            chain = series(chain, f)
        return chain

    def margins(self, mass: float, damping: float, step: float) -> Margins:
        """Margins of the loop around a rigid axis of `mass` (ZOH at `step`)."""
        return loop_margins(self.state_space(step), AxisPlant(mass, damping, 0.0))


def designed_pid(crossover_hz: float, mass: float, step: float, damping: float = 0.0,
                 **filters: Any) -> AxisPid:
    """Loop-shaped gains for a rigid axis 1 / (mass s^2 + damping s), as loop_shaping.design_pid:
    kp (1 + s/wd)(1 + wi/s) / (1 + s/wt), wd = wc/3, wt = 3 wc, wi = wc/10, written in parallel
    form (derivative filter at wt) and scaled so the discrete loop crosses 1 at the crossover."""
    if not (crossover_hz > 0 and mass > 0 and damping >= 0):
        raise opt.OptionError(f"crossover_hz ({crossover_hz}) and mass ({mass}) must be "
                              f"positive and damping ({damping}) not negative")
    wc = 2 * math.pi * crossover_hz
    wd, wt, wi = wc / 3, 3 * wc, wc / 10
    proportional = 1 + wi / wd - wi / wt
    unit = AxisPid(kp=proportional, ki=wi, kd=1 / wd - proportional / wt,
                   derivative_filter_hz=wt / (2 * math.pi), **filters)
    plant = AxisPlant(mass, damping, 0.0).discretized(step)
    loop = unit.state_space(step).response(wc)[0] * plant.response(wc)[0]
    scale = 1 / abs(loop)
    return replace(unit, kp=float(scale * unit.kp), ki=float(scale * unit.ki),
                   kd=float(scale * unit.kd))


def _axis_parameters(axis: str, pid: AxisPid, unit: str, position: str,
                     anti_windup: AntiWindup) -> tuple[Parameter, ...]:
    gains = (Parameter(f"kp_{axis}", f"{unit}/{position}", f"proportional gain, {axis} axis",
                       pid.kp),
             Parameter(f"ki_{axis}", f"{unit}/({position}.s)", f"integral gain, {axis} axis",
                       pid.ki),
             Parameter(f"kd_{axis}", f"{unit}.s/{position}", f"derivative gain, {axis} axis",
                       pid.kd))
    if pid.effort_limit is None:
        return gains
    limit = Parameter(f"effort_limit_{axis}", unit, f"largest |effort|, {axis} axis",
                      pid.effort_limit, positive=True)
    if anti_windup == "clamp":
        return (*gains, limit)
    return (*gains, limit, Parameter(f"tracking_gain_{axis}", "1/s", "back-calculation gain "
                                     f"(1 / tracking time), {axis} axis",
                                     pid.default_tracking_gain()))


def _axis_states(axis: str, pid: AxisPid, step: float, unit: str, position: str
                 ) -> tuple[Variable, ...]:
    unit_states = (Variable(f"{axis}_integral", unit, f"integral term, {axis} axis"),
                   Variable(f"{axis}_error_prev", position, f"previous error, {axis} axis"),
                   Variable(f"{axis}_rate", f"{position}/s", f"filtered error rate, {axis} axis"))
    return (*unit_states, *(Variable(f"{axis}_{n}_{k + 1}", "", f"{n} filter state {k + 1}, "
                                     f"{axis} axis")
                            for n, f in pid.filters(step).items() for k in range(f.A.shape[0])))


def pid_system(loops: Mapping[str, AxisPid], step: float,
               anti_windup: AntiWindup = "back-calculation", effort_unit: str = "N",
               position_unit: str = "m") -> System:
    """A discrete PID per axis (keys of `loops`, in order), sampled at `step`."""
    if anti_windup not in ANTI_WINDUP:
        raise opt.OptionError(f"option 'anti_windup' {anti_windup!r}: choose one of "
                              f"{', '.join(ANTI_WINDUP)}")
    if not (step > 0 and math.isfinite(step)):
        raise opt.OptionError(f"step {step} must be a positive number of seconds")
    axes = tuple(loops)
    inputs = tuple(v for a in axes for v in (
        Variable(f"{a}_ref", position_unit, f"reference position, {a} axis"),
        Variable(a, position_unit, f"measured position, {a} axis"),
        Variable(f"{a}_ff", effort_unit, f"feedforward effort, {a} axis")))
    outputs = tuple(v for a in axes for v in (
        Variable(f"{a}_effort", effort_unit, f"commanded effort (feedback + feedforward, "
                 f"saturated), {a} axis"),
        Variable(f"{a}_fb", effort_unit, f"feedback effort, {a} axis")))
    parameters = tuple(p for a in axes for p in _axis_parameters(
        a, loops[a], effort_unit, position_unit, anti_windup))
    states = tuple(s for a in axes for s in _axis_states(a, loops[a], step, effort_unit,
                                                         position_unit))
    x, u = ca.SX.sym("x", len(states)), ca.SX.sym("u", len(inputs))
    p, w = ca.SX.sym("p", len(parameters)), ca.SX.sym("w", 0)
    index = {v.name: k for k, v in enumerate((*inputs, *parameters, *states))}

    def sym(name: str) -> ca.SX:
        k = index[name]
        if k < len(inputs):
            return u[k]
        k -= len(inputs)
        return p[k] if k < len(parameters) else x[k - len(parameters)]

    y, x_next = [], []
    for a in axes:
        pid = loops[a]
        e = sym(f"{a}_ref") - sym(a)
        pole = pid.rate_pole(step)
        rate = pole * sym(f"{a}_rate") + (1 - pole) * (e - sym(f"{a}_error_prev")) / step
        integral = sym(f"{a}_integral")
        fb = sym(f"kp_{a}") * e + integral + sym(f"kd_{a}") * rate
        filter_states = []
        for n, f in pid.filters(step).items():
            state = ca.vertcat(*(sym(f"{a}_{n}_{k + 1}") for k in range(f.A.shape[0])))
            fb, nxt = step_symbolic(f, state, fb)
            filter_states.append(nxt)
        wanted = fb + sym(f"{a}_ff")
        integral_next = integral + sym(f"ki_{a}") * step * e
        effort = wanted
        if pid.effort_limit is not None:
            limit = sym(f"effort_limit_{a}")
            effort = ca.fmin(ca.fmax(wanted, -limit), limit)
            if anti_windup == "clamp":
                integral_next = ca.fmin(ca.fmax(integral_next, -limit), limit)
            else:
                integral_next += sym(f"tracking_gain_{a}") * step * (effort - wanted)
        y += [effort, fb]
        x_next += [integral_next, e, rate, *filter_states]
    design = {a: {"kp": loops[a].kp, "ki": loops[a].ki, "kd": loops[a].kd,
                  "derivative_filter_pole": loops[a].rate_pole(step),
                  "notch_hz": loops[a].notch_hz, "lowpass_hz": loops[a].lowpass_hz}
              for a in axes}
    limited = any(loops[a].effort_limit is not None for a in axes)
    return System(
        name=f"pid_{'_'.join(axes)}",
        description=f"discrete PID per axis ({', '.join(axes)}) with feedforward input"
                    + (f", effort limit and {anti_windup} anti-windup" if limited else ""),
        kind="discrete",
        states=states, inputs=inputs, outputs=outputs, parameters=parameters,
        initial_state=ca.Function("initial_state", [p], [ca.SX.zeros(len(states), 1)]),
        dynamics=ca.Function("dynamics", [x, u, p], [ca.vertcat(*x_next)]),
        output=ca.Function("output", [x, u, p, w], [ca.vertcat(*y)]),
        sample_time=step,
        extra={"design": json.dumps(design)},
    )


def _axis_from_options(options: Mapping[str, Any], axis: str, step: float,
                       values: Mapping[str, float | None]) -> AxisPid:
    zeta = options.get("notch_zeta", NOTCH_ZETA)
    if not (isinstance(zeta, Sequence) and len(zeta) == 2
            and all(isinstance(z, int | float) and not isinstance(z, bool) for z in zeta)):
        raise opt.OptionError(f"option 'notch_zeta' must be two numbers [z1, z2], got {zeta!r}")
    filters: dict[str, Any] = dict(
        notch_hz=values["notch_hz"], notch_zeta=(float(zeta[0]), float(zeta[1])),
        lowpass_hz=values["lowpass_hz"],
        lowpass_zeta=opt.number(options, "lowpass_zeta", LOWPASS_ZETA, positive=True),
        effort_limit=values["effort_limit"], tracking_gain=values["tracking_gain"])
    explicit = [k for k in ("kp", "ki", "kd", "derivative_filter_hz") if values[k] is not None]
    if values["crossover_hz"] is not None:
        if explicit or values["mass"] is None:
            raise opt.OptionError(f"axis {axis!r}: give crossover_hz with mass (and damping), "
                                  "or kp, ki, kd, not both" + (": drop " + ", ".join(explicit)
                                                                if explicit else ""))
        return designed_pid(values["crossover_hz"], values["mass"], step,
                            values["damping"] or 0.0, **filters)
    if values["kp"] is None:
        raise opt.OptionError(f"axis {axis!r} has no gains: give crossover_hz and mass, or kp "
                              "(ki, kd optional)")
    return AxisPid(kp=values["kp"], ki=values["ki"] or 0.0, kd=values["kd"] or 0.0,
                   derivative_filter_hz=values["derivative_filter_hz"], **filters)


def pid_from_options(options: Mapping[str, Any], step: float) -> System:
    """The `pid-gains` block from a configuration's options; per axis (a number, or a table
    {axis = number}):
      crossover_hz [Hz] with mass [effort/(position/s^2)] and damping (default 0): loop-shaped
        gains (designed_pid); or kp, ki (default 0), kd (default 0), derivative_filter_hz
        (default a fifth of Nyquist);
      notch_hz, lowpass_hz [Hz]: the optional filters; effort_limit: the saturation, with
        tracking_gain [1/s] (back-calculation; default ki / kp);
    for all axes: axes (list of names, required), notch_zeta = [z1, z2] (default
    loop_shaping.NOTCH_ZETA), lowpass_zeta (default 1/sqrt(2)), anti_windup =
    "back-calculation" (default) | "clamp", effort_unit (default "N"), position_unit ("m")."""
    opt.check_keys(options, opt.PID_OPTIONS, "pid-gains")
    axes = opt.names(options, "axes")
    positive = {"crossover_hz", "mass", "derivative_filter_hz", "notch_hz", "lowpass_hz",
                "effort_limit"}
    values = {k: opt.per_axis(options, k, axes, positive=k in positive)
              for k in opt.PID_PER_AXIS_OPTIONS}
    if "anti_windup" in options and all(v is None for v in values["effort_limit"].values()):
        raise opt.OptionError("option 'anti_windup' acts at an effort limit: give effort_limit")
    loops = {a: _axis_from_options(options, a, step, {k: v[a] for k, v in values.items()})
             for a in axes}
    return pid_system(loops, step, options.get("anti_windup", "back-calculation"),
                      opt.unit(options, "effort_unit", "N"),
                      opt.unit(options, "position_unit", "m"))
