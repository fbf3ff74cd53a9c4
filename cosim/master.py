"""Fixed-step co-simulation master over fmpy's low-level FMI 2.0 co-simulation API.

FMUs run in a fixed Gauss-Seidel order, connected by signal name (cosim.connections). All
signals live in one float64 array, the bus: the external source signals first, then each FMU's
outputs as one block, so that fmi2GetReal writes straight into the bus, and fmi2SetReal reads
straight from it whenever an FMU's inputs form a block of the bus in order (otherwise they are
gathered into a buffer first). Communication point k (t_k = k * step), for k = 0 .. steps:

  1. the source signals of point k are copied into the bus;
  2. in order, each FMU gets its inputs (fmi2SetReal) and, if a later FMU or no FMU reads its
     outputs, gives them (fmi2GetReal): values at t_k with the inputs of t_k, so direct
     feedthrough takes effect at once;
  3. the bus is recorded as sample k; after the last point the run ends here;
  4. each FMU steps to t_{k+1} (fmi2DoStep); an FMU whose outputs are fed back to an earlier
     one gives them right after its step, values at t_{k+1} (they have no feedthrough, checked
     at load time, so they equal what step 2 of the next point would read). Such outputs are
     also read once after initialization, for point 0.

So with the order feedforward -> controller -> plant, the controller at t_k sees the encoders
at t_k and the plant holds the currents computed from them over [t_k, t_{k+1}], as a
zero-order-hold digital controller does, with no extra delay. A recorded feedback-only output
with feedthrough (the plant's torques) is the value at t_k with the inputs of the previous
step. Each FMU costs one fmi2SetReal, one fmi2GetReal and one fmi2DoStep per step, called
through the ctypes functions fmpy loaded (not fmpy's Python wrappers); every status is checked.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Mapping, Sequence
from ctypes import byref, c_double, c_int, c_size_t, c_uint
from dataclasses import dataclass, field
from pathlib import Path

import fmpy
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy
from tqdm import tqdm

from cosim.connections import SOURCE, Port, connect
from fmu.runner import bare_calls
from cosim.recording import Recording

PROGRESS_MIN_STEPS = 100_000  # runs this long show a progress bar (on a terminal)
PROGRESS_CHUNK = 1000  # steps between progress bar updates
STATUS_LABELS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")


@dataclass(frozen=True)
class SlaveSpec:
    """One FMU of a co-simulation: its instance name, its file and parameter start values."""

    name: str
    fmu: Path
    parameters: Mapping[str, float | int] = field(default_factory=dict)


class CosimError(RuntimeError):
    """An FMI call failed during a co-simulation (the message carries the FMU's log)."""


class _Slave:
    """One instantiated FMU: its signals, its raw fmi2 functions and its log messages."""

    def __init__(self, spec: SlaveSpec) -> None:
        self.name = spec.name
        self.parameters = dict(spec.parameters)
        md = read_model_description(str(spec.fmu))
        if md.fmiVersion != "2.0" or md.coSimulation is None:
            raise ValueError(f"{spec.fmu}: {spec.name!r} is not an FMI 2.0 co-simulation FMU")
        self.guid = md.guid
        self.variables = {v.name: v for v in md.modelVariables}
        self.inputs = tuple(v.name for v in md.modelVariables if v.causality == "input")
        self.outputs = tuple(v.name for v in md.modelVariables if v.causality == "output")
        self.feedthrough = frozenset(u.variable.name for u in md.outputs if u.dependencies)
        for name in self.inputs + self.outputs:
            if self.variables[name].type != "Real":
                raise ValueError(f"{spec.name}: signal {name!r} is not Real")
        for name in self.parameters:
            v = self.variables.get(name)
            if v is None or v.causality != "parameter":
                known = ", ".join(n for n, w in self.variables.items()
                                  if w.causality == "parameter")
                raise ValueError(f"{spec.name}: unknown parameter {name!r} (known: {known})")
        self.messages: list[str] = []
        self._unzipdir = extract(str(spec.fmu))
        self.library = (Path(self._unzipdir) / "binaries" / fmpy.platform
                        / f"{md.coSimulation.modelIdentifier}{fmpy.sharedLibraryExtension}")
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=spec.name)
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        addLoggerProxy(byref(self._callbacks))  # formats the variadic messages in C
        self.fmu.instantiate(callbacks=self._callbacks)
        self.component = self.fmu.component
        calls = bare_calls(self.fmu)  # exact C argument types only: see fmu.runner.BareCalls
        self.c, self.set_real, self.get_real, self.do_step = (
            calls.component, calls.set_real, calls.get_real, calls.do_step)
        self.initialized = False

    def _log(self, env, instance, status, category, message) -> None:
        label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
        self.messages.append(f"[{label}] {message.decode('utf-8', 'replace')}")

    def port(self) -> Port:
        return Port(self.name, self.inputs, self.outputs, self.feedthrough)

    def vr(self, name: str) -> int:
        return self.variables[name].valueReference

    def fail(self, what: str) -> CosimError:
        log = "; ".join(self.messages[-5:]) or "no message from the FMU"
        return CosimError(f"{self.name}: {what} failed: {log}")

    def check(self, status: int, what: str) -> None:
        if status > 1:
            raise self.fail(what)

    def initialize(self, stop_time: float) -> None:
        """Set up the experiment from t = 0, set the parameters, leave initialization mode."""
        dll, c = self.fmu.dll, self.component
        self.check(dll.fmi2SetupExperiment(c, 0, 0.0, 0.0, 1, stop_time), "fmi2SetupExperiment")
        self.check(dll.fmi2EnterInitializationMode(c), "fmi2EnterInitializationMode")
        for name, value in self.parameters.items():
            if self.variables[name].type == "Integer":
                status = dll.fmi2SetInteger(c, (c_uint * 1)(self.vr(name)), 1,
                                            (c_int * 1)(int(value)))
            else:
                status = dll.fmi2SetReal(c, (c_uint * 1)(self.vr(name)), 1,
                                         (c_double * 1)(float(value)))
            self.check(status, f"setting parameter {name} = {value!r}")
        self.check(dll.fmi2ExitInitializationMode(c), "fmi2ExitInitializationMode")
        self.initialized = True

    def close(self) -> None:
        """Terminate (if it ran), free the instance and delete the extracted files."""
        try:
            if self.initialized:
                self.fmu.dll.fmi2Terminate(self.component)
            self.fmu.freeInstance()
        finally:
            shutil.rmtree(self._unzipdir, ignore_errors=True)


@dataclass
class _Plan:
    """How one FMU reads its inputs from and writes its outputs to the bus."""

    slave: _Slave
    in_vr: object
    in_values: object  # ctypes array: a view of the bus, or a gather buffer
    gather: np.ndarray | None  # bus indices to gather into in_values, None if a view
    gather_view: np.ndarray | None
    out_vr: object
    out_values: object  # ctypes view of the FMU's output block of the bus
    out_offset: int
    read_before: bool  # outputs read at t_k, before the step
    read_after: bool  # outputs read at t_{k+1}, after the step (feedback)


class Master:
    """Loaded FMUs connected by name, ready for one run; use it as a context manager.

    `sources` names the external signals (the reference, constants) given to `run`.
    """

    def __init__(self, slaves: Sequence[SlaveSpec], sources: Sequence[str], step: float) -> None:
        if not step > 0:
            raise ValueError(f"step must be positive, got {step}")
        self.step = float(step)
        self.sources = tuple(sources)
        self._slaves: list[_Slave] = []
        try:
            for spec in slaves:
                self._slaves.append(_Slave(spec))
            self.connections = connect(self.sources, [s.port() for s in self._slaves])
            self._layout()
        except BaseException:
            self.close()
            raise
        self._ran = False

    # -- layout -------------------------------------------------------------------------------
    def _layout(self) -> None:
        names = list(self.sources)
        offsets = {}
        for s in self._slaves:
            offsets[s.name] = len(names)
            names += s.outputs
        self.signals = tuple(names)
        index = {n: i for i, n in enumerate(names)}
        self._bus = np.zeros(len(names))
        feeds_later = {s.name: False for s in self._slaves}
        feeds_back = dict(feeds_later)
        for c in self.connections:
            if c.source != SOURCE:
                (feeds_back if c.feedback else feeds_later)[c.source] = True
        self._plans = []
        for s in self._slaves:
            gather = np.array([index[n] for n in s.inputs], dtype=np.intp)
            contiguous = gather.size == 0 or np.array_equal(
                gather, np.arange(gather[0], gather[0] + gather.size))
            if contiguous:
                in_values = self._view(int(gather[0]) if gather.size else 0, gather.size)
                gather_idx, gather_view = None, None
            else:
                in_values = (c_double * gather.size)()
                gather_idx, gather_view = gather, np.frombuffer(in_values)
            offset = offsets[s.name]
            self._plans.append(_Plan(
                slave=s,
                in_vr=(c_uint * len(s.inputs))(*map(s.vr, s.inputs)),
                in_values=in_values, gather=gather_idx, gather_view=gather_view,
                out_vr=(c_uint * len(s.outputs))(*map(s.vr, s.outputs)),
                out_values=self._view(offset, len(s.outputs)), out_offset=offset,
                read_before=feeds_later[s.name] or not feeds_back[s.name],
                read_after=feeds_back[s.name]))

    def _view(self, offset: int, n: int):
        """A ctypes array sharing the bus memory from `offset` (n values; n = 0: a dummy)."""
        return (c_double * n).from_buffer(self._bus, 8 * offset) if n else (c_double * 1)()

    def layout(self) -> dict:
        """The bus layout and every FMU's call plan, as plain data (for the C loop)."""
        index = {n: i for i, n in enumerate(self.signals)}
        return {
            "step": self.step, "signals": list(self.signals), "n_sources": len(self.sources),
            "slaves": [{
                "name": p.slave.name, "library": str(p.slave.library), "guid": p.slave.guid,
                "parameters": [(p.slave.vr(n), p.slave.variables[n].type, v)
                               for n, v in p.slave.parameters.items()],
                "inputs": [(p.slave.vr(n), index[n]) for n in p.slave.inputs],
                "outputs": [p.slave.vr(n) for n in p.slave.outputs],
                "output_offset": p.out_offset,
                "read_before": p.read_before, "read_after": p.read_after,
            } for p in self._plans]}

    # -- running ------------------------------------------------------------------------------
    def run(self, sources: Mapping[str, np.ndarray | float], steps: int,
            record: Sequence[str] | None = None, progress: bool | None = None) -> Recording:
        """Run `steps` steps from t = 0; return the recorded signals at the steps + 1 points.

        `sources` gives every source signal as a constant or as steps + 1 samples; `record`
        names the signals to keep (default: all); `progress` shows a tqdm bar (default: on a
        terminal, for runs of at least PROGRESS_MIN_STEPS steps).
        """
        if self._ran:
            raise RuntimeError("a Master runs once; load the FMUs again for another run")
        self._ran = True
        table = self._source_table(sources, steps)
        record = list(self.signals if record is None else record)
        unknown = [n for n in record if n not in self.signals]
        if unknown:
            raise ValueError(f"cannot record unknown signal(s) {unknown}; known: "
                             f"{', '.join(self.signals)}")
        columns = np.array([self.signals.index(n) for n in record], dtype=np.intp)
        everything = np.array_equal(columns, np.arange(len(self.signals)))
        out = np.empty((steps + 1, len(columns)))
        for s in self._slaves:
            s.initialize(stop_time=steps * self.step)
        for p in self._plans:
            if p.read_after:
                p.slave.check(self._get(p), "fmi2GetReal after initialization")
        if progress is None:
            progress = sys.stderr.isatty() and steps >= PROGRESS_MIN_STEPS
        start = time.perf_counter()
        with tqdm(total=steps, unit="step", disable=not progress, leave=False) as bar:
            for k0 in range(0, steps + 1, PROGRESS_CHUNK):
                k1 = min(k0 + PROGRESS_CHUNK, steps + 1)
                self._loop(k0, k1, steps, table, out, None if everything else columns)
                bar.update(min(k1, steps) - k0)
        wall = time.perf_counter() - start
        signals = {n: np.ascontiguousarray(out[:, j]) for j, n in enumerate(record)}
        return Recording(np.arange(steps + 1) * self.step, signals, wall)

    def _source_table(self, values: Mapping[str, np.ndarray | float], steps: int) -> np.ndarray:
        missing = [n for n in self.sources if n not in values]
        extra = [n for n in values if n not in self.sources]
        if missing or extra:
            raise ValueError(f"source values: missing {missing}, unexpected {extra}")
        table = np.empty((steps + 1, len(self.sources)))
        for j, name in enumerate(self.sources):
            column = np.asarray(values[name], dtype=float)
            if column.ndim and column.shape != (steps + 1,):
                raise ValueError(f"source {name!r} has {column.shape} samples, the run needs "
                                 f"({steps + 1},) (or a constant)")
            if not np.all(np.isfinite(column)):
                raise ValueError(f"source {name!r} has non-finite values")
            table[:, j] = column
        return table

    def _get(self, p: _Plan) -> int:
        return p.slave.get_real(p.slave.c, p.out_vr, c_size_t(len(p.slave.outputs)),
                                p.out_values)

    def _loop(self, k0: int, k1: int, steps: int, table: np.ndarray, out: np.ndarray,
              columns: np.ndarray | None) -> None:
        """Communication points k0 .. k1 - 1 (see the module docstring); the hot loop."""
        h, bus, take, double = self.step, self._bus, np.take, c_double
        h_c, true = c_double(self.step), c_int(1)
        sources = bus[:len(self.sources)]
        before = [(p.slave.c, p.slave.set_real if p.slave.inputs else None, p.in_vr,
                   c_size_t(len(p.slave.inputs)), p.in_values, p.gather, p.gather_view,
                   p.slave.get_real if p.read_before and p.slave.outputs else None, p.out_vr,
                   c_size_t(len(p.slave.outputs)), p.out_values, p.slave) for p in self._plans]
        after = [(p.slave.c, p.slave.do_step,
                  p.slave.get_real if p.read_after and p.slave.outputs else None, p.out_vr,
                  c_size_t(len(p.slave.outputs)), p.out_values, p.slave) for p in self._plans]
        for k in range(k0, k1):
            sources[:] = table[k]
            for c, set_real, in_vr, n_in, u, gather, view, get_real, out_vr, n_out, y, s in before:
                if gather is not None:
                    take(bus, gather, out=view)
                if set_real is not None and set_real(c, in_vr, n_in, u) > 1:
                    raise s.fail(f"fmi2SetReal at t = {k * h:.9g} s")
                if get_real is not None and get_real(c, out_vr, n_out, y) > 1:
                    raise s.fail(f"fmi2GetReal at t = {k * h:.9g} s")
            if columns is None:
                out[k] = bus
            else:
                take(bus, columns, out=out[k])
            if k == steps:
                return
            t = k * h
            t_c = double(t)
            for c, do_step, get_real, out_vr, n_out, y, s in after:
                if do_step(c, t_c, h_c, true) > 1:
                    raise s.fail(f"fmi2DoStep from t = {t:.9g} s")
                if get_real is not None and get_real(c, out_vr, n_out, y) > 1:
                    raise s.fail(f"fmi2GetReal at t = {t + h:.9g} s")

    def close(self) -> None:
        """Terminate and free every FMU (safe to call twice)."""
        while self._slaves:
            self._slaves.pop().close()

    def __enter__(self) -> Master:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

