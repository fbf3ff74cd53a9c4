"""One axis of the PID block: its gains, filters and effort limit, and its linear controller.

Gains are explicit (`Gains`: kp, ki, kd, derivative filter) or loop-shaped (`LoopShape`: a
crossover around the rigid axis 1 / (mass s^2 + damping s + stiffness)). Two discrete forms:
  parallel  kp e + I + kd r (I by forward Euler, r the error rate through a first-order filter by
            backward Euler), then the notch and the low-pass; loop-shaped gains are converted to
            this form and scaled so the discrete loop crosses 1 at the crossover;
  series    loop-shaped gains only: blocks.loop_shaping's design_pid (series form, notch
            included, Tustin at the crossover), then the low-pass, one state space.
The form sets the defaults: anti-windup conditional integration (series) or back-calculation
(parallel), a first-order (series) or second-order Butterworth (parallel) low-pass.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from flexff.blocks.filters import lowpass, notch
from flexff.blocks.loop_shaping import (
    NOTCH_ZETA,
    AxisPlant,
    Margins,
    StateSpace,
    design_pid,
    from_polynomials,
    loop_margins,
    series,
)
from flexff.blocks.options import OptionError

Form = Literal["series", "parallel"]
AntiWindup = Literal["conditional", "back-calculation", "clamp"]
DERIVATIVE_FILTER_NYQUIST_FRACTION = 0.2  # default derivative filter: a fifth of Nyquist


@dataclass(frozen=True)
class Gains:
    """Explicit parallel-form gains; the derivative filter defaults to a fifth of Nyquist."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    derivative_filter_hz: float | None = None

    def rate_pole(self, step: float) -> float:
        """The derivative filter's discrete pole a: r_k = a r_k-1 + (1 - a)(e_k - e_k-1) / step."""
        hz = self.derivative_filter_hz or DERIVATIVE_FILTER_NYQUIST_FRACTION * 0.5 / step
        if not 0 < hz < 0.5 / step:
            raise OptionError(f"derivative_filter_hz {hz} must lie in (0, {0.5 / step:g}) Hz, "
                              f"below the Nyquist frequency of the {step} s step")
        time_constant = 1 / (2 * math.pi * hz)
        return time_constant / (time_constant + step)


@dataclass(frozen=True)
class LoopShape:
    """Loop-shaping target: the crossover [Hz] around the axis's mass, damping and stiffness."""

    crossover_hz: float
    mass: float
    damping: float = 0.0
    stiffness: float = 0.0

    def __post_init__(self) -> None:
        if not (self.crossover_hz > 0 and self.mass > 0 and self.damping >= 0
                and self.stiffness >= 0):
            raise OptionError(f"crossover_hz ({self.crossover_hz}) and mass ({self.mass}) must "
                              f"be positive, damping ({self.damping}) and stiffness "
                              f"({self.stiffness}) not negative")

    @property
    def plant(self) -> AxisPlant:
        return AxisPlant(self.mass, self.damping, self.stiffness)


@dataclass(frozen=True)
class AxisPid:
    """One axis: gains, form, filters (None: off), effort limit (None: none) and anti-windup
    (None: the form's default), units. Refuses combinations its form cannot run."""

    gains: Gains | LoopShape
    form: Form = "parallel"
    notch_hz: float | None = None
    notch_zeta: tuple[float, float] = NOTCH_ZETA
    lowpass_hz: float | None = None
    lowpass_order: int | None = None  # None: the form's default
    lowpass_zeta: float | None = None  # second order only; None: Butterworth
    effort_limit: float | None = None
    anti_windup: AntiWindup | None = None
    tracking_gain: float | None = None  # back-calculation [1/s]; None: ki / kp
    position_unit: str = "m"
    effort_unit: str = "N"

    def __post_init__(self) -> None:
        if self.form == "series" and not isinstance(self.gains, LoopShape):
            raise OptionError("option 'form' \"series\" takes loop-shaped gains (crossover_hz, "
                              "mass): give form = \"parallel\" for kp, ki, kd")
        if self.form == "series" and self.windup != "conditional":
            raise OptionError(f"option 'anti_windup' {self.windup!r} needs form = \"parallel\":"
                              " the series form has no integrator state of its own")
        if self.tracking_gain is not None and self.windup != "back-calculation":
            raise OptionError("option 'tracking_gain' acts with anti_windup = "
                              "\"back-calculation\" only: drop it")
        if self.lowpass_zeta is not None and self.order != 2:
            raise OptionError("option 'lowpass_zeta' shapes a second-order low-pass: give "
                              "lowpass_order = 2 or drop it")

    @property
    def windup(self) -> AntiWindup:
        """The anti-windup in force (at an effort limit)."""
        return self.anti_windup or ("conditional" if self.form == "series"
                                    else "back-calculation")

    @property
    def order(self) -> int:
        """The low-pass's order in force."""
        return self.lowpass_order or (1 if self.form == "series" else 2)

    def tracking(self, step: float) -> float:
        """The back-calculation gain: as given, else 1 / Ti = ki / kp (Åström's Tt = Ti)."""
        if self.tracking_gain is not None:
            return self.tracking_gain
        gains = self.parallel_gains(step)
        return gains.ki / gains.kp if gains.kp else 0.0

    def filters(self, step: float) -> dict[str, StateSpace]:
        """The parallel form's notch then low-pass, those that are on, by name."""
        chain = {}
        if self.notch_hz is not None:
            chain["notch"] = notch(self.notch_hz, self.notch_zeta, step)
        if self.lowpass_hz is not None:
            chain["lowpass"] = self._lowpass(self.lowpass_hz, step)
        return chain

    def _lowpass(self, hz: float, step: float) -> StateSpace:
        return lowpass(hz, step, self.order, self.lowpass_zeta)

    def parallel_gains(self, step: float) -> Gains:
        """The parallel form's gains: as given, or loop-shaped (as loop_shaping.design_pid,
        kp (1 + s/wd)(1 + wi/s) / (1 + s/wt), wd = wc/3, wt = 3 wc, wi = wc/10, written in
        parallel form with the derivative filter at wt and scaled so that the discrete loop,
        filters included, crosses 1 at wc)."""
        if isinstance(self.gains, Gains):
            return self.gains
        wc = 2 * math.pi * self.gains.crossover_hz
        wd, wt, wi = wc / 3, 3 * wc, wc / 10
        proportional = 1 + wi / wd - wi / wt
        unit = replace(self, gains=Gains(proportional, wi, 1 / wd - proportional / wt,
                                         wt / (2 * math.pi)))
        plant = self.gains.plant.discretized(step)
        scale = 1 / abs(unit.state_space(step).response(wc)[0] * plant.response(wc)[0])
        return Gains(float(scale * proportional), float(scale * wi),
                     float(scale * (1 / wd - proportional / wt)), wt / (2 * math.pi))

    def series_controller(self, step: float) -> StateSpace:
        """The series form's controller from error to feedback, at unit scale."""
        assert isinstance(self.gains, LoopShape)
        controller = _series_design(self.gains, self.notch_hz, self.notch_zeta, step)
        if self.lowpass_hz is None:
            return controller
        return series(controller, self._lowpass(self.lowpass_hz, step))

    def state_space(self, step: float) -> StateSpace:
        """The linear map error -> feedback (no limit) as a discrete StateSpace."""
        if self.form == "series":
            return self.series_controller(step)
        gains = self.parallel_gains(step)
        a = gains.rate_pole(step)
        den = np.polymul([1.0, -1.0], [1.0, -a])
        num = np.polyadd(gains.kp * den + gains.kd * (1 - a) / step * np.array([1.0, -2.0, 1.0]),
                         gains.ki * step * np.array([1.0, -a]))
        chain = replace(from_polynomials(num, den), step=step)
        for f in self.filters(step).values():
            chain = series(chain, f)
        return chain

    def margins(self, step: float, plant: AxisPlant | None = None) -> Margins:
        """Margins of the loop around `plant` (default: the loop shape's) under ZOH at `step`."""
        if plant is None:
            if not isinstance(self.gains, LoopShape):
                raise OptionError("explicit gains have no plant of their own: pass one")
            plant = self.gains.plant
        return loop_margins(self.state_space(step), plant)


@functools.lru_cache(maxsize=64)
def _series_design(shape: LoopShape, notch_hz: float | None, notch_zeta: tuple[float, float],
                   step: float) -> StateSpace:
    """design_pid's discrete controller (its margins cost tens of ms: a block asks thrice)."""
    return design_pid(shape.crossover_hz, step, notch_hz, notch_zeta, plant=shape.plant).discrete
