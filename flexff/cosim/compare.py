"""compare_fmu: one FMU run alone on its default experiment in flexff and in FMPy, and the
largest difference per output: the check to run before trusting flexff with an FMU from
elsewhere (`flexff fmu compare`).

Both runs take the experiment as FMPy derives it from the model description (`experiment`):
start and stop time of the default experiment (else 0 and start + 1 s), and as the
communication step the fixed internal step (FMI 3.0), else the default experiment's step
(doubled until the run has at most 1000 steps), else FMPy's automatic interval. Inputs keep
their start values in both, and both pass the default experiment's start time and tolerance
to the FMU (a flexff run's defaults, cosim.config). flexff runs the FMU through the path of
`flexff run` (a one-FMU configuration, the co-simulation master); FMPy through
`fmpy.simulate_fmu` with the same output interval, on the FMU unpacked by fmu.archive. The
outputs are compared at the time points both runs have; each output's difference is also
given relative to its largest magnitude in either run.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import fmpy
import numpy as np
from fmpy.util import auto_interval

from flexff.fmu.archive import extract_archive
from flexff.fmu.importer import FmuInfo, read_fmu

if TYPE_CHECKING:
    from flexff.cosim.recording import Recording

RTOL = 1e-9  # relative: outputs that differ by at most this much agree
MAX_STEPS = 1000  # FMPy doubles a default-experiment step until the run has at most this many
INSTANCE = "fmu"  # the FMU's instance name in flexff's run
NUMERIC = ("float64", "float32", "int8", "uint8", "int16", "uint16", "int32", "uint32",
           "int64", "uint64", "enumeration", "boolean")


@dataclass(frozen=True)
class Experiment:
    """The default experiment as FMPy runs it: [start, stop] in steps of `step` (seconds),
    and the tolerance both pass to the FMU (None: none given)."""

    start: float
    stop: float
    step: float
    tolerance: float | None


@dataclass(frozen=True)
class OutputDifference:
    """The largest difference of one output between the runs: absolute, and relative to the
    output's largest magnitude in either run (inf where a value is NaN in one run only)."""

    name: str
    absolute: float
    relative: float


@dataclass(frozen=True)
class Comparison:
    """One FMU in flexff and FMPy: the experiment, the common time points, each output's
    difference."""

    path: Path
    experiment: Experiment
    points: int
    outputs: tuple[OutputDifference, ...]

    @property
    def largest(self) -> OutputDifference | None:
        """The output with the largest relative difference (None without outputs)."""
        return max(self.outputs, key=lambda o: o.relative, default=None)

    def verdict(self, rtol: float = RTOL) -> str:
        """One line: bit-equal, equal within `rtol`, or different (the worst output)."""
        worst = self.largest
        if self.points == 0:
            return "no common time points"
        if worst is None:
            return "no outputs to compare"
        if worst.absolute == 0.0:
            return f"bit-equal ({len(self.outputs)} outputs, {self.points} points)"
        if worst.relative <= rtol:
            return f"equal within {worst.relative:.2g} (relative, {worst.name})"
        return f"DIFFERENT: {worst.name} differs by {worst.relative:.2g} (relative)"

    def agrees(self, rtol: float = RTOL) -> bool:
        """Whether every output agrees within `rtol` at one common time point or more."""
        worst = self.largest
        return self.points > 0 and (worst is None or worst.relative <= rtol)

    def report(self, rtol: float = RTOL) -> str:
        """The comparison as text: the experiment, one line per output, the verdict."""
        run = self.experiment
        tolerance = "none given" if run.tolerance is None else f"{run.tolerance:g}"
        width = max([len("output"), *(len(o.name) for o in self.outputs)])
        lines = [f"{self.path}: {run.start:g} .. {run.stop:g} s, step {run.step:g} s, "
                 f"tolerance {tolerance}; {self.points} common points",
                 f"  {'output':<{width}}  {'largest |difference|':>20}  {'relative':>9}"]
        lines += [f"  {o.name:<{width}}  {o.absolute:>20.3g}  {o.relative:>9.2g}"
                  for o in self.outputs]
        lines.append(f"  -> {self.verdict(rtol)}")
        return "\n".join(lines)


def experiment(info: FmuInfo) -> Experiment:
    """The FMU's default experiment as FMPy runs it (module doc)."""
    md = info.model_description
    default = md.defaultExperiment
    start = float(default.startTime) if default is not None and default.startTime else 0.0
    stop = float(default.stopTime) if default is not None and default.stopTime else start + 1.0
    tolerance = float(default.tolerance) if default is not None and default.tolerance else None
    fixed = getattr(md.coSimulation, "fixedInternalStepSize", None)
    if fixed is not None:
        step = float(fixed)
    elif info.default_step:
        step = info.default_step
    else:
        return Experiment(start, stop, float(auto_interval(stop - start)), tolerance)
    while (stop - start) / step > MAX_STEPS:
        step *= 2
    return Experiment(start, stop, step, tolerance)


def outputs(info: FmuInfo) -> list[str]:
    """The outputs compared: scalar ones of a numeric type."""
    return [n for n in info.outputs
            if info.variables[n].scalar and info.variables[n].kind in NUMERIC]


def flexff_run(path: Path, run: Experiment) -> Recording:
    """The FMU alone in flexff's master, inputs at their start values, every signal recorded."""
    from flexff.cosim.config import parse_config  # the run path's imports (plots among them)
    from flexff.cosim.run import simulate_config  # load only when a comparison runs

    steps = math.floor((run.stop - run.start) / run.step * (1 + 1e-12))
    config = parse_config({"run": {"start": run.start, "step": run.step,
                                   "stop": run.start + steps * run.step},
                           "fmu": {INSTANCE: {"path": str(path.resolve()),
                                              "unconnected": "start"}}},
                          name=path.stem, origin=str(path))
    return simulate_config(config, progress=False)


def fmpy_run(path: Path, info: FmuInfo, run: Experiment, names: list[str]) -> Any:
    """The FMU alone in FMPy (co-simulation, inputs at their start values): its result."""
    folder = extract_archive(path)
    try:
        return fmpy.simulate_fmu(str(folder), start_time=run.start, stop_time=run.stop,
                                 output_interval=run.step, fmi_type="CoSimulation",
                                 output=names, model_description=info.model_description)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def difference(name: str, ours: np.ndarray, theirs: np.ndarray) -> OutputDifference:
    """The largest difference of one output's samples (module doc)."""
    a, b = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    if same.all():
        return OutputDifference(name, 0.0, 0.0)
    if np.isnan(a[~same]).any() or np.isnan(b[~same]).any():
        return OutputDifference(name, math.inf, math.inf)
    absolute = float(np.max(np.abs(a[~same] - b[~same])))
    finite = np.abs(np.concatenate([a, b]))
    scale = float(np.max(finite[np.isfinite(finite)], initial=0.0))
    return OutputDifference(name, absolute, absolute / scale if scale > 0 else math.inf)


def compare_fmu(path: str | Path) -> Comparison:
    """Run the FMU at `path` in flexff and in FMPy on its default experiment and compare every
    output (module doc); InputError for a file that is not a usable FMU."""
    path = Path(path)
    info = read_fmu(path)
    run = experiment(info)
    names = outputs(info)
    ours = flexff_run(path, run)
    theirs = fmpy_run(path, info, run, names)
    # common points by step index (both runs are on the grid start + k * step)
    index_ours = {round((t - run.start) / run.step): k for k, t in enumerate(ours.time)}
    pairs = [(index_ours[i], k) for k, t in enumerate(theirs["time"])
             if (i := round((t - run.start) / run.step)) in index_ours
             and math.isclose(t, ours.time[index_ours[i]], rel_tol=1e-9, abs_tol=1e-9 * run.step)]
    mine = np.array([p[0] for p in pairs], dtype=int)
    other = np.array([p[1] for p in pairs], dtype=int)
    return Comparison(path, run, len(pairs), tuple(
        difference(n, ours[f"{INSTANCE}.{n}"][mine], theirs[n][other]) for n in names))
