"""The same co-simulation under libcosim (through libcosimpy), the second FMI importer.

FMUs, parameters and connections are those of cosim.master (connected by name); libcosim's
own fixed-step master runs them. Varying source signals are written by an override
manipulator before each step, constant ones are initial values, and a last-value observer
reads every FMU's outputs after each step. libcosim's algorithm is Jacobi-like, so direct
feedthrough outputs arrive one step after cosim.master's Gauss-Seidel. libcosimpy creates
every execution at t = 0; one that starts elsewhere goes through libcosim's C call
(`_execution`).

How the two masters differ: "The master algorithm", section libcosim
(docs/explanation/master-algorithm.md).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from ctypes import POINTER, c_int64

import numpy as np

from flexff.fmu.archive import check_archive
from flexff.fmu.errors import InputError, MissingPackage, RunError

try:
    from libcosimpy._internal import libcosimc, wrap_function
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave
except ImportError:  # an optional dependency: the extra "libcosim"
    raise MissingPackage("runs under libcosim need libcosimpy: pip install 'flexff[libcosim]'"
                         ) from None

from flexff.cosim.master import ResolvedFmu
from flexff.cosim.recording import Recording
from flexff.cosim.schema import point_time
from flexff.cosim.wiring import SOURCE, Link, Port, wire


class _Execution:
    """A libcosim execution of the FMUs, wired as the master wires them (default: by name),
    with parameters and constant sources as initial values; `varying` lists the inputs fed
    from time-varying sources."""

    def __init__(self, fmus: Sequence[ResolvedFmu], sources: Mapping[str, np.ndarray | float],
                 step: float, links: Sequence[Link] | None = None, start: float = 0.0) -> None:
        log_output_level(CosimLogLevel.WARNING)  # libcosim traces every FMI call otherwise
        infos = {s.name: s.described() for s in fmus}
        for s in fmus:  # libcosim unpacks each FMU itself: its sizes are checked first
            check_archive(s.path)
        self.variables = {name: info.variables for name, info in infos.items()}
        self.ports = [Port(s.name, infos[s.name]) for s in fmus]
        if links is None:
            links = wire(self.ports, list(sources), algorithm="jacobi")
        self.execution = execution = _execution(start, step)
        self.index = {s.name: execution.add_local_slave(
            CosimLocalSlave(fmu_path=str(s.path), instance_name=s.name)) for s in fmus}
        for s in fmus:
            for name, value in s.parameters.items():
                self.initial_value(s.name, name, value)
        self.varying: dict[str, list[tuple[int, str]]] = {}  # fmu -> (value ref., source)
        for c in links:
            if c.affine or not c.on_bus:
                raise InputError(f"{c}: libcosim's API connects Real signals as they are; "
                                 f"run the SSP export for linear transformations")
            if c.producer != SOURCE:
                status = execution.connect_real_variables(
                    self.index[c.producer], self.vr(c.producer, c.signal),
                    self.index[c.consumer], self.vr(c.consumer, c.input))
                if not (status is True or (type(status) is int and status == 0)):  # int in 0.0.6
                    raise RunError(f"libcosim refused to connect {c}")
            elif np.ndim(sources[c.signal]) == 0:
                self.initial_value(c.consumer, c.input, sources[c.signal])
            else:
                self.varying.setdefault(c.consumer, []).append(
                    (self.vr(c.consumer, c.input), c.signal))

    def vr(self, fmu: str, name: str) -> int:
        return self.variables[fmu][name].value_reference

    def initial_value(self, fmu: str, name: str, value: float | np.ndarray) -> None:
        """Set a parameter or a constant input (a scalar, np.ndim 0) before the run."""
        i, vr = self.index[fmu], self.vr(fmu, name)
        ok = (self.execution.integer_initial_value(i, vr, int(value))
              if self.variables[fmu][name].kind == "int32" else
              self.execution.real_initial_value(i, vr, float(value)))
        if not ok:
            raise RunError(f"libcosim rejected {fmu}.{name} = {value!r}")


def _execution(start: float, step: float) -> CosimExecution:
    """An empty execution with libcosim's fixed-step algorithm from `start` (s)."""
    if start == 0.0:
        return CosimExecution.from_step_size(round(step * 1e9))
    create = wrap_function(lib=libcosimc(), funcname="cosim_execution_create",
                           argtypes=[c_int64, c_int64], restype=POINTER(CosimExecution))
    pointer = create(round(start * 1e9), round(step * 1e9))
    if not pointer:
        raise RunError(f"libcosim cannot create an execution from t = {start!r} s")
    key = CosimExecution._CosimExecution__create_key  # libcosimpy guards its constructor
    return CosimExecution(key, pointer)


def run_libcosim(fmus: Sequence[ResolvedFmu], sources: Mapping[str, np.ndarray | float],
                 step: float, steps: int, record: Sequence[str] | None = None,
                 links: Sequence[Link] | None = None, start: float = 0.0) -> Recording:
    """Run `steps` steps from `start`; the recording holds the FMU outputs (all, or `record`)
    at t_1 .. t_steps, read after each step, and the source signals at those points.

    Its wall time includes libcosimpy's per-step calls (manipulator and observer), which
    build their ctypes prototypes on every call: see `time_libcosim_engine` for the rest.
    """
    ex = _Execution(fmus, sources, step, links, start)
    override, observer = CosimManipulator.create_override(), CosimObserver.create_last_value()
    ex.execution.add_manipulator(override)
    ex.execution.add_observer(observer)
    by_fmu = {p.name: [n for n in p.info.outputs if record is None or n in record
                         or f"{p.name}.{n}" in record] for p in ex.ports}
    by_fmu = {s: names for s, names in by_fmu.items() if names}
    refs = {s: [ex.vr(s, n) for n in names] for s, names in by_fmu.items()}
    out = {s: np.empty((steps, len(names))) for s, names in by_fmu.items()}
    table = {n: np.broadcast_to(np.asarray(v, dtype=float), (steps + 1,))
             for n, v in sources.items()}
    began = time.perf_counter()
    for k in range(steps):
        for fmu, inputs in ex.varying.items():
            if not override.slave_real_values(ex.index[fmu], [r for r, _ in inputs],
                                              [float(table[n][k]) for _, n in inputs]):
                raise RunError(f"libcosim rejected the inputs of {fmu} at step {k}")
        if not ex.execution.step(1):
            raise RunError(f"libcosim failed in the step from t = "
                           f"{point_time(start, step, k):.9g} s")
        for fmu, values in out.items():
            values[k] = observer.last_real_values(ex.index[fmu], refs[fmu])
    wall = time.perf_counter() - began
    signals = {n: np.ascontiguousarray(table[n][1:]) for n in sources
               if record is None or n in record}
    for fmu, names in by_fmu.items():
        signals.update({f"{fmu}.{n}": np.ascontiguousarray(out[fmu][:, j])
                        for j, n in enumerate(names)})
    return Recording(point_time(start, step, np.arange(steps) + 1), signals, wall)


def time_libcosim_engine(fmus: Sequence[ResolvedFmu], sources: Mapping[str, np.ndarray | float],
                         step: float, steps: int) -> float:
    """Seconds libcosim takes for `steps` steps of the connected FMUs in one call, the
    varying sources held at their first sample: the engine's cost without per-step Python."""
    ex = _Execution(fmus, {n: float(np.ravel(v)[0]) for n, v in sources.items()}, step)
    start = time.perf_counter()
    if not ex.execution.step(steps):
        raise RunError("libcosim failed")
    return time.perf_counter() - start
