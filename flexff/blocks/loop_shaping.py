"""PID (+ notch) design for one axis by loop shaping, and the margins of the resulting loop.

The axis is a mass-spring-damper P(s) = 1 / (m s^2 + d s + k) from force to position (a
machine gives its own: the manipulator's at its workspace centre, controllers.axis_plant). It
gets the usual mechatronic PID

    C(s) = kp (1 + s/wd) / (1 + s/wt) (1 + wi/s),   wd = wc/3, wt = 3 wc, wi = wc/10,

with kp such that |C(j wc) P(j wc)| = 1 (notch included): the tamed derivative puts its most
phase lead at the crossover wc and the integrator acts a decade below. An optional notch
suppresses a parasitic mode. Both parts are discretized by Tustin with prewarping (the PID at
wc, the notch at its centre), so the discrete controller matches the continuous one exactly
where it matters most.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.signal import cont2discrete, tf2ss

from flexff.fmu.errors import InputError

# notch damping ratios (numerator, denominator): -28 dB deep, a few Hz wide at 40 Hz
NOTCH_ZETA = (0.02, 0.5)


@dataclass(frozen=True)
class StateSpace:
    """SISO state-space model x' = A x + B u, y = C x + D u; `step` None means continuous."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    step: float | None = None

    def response(self, w: float | np.ndarray) -> np.ndarray:
        """Complex frequency response at angular frequencies w [rad/s] (z = exp(j w step))."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        points = 1j * w if self.step is None else np.exp(1j * w * self.step)
        pencil = points[:, None, None] * np.eye(self.A.shape[0]) - self.A
        values: np.ndarray = (self.C @ np.linalg.solve(pencil, self.B))[:, 0, 0] + self.D[0, 0]
        return values


@dataclass(frozen=True)
class AxisPlant:
    """One axis at the centre: P(s) = 1 / (mass s^2 + damping s + stiffness), force to position."""

    mass: float
    damping: float
    stiffness: float

    def state_space(self) -> StateSpace:
        a = np.array([[0.0, 1.0], [-self.stiffness / self.mass, -self.damping / self.mass]])
        return StateSpace(a, np.array([[0.0], [1.0 / self.mass]]), np.array([[1.0, 0.0]]),
                          np.zeros((1, 1)))

    def discretized(self, step: float) -> StateSpace:
        """Zero-order-hold equivalent: the force is held over each sample step."""
        ss = self.state_space()
        a, b, c, d, _ = cont2discrete((ss.A, ss.B, ss.C, ss.D), step, method="zoh")
        return StateSpace(a, b, c, d, step)


@dataclass(frozen=True)
class Margins:
    """Stability margins of an open loop L = C P.

    `crossover_hz` is the highest gain crossover (the bandwidth). `phase_margin_deg` is the
    smallest angle by which L misses the negative real axis at any gain crossover (the usual
    180 + arg L at the bandwidth; the lower crossovers near the mode sit far from it). A loop
    around a lightly damped mode below crossover may be conditionally stable, so there are two
    gain margins: `gain_margin_db` (how much the gain may rise, from the phase crossovers where
    |L| < 1; inf if none) and `lower_gain_margin_db` (how much it may fall, negative; -inf if
    there is no such limit).
    """

    crossover_hz: float
    phase_margin_deg: float
    gain_margin_db: float
    lower_gain_margin_db: float


@dataclass(frozen=True)
class PIDDesign:
    """One axis's controller (PID times optional notch), continuous and discrete, with numbers.

    Frequencies are in rad/s, except `crossover_hz` (the requested one) and `notch_hz`.
    `margins` are those of the discrete loop with the zero-order-hold plant.
    """

    crossover_hz: float
    step: float
    kp: float
    wd: float
    wt: float
    wi: float
    notch_hz: float | None
    notch_zeta: tuple[float, float] | None
    plant: AxisPlant
    continuous: StateSpace
    discrete: StateSpace
    margins: Margins

    def summary(self) -> dict[str, float]:
        """The design numbers as plain floats (notch frequency 0 when there is none)."""
        return {
            "kp": self.kp, "wd": self.wd, "wt": self.wt, "wi": self.wi,
            "requested_crossover_hz": self.crossover_hz,
            "notch_hz": self.notch_hz or 0.0,
            "crossover_hz": self.margins.crossover_hz,
            "phase_margin_deg": self.margins.phase_margin_deg,
            "gain_margin_db": self.margins.gain_margin_db,
            "lower_gain_margin_db": self.margins.lower_gain_margin_db,
        }


def series(first: StateSpace, second: StateSpace) -> StateSpace:
    """`first` followed by `second` (same time domain); states of `first` come first."""
    a = np.block([[first.A, np.zeros((first.A.shape[0], second.A.shape[0]))],
                  [second.B @ first.C, second.A]])
    b = np.vstack([first.B, second.B @ first.D])
    c = np.hstack([second.D @ first.C, second.C])
    return StateSpace(a, b, c, second.D @ first.D, first.step)


def from_polynomials(numerator: np.ndarray, denominator: np.ndarray) -> StateSpace:
    a, b, c, d = tf2ss(numerator, denominator)
    return StateSpace(a, b, c, d)


def tustin(ss: StateSpace, step: float, prewarp: float) -> StateSpace:
    """Bilinear map s = w0 / tan(w0 step / 2) (z - 1)/(z + 1): exact response at w0.

    That is plain Tustin with the fictitious step 2 tan(w0 step / 2) / w0.
    """
    fictitious = 2 * math.tan(prewarp * step / 2) / prewarp
    a, b, c, d, _ = cont2discrete((ss.A, ss.B, ss.C, ss.D), fictitious, method="bilinear")
    return StateSpace(a, b, c, d, step)


def _pid_polynomials(kp: float, wd: float, wt: float, wi: float) -> tuple[np.ndarray, np.ndarray]:
    """kp (1 + s/wd)(s + wi) / (s (1 + s/wt)) as numerator and denominator in s."""
    return kp * np.polymul([1 / wd, 1], [1, wi]), np.polymul([1 / wt, 1], [1, 0])


def _notch(wn: float, zeta: tuple[float, float]) -> StateSpace:
    """(s^2 + 2 z1 wn s + wn^2) / (s^2 + 2 z2 wn s + wn^2): depth z1/z2 at wn, unity elsewhere."""
    z1, z2 = zeta
    if not 0 <= z1 < z2:
        raise InputError(f"notch damping ratios {zeta} must satisfy 0 <= z1 < z2")
    return from_polynomials(np.array([1, 2 * z1 * wn, wn**2]), np.array([1, 2 * z2 * wn, wn**2]))


def design_pid(crossover_hz: float, step: float, notch_hz: float | None = None,
               notch_zeta: tuple[float, float] = NOTCH_ZETA, *,
               plant: AxisPlant) -> PIDDesign:
    """Loop-shaped PID (and notch) for the axis `plant` with crossover `crossover_hz`, sampled
    at `step`."""
    if not (crossover_hz > 0 and step > 0 and math.isfinite(crossover_hz + step)):
        raise InputError(f"crossover ({crossover_hz} Hz) and step ({step} s) must be positive")
    nyquist_hz = 0.5 / step
    for what, f in (("crossover", crossover_hz), ("notch", notch_hz)):
        if f is not None and not 0 < f < nyquist_hz:
            raise InputError(f"{what} frequency {f} Hz must lie in (0, {nyquist_hz:g}) Hz, "
                             f"below the Nyquist frequency of the {step} s step")
    wc = 2 * math.pi * crossover_hz
    wd, wt, wi = wc / 3, 3 * wc, wc / 10
    notch = _notch(2 * math.pi * notch_hz, notch_zeta) if notch_hz is not None else None
    loop = (from_polynomials(*_pid_polynomials(1.0, wd, wt, wi)).response(wc)[0]
            * plant.state_space().response(wc)[0])
    if notch is not None:
        loop *= notch.response(wc)[0]
    kp = float(1.0 / abs(loop))
    pid = from_polynomials(*_pid_polynomials(kp, wd, wt, wi))
    continuous, discrete = pid, tustin(pid, step, wc)
    if notch is not None and notch_hz is not None:
        continuous = series(pid, notch)
        discrete = series(discrete, tustin(notch, step, 2 * math.pi * notch_hz))
    return PIDDesign(
        crossover_hz=crossover_hz, step=step, kp=kp, wd=wd, wt=wt, wi=wi, notch_hz=notch_hz,
        notch_zeta=(notch_zeta[0], notch_zeta[1]) if notch_hz is not None else None, plant=plant,
        continuous=continuous, discrete=discrete,
        margins=loop_margins(discrete, plant))


def loop_margins(controller: StateSpace, plant: AxisPlant, points: int = 20000) -> Margins:
    """Crossover, phase margin and gain margins of the loop controller * plant.

    A discrete controller is closed around the zero-order-hold plant at its step (frequencies
    up to Nyquist); a continuous one around P(s). Crossings are bracketed on a log grid of
    `points` frequencies from 1 mHz and refined by root finding.
    """
    if controller.step is None:
        plant_ss, top = plant.state_space(), 1e4 * math.sqrt(plant.stiffness / plant.mass)
    else:
        plant_ss, top = plant.discretized(controller.step), math.pi / controller.step * 0.999999

    def loop(w: float) -> complex:
        return complex(controller.response(w)[0] * plant_ss.response(w)[0])

    grid = np.geomspace(2 * math.pi * 1e-3, top, points)
    values = controller.response(grid) * plant_ss.response(grid)
    gain_crossings = _roots(lambda w: math.log(abs(loop(w))), grid, np.log(np.abs(values)))
    if not gain_crossings:
        raise ValueError("the loop gain never crosses 1: no crossover")
    phase_margins = [abs(math.degrees(np.angle(-loop(w)))) for w in gain_crossings]
    phase_crossings = [w for w in _roots(lambda w: loop(w).imag, grid, values.imag)
                       if loop(w).real < 0]
    factors = [1.0 / abs(loop(w)) for w in phase_crossings]
    upper = [f for f in factors if f > 1]
    lower = [f for f in factors if f < 1]
    return Margins(
        crossover_hz=max(gain_crossings) / (2 * math.pi),
        phase_margin_deg=min(phase_margins),
        gain_margin_db=20 * math.log10(min(upper)) if upper else math.inf,
        lower_gain_margin_db=20 * math.log10(max(lower)) if lower else -math.inf)


def _roots(f: Callable[[float], float], grid: np.ndarray, values: np.ndarray) -> list[float]:
    """Roots of f between grid points where the sampled `values` change sign."""
    changes = np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)[0]
    return [brentq(f, grid[k], grid[k + 1], xtol=1e-12, rtol=1e-14) for k in changes]
