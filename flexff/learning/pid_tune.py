"""`flexff tune LOOP`: the PID block's loop shape (`mass`, `damping`, `crossover_hz` per axis)
from each axis's plant measured in the loop, for a stated phase margin.

Each axis is measured on its own in the loop as it is (PID closed, the other axes held where
the plant rests, feedforward zero): its reference sweeps a logarithmic chirp up to `high_hz`
about its rest, as large as the description's limits allow. Effort and measured motion,
low-passed alike, give its rigid model by least squares (effort = mass a + damping v +
Coulomb tanh(v / w) + offset), the effort's lead searched: beyond the zero-order hold's half
sample it is the plant's delay (a current loop's lag). The proposal is the highest crossover
up to `high_hz` whose loop, the block loop-shaped on that model, keeps the phase margin and
GAIN_MARGIN_DB around the model with its delay. TOML: the block's table with the proposal,
and `[tune]`, what was measured.

Docs: "Tune the PID block" (docs/how-to/tune-pid.md).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import tomli_w

from flexff.blocks.loop_shaping import AxisPlant, Margins, StateSpace, loop_margins
from flexff.blocks.pid_design import AxisPid, Form, LoopShape
from flexff.blocks.pid_options import axes_from_options
from flexff.cosim.config import checked
from flexff.cosim.csv_text import TIME
from flexff.cosim.machine import Axis, Machine
from flexff.cosim.recording import Recording, atomic_write
from flexff.cosim.run import simulate_config
from flexff.cosim.schema import FmuConfig, RunConfig
from flexff.fmu.errors import InputError, RunError
from flexff.learning.machine_features import lagged
from flexff.learning.machine_loop import loop_machine, on_references, record_signals
from flexff.learning.signal_processing import differentiate, lowpass

PHASE_MARGIN_DEG = 40.0  # the default margin asked for
GAIN_MARGIN_DB = 6.0  # the least gain margin a proposal keeps
SETTLE_S = 1.0  # at rest before the chirp: the loop settles, left out of the fit
FADE_S = 1.0  # the chirp's amplitude fades in over this long
LOW_HZ = 0.5  # the chirp's lowest frequency
HIGH_SHARE = 0.05  # the default highest frequency: this share of the loop's rate
FIT_CORNER = 4.0  # the fit's low-pass corner: this many times the chirp's highest frequency
RANGE_SHARE = 0.25  # the chirp's largest amplitude: this share of the axis's range
MAX_LEAD = 20  # the longest lead searched [samples]
CROSSOVERS = 24  # crossovers tried from LOW_HZ to high_hz (log-spaced)
PID_BUILTINS = {"pid": "series", "pid-gains": "parallel"}  # built-in -> its default form


@dataclass(frozen=True)
class AxisTuning:
    """One axis: its identified rigid model, the proposed crossover and the loop's margins
    around the identified model with the proposal (None: no crossover has them)."""

    axis: str
    block_axis: str  # the axis's name in the PID block
    mass: float
    damping: float
    coulomb: float
    offset: float
    delay_s: float
    fit_error: float  # ||effort - model|| / ||effort|| over the fitted samples
    crossover_hz: float | None
    margins: Margins | None

    def to_dict(self) -> dict[str, Any]:
        return {"mass": self.mass, "damping": self.damping, "coulomb": self.coulomb,
                "offset": self.offset, "delay_s": self.delay_s, "fit_error": self.fit_error,
                **({} if self.crossover_hz is None or self.margins is None else {
                    "crossover_hz": self.crossover_hz,
                    "phase_margin_deg": self.margins.phase_margin_deg,
                    "gain_margin_db": self.margins.gain_margin_db})}


@dataclass(frozen=True)
class Tuning:
    """Every axis's tuning, the PID block it is for (None: the loop has none of flexff's) and
    the margin asked for."""

    block: FmuConfig | None
    phase_margin_deg: float
    high_hz: float
    axes: list[AxisTuning]


@dataclass(frozen=True)
class _Delayed(StateSpace):
    """A controller followed by a pure delay [s] (the plant's, beyond the zero-order hold)."""

    delay: float = 0.0

    def response(self, w: float | np.ndarray) -> np.ndarray:
        w = np.atleast_1d(np.asarray(w, dtype=float))
        return super().response(w) * np.exp(-1j * w * self.delay)


def tune_loop(loop: RunConfig, phase_margin_deg: float = PHASE_MARGIN_DEG,
              seconds: float = 8.0, high_hz: float | None = None) -> Tuning:
    """Measure each axis of `loop` with a chirp of `seconds` up to `high_hz` (default
    HIGH_SHARE of the rate), fit its rigid model and propose its crossover for
    `phase_margin_deg`."""
    machine = loop_machine(loop)
    rate_hz = 1.0 / loop.step
    high = HIGH_SHARE * rate_hz if high_hz is None else high_hz
    if not LOW_HZ < high < rate_hz / (2 * FIT_CORNER):
        raise InputError(f"high_hz {high!r}: the chirp's highest frequency must lie above "
                         f"{LOW_HZ:g} Hz and below {rate_hz / (2 * FIT_CORNER):g} Hz (the rate "
                         f"over {2 * FIT_CORNER:g})")
    if not 0 < phase_margin_deg < 90:
        raise InputError(f"phase margin {phase_margin_deg!r}: expected degrees between 0 "
                         f"and 90 (40 to 60 is usual)")
    if not seconds >= 2.0:
        raise InputError(f"seconds {seconds!r}: the chirp needs at least 2 s")
    block = _pid_block(loop, machine)
    designs, names = _block_axes(loop, block, machine)
    rest = _rest(loop, machine)
    axes = []
    for axis in machine.axes:
        signals = _measure(loop, machine, axis, rest, seconds, high)
        fit = _fit(signals, axis, rate_hz, high)
        crossover, margins = _proposal(designs[axis.name], fit, loop.step, phase_margin_deg,
                                       high)
        axes.append(AxisTuning(axis.name, names[axis.name], *fit, crossover, margins))
    return Tuning(block, phase_margin_deg, high, axes)


def proposed_options(tuning: Tuning) -> dict[str, Any]:
    """The PID block's options with each axis's proposal (mass, damping, crossover_hz) in
    place of its gains and stiffness (the model has none), in the block's own layout (axis
    tables, or {axis = value} tables); a fresh "pid" block's where the loop has none."""
    proposed = {a.block_axis: {"mass": a.mass, "damping": a.damping,
                               "crossover_hz": a.crossover_hz}
                for a in tuning.axes if a.crossover_hz is not None}
    replaced = ("kp", "ki", "kd", "derivative_filter_hz", "stiffness")  # by the proposal
    if tuning.block is None:
        return {"builtin": "pid", "axes": [{"name": n, **v} for n, v in proposed.items()]}
    options: dict[str, Any] = {"builtin": tuning.block.builtin, **tuning.block.options}
    tables = options.get("axes")
    if isinstance(tables, list) and any(isinstance(t, dict) for t in tables):
        options["axes"] = [{**{k: v for k, v in t.items() if k not in replaced},
                            **proposed[t["name"]]} if t.get("name") in proposed else t
                           for t in tables]
        return options
    names = [str(n) for n in tables or ()]
    for key in (*replaced, "mass", "damping", "crossover_hz"):
        given = options.pop(key, None)
        values = dict(given) if isinstance(given, dict) else \
            {} if given is None else dict.fromkeys(names, given)
        values = {n: v for n, v in values.items() if n not in proposed}
        if key not in replaced:
            values |= {n: p[key] for n, p in proposed.items()}
        if values:
            options[key] = values
    return options


def tuning_toml(tuning: Tuning, origin: str) -> str:
    """The proposal as TOML: the PID block's table to put in the loop, then what was
    measured (`[tune]`)."""
    block = tuning.block.name if tuning.block is not None else "pid"
    tune = {"phase_margin_deg": tuning.phase_margin_deg, "gain_margin_db": GAIN_MARGIN_DB,
            "highest_hz": tuning.high_hz, "axis": {a.axis: a.to_dict() for a in tuning.axes}}
    head = (f"# flexff tune {origin}: each axis's plant measured in the loop, the PID block's "
            f"loop shape for a {tuning.phase_margin_deg:g} deg phase margin\n# (replace the "
            f"loop's [fmu.{block}] with this one{'' if tuning.block else ', and connect it'})\n")
    return head + tomli_w.dumps({"fmu": {block: proposed_options(tuning)}, "tune": tune})


def write_tuning(tuning: Tuning, path: str | Path, origin: str) -> Path:
    text = tuning_toml(tuning, origin)
    return atomic_write(Path(path), lambda tmp: tmp.write_text(text, "utf-8"))


def tuned_loop(loop: RunConfig, tuning: Tuning) -> RunConfig:
    """`loop` with its PID block's options as proposed (a loop without flexff's PID block:
    InputError)."""
    if tuning.block is None:
        raise InputError("the loop has no PID block of flexff's to tune: add one (builtin = "
                         "\"pid\") with the proposed options")
    options = {k: v for k, v in proposed_options(tuning).items() if k != "builtin"}
    name = tuning.block.name
    return checked(replace(loop, fmus=tuple(replace(f, options=options) if f.name == name else f
                                            for f in loop.fmus)))


def tuning_table(tuning: Tuning) -> str:
    """A plain-text table: one row per axis."""
    rows = [f"{'axis':<6} {'mass':>10} {'damping':>10} {'delay ms':>9} {'fit %':>7} "
            f"{'crossover Hz':>13} {'PM deg':>7} {'GM dB':>6}"]
    for a in tuning.axes:
        proposal = (f"{a.crossover_hz:13.3g} {a.margins.phase_margin_deg:7.1f} "
                    f"{a.margins.gain_margin_db:6.1f}"
                    if a.crossover_hz is not None and a.margins is not None else
                    f"{'none':>13} {'-':>7} {'-':>6}")
        rows.append(f"{a.axis:<6} {a.mass:10.4g} {a.damping:10.4g} {1e3 * a.delay_s:9.3g} "
                    f"{100 * a.fit_error:7.2f} {proposal}")
    return "\n".join(rows)


def margins_of(design: AxisPid, mass: float, damping: float, crossover_hz: float,
               delay_s: float, step: float) -> Margins:
    """The margins of `design` loop-shaped at `crossover_hz` on (mass, damping), around that
    rigid model with the delay `delay_s` under the zero-order hold at `step`."""
    shaped = replace(design, gains=LoopShape(crossover_hz, mass, damping))
    c = shaped.state_space(step)
    return loop_margins(_Delayed(c.A, c.B, c.C, c.D, c.step, delay_s),
                        AxisPlant(mass, damping, 0.0))


def _pid_block(loop: RunConfig, machine: Machine) -> FmuConfig | None:
    """The PID built-in that commands every axis's effort (None: none of flexff's)."""
    names = {a.effort.split(".", 1)[0] for a in machine.axes}
    blocks = [f for f in loop.fmus if f.name in names and f.builtin in PID_BUILTINS]
    return blocks[0] if len(blocks) == 1 and len(names) == 1 else None


def _block_axes(loop: RunConfig, block: FmuConfig | None, machine: Machine
                ) -> tuple[dict[str, AxisPid], dict[str, str]]:
    """Each machine axis's PID design (its block's filters and form; the series form's
    defaults where the loop has no PID block of flexff's) and its name in the block."""
    if block is None:
        return ({a.name: AxisPid(LoopShape(1.0, 1.0), form="series") for a in machine.axes},
                {a.name: a.name for a in machine.axes})
    assert block.builtin is not None
    form = cast(Form, PID_BUILTINS[block.builtin])
    designs = axes_from_options(block.options, loop.step, form, block.builtin)
    out, names = {}, {}
    for axis in machine.axes:
        name = axis.effort.split(".", 1)[1].removesuffix("_effort")
        if name not in designs:
            raise InputError(f"machine axis {axis.name}: its effort {axis.effort} is no axis "
                             f"of the PID block {block.name} (axes {', '.join(designs)})")
        out[axis.name], names[axis.name] = designs[name], name
    return out, names


def _rest(loop: RunConfig, machine: Machine) -> dict[str, float]:
    """Where each axis's measured position starts (the plant's own start), in its range."""
    recording = _run(loop, machine, np.arange(3) * loop.step,
                     {a.name: 0.5 * (a.limits.low + a.limits.high) for a in machine.axes},
                     "tune-rest")
    signals = record_signals(recording, machine)
    return {a.name: float(np.clip(signals[a.measured_signal][0], a.limits.low, a.limits.high))
            for a in machine.axes}


def _measure(loop: RunConfig, machine: Machine, axis: Axis, rest: dict[str, float],
             seconds: float, high: float) -> dict[str, np.ndarray]:
    """The loop's record with `axis`'s reference a chirp about its rest, the others at rest."""
    step = loop.step
    t = np.arange(0.0, SETTLE_S + seconds + step / 2, step)
    chirp = np.clip(t - SETTLE_S, 0.0, None)
    ratio = math.log(high / LOW_HZ)
    frequency = LOW_HZ * np.exp(ratio * chirp / seconds)
    phase = 2 * math.pi * LOW_HZ * seconds / ratio * (np.exp(ratio * chirp / seconds) - 1)
    w = 2 * math.pi * frequency
    limits = axis.limits
    room = min(rest[axis.name] - limits.low, limits.high - rest[axis.name],
               RANGE_SHARE * (limits.high - limits.low))
    amplitude = np.minimum.reduce([np.full_like(w, room), limits.velocity / w,
                                   limits.acceleration / w**2])
    fade = 0.5 * (1 - np.cos(math.pi * np.clip(chirp / FADE_S, 0.0, 1.0)))
    position = rest[axis.name] + fade * amplitude * np.sin(phase)
    references = {a.name: (position if a is axis else np.full_like(t, rest[a.name]))
                  for a in machine.axes}
    recording = _run(loop, machine, t, references, f"tune-{axis.name}")
    signals = record_signals(recording, machine)
    for name in (axis.measured_signal, axis.effort_signal):
        if not np.all(np.isfinite(signals[name])):
            raise RunError(f"axis {axis.name}: the loop gave NaN or Inf under the chirp: its "
                           f"PID does not hold the plant; lower its gains (crossover_hz) and "
                           f"tune again")
    return {TIME: recording.time, **signals}


def _run(loop: RunConfig, machine: Machine, t: np.ndarray, positions: dict[str, Any],
         name: str) -> Recording:
    """The loop run at the times `t` on the references `positions` (an array per axis, or a
    constant), feedforward zero."""
    columns: dict[str, np.ndarray] = {}
    for axis in machine.axes:
        x = np.broadcast_to(np.asarray(positions[axis.name], dtype=float), t.shape).copy()
        v = np.gradient(x, loop.step)
        a = np.gradient(v, loop.step)
        columns |= dict(zip((axis.reference, *axis.derivatives),
                            (x, v, a, np.gradient(a, loop.step))))
    with tempfile.TemporaryDirectory(prefix="flexff-tune-") as folder:
        table = Path(folder) / f"{name}.csv"
        data = np.column_stack([t, *columns.values()])
        np.savetxt(table, data, fmt="%.17g", delimiter=",",
                   header=",".join([TIME, *columns]), comments="")
        return simulate_config(on_references(loop, table, float(t[-1]), name), progress=False)


def _fit(signals: dict[str, np.ndarray], axis: Axis, rate_hz: float, high: float
         ) -> tuple[float, float, float, float, float, float]:
    """mass, damping, Coulomb, offset, delay [s] and relative residual of the axis's rigid
    model on the chirp's samples (4 significant digits), the effort's lead searched."""
    corner = FIT_CORNER * high
    position = lowpass(np.asarray(signals[axis.measured_signal]), rate_hz, corner)
    velocity, acceleration = differentiate(position, rate_hz)
    effort = np.asarray(signals[axis.effort_signal], dtype=float)
    width = 0.01 * axis.limits.velocity
    columns = np.column_stack([acceleration, velocity, np.tanh(velocity / width),
                               np.ones_like(velocity)])
    edge = math.ceil(2 * rate_hz / corner)
    kept = slice(int(SETTLE_S * rate_hz) + edge, len(effort) - edge)
    best: tuple[float, np.ndarray, float] | None = None
    for lead in np.arange(0.0, MAX_LEAD + 0.125, 0.25):
        labels = lowpass(lagged(effort, rate_hz, lead / rate_hz), rate_hz, corner)[kept]
        theta, *_ = np.linalg.lstsq(columns[kept], labels, rcond=None)
        error = float(np.linalg.norm(labels - columns[kept] @ theta) / np.linalg.norm(labels))
        if best is None or error < best[0]:
            best = (error, theta, lead)
    assert best is not None
    error, theta, lead = best
    mass, damping, coulomb, offset = (float(v) for v in theta)
    if not mass > 0:
        raise RunError(f"axis {axis.name}: the fit found no positive mass ({mass:.4g}): the "
                       f"chirp did not move the axis enough to tell; give a higher high_hz or "
                       f"a longer chirp")
    def rounded(value: float) -> float:  # 4 significant digits: what the proposal is for
        return float(f"{value:.4g}")
    return (rounded(mass), rounded(max(damping, 0.0)), rounded(coulomb), rounded(offset),
            max(lead - 0.5, 0.0) / rate_hz, rounded(error))


def _proposal(design: AxisPid, fit: tuple[float, ...], step: float, phase_margin_deg: float,
              high: float) -> tuple[float | None, Margins | None]:
    """The highest crossover up to `high` whose margins around the fitted model meet the phase
    margin and GAIN_MARGIN_DB: the highest of CROSSOVERS log-spaced ones that does, refined
    by bisection towards the next (3 significant digits, rounded down)."""
    mass, damping, _, _, delay, _ = fit

    def meets(crossover: float) -> Margins | None:
        try:
            margins = margins_of(design, mass, damping, crossover, delay, step)
        except (InputError, ValueError):
            return None  # a design the block refuses, or a loop that never crosses 1
        good = margins.phase_margin_deg >= phase_margin_deg and \
            margins.gain_margin_db >= GAIN_MARGIN_DB
        return margins if good else None
    grid = np.geomspace(LOW_HZ, high, CROSSOVERS)
    passing = [k for k, crossover in enumerate(grid) if meets(float(crossover))]
    if not passing:
        return None, None
    low = float(grid[passing[-1]])
    if passing[-1] + 1 < len(grid):
        up = float(grid[passing[-1] + 1])
        while up - low > 1e-3 * low:
            middle = 0.5 * (low + up)
            low, up = (middle, up) if meets(middle) else (low, middle)
    scale = 10.0 ** (math.floor(math.log10(low)) - 2)
    value = float(f"{math.floor(low / scale) * scale:.3g}")
    margins = meets(value)
    if margins is None:  # the rounding left the tried crossovers: keep the one found
        value, margins = low, meets(low)
    return value, margins
