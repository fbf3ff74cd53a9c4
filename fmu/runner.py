"""Minimal fixed-step runner of one FMU through fmpy's low-level FMU2Slave, for tests and benches.

It is not the co-simulation master (that lives in cosim/): one FMU, inputs given as arrays, no
connections. Sample k is read at t_k = k * step after setting the inputs of step k, so direct
feedthrough shows up as it would in a Gauss-Seidel master.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Mapping, Sequence
from ctypes import CFUNCTYPE, c_int, c_void_p, cast
from dataclasses import dataclass
from pathlib import Path

import fmpy
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


@dataclass(frozen=True)
class BareCalls:
    """fmi2SetReal, fmi2GetReal and fmi2DoStep of one instantiated FMU as bare C pointers.

    They are the C functions fmpy loaded, called without fmpy's Python wrapper and without
    ctypes' per-argument conversion, which halves the cost of a call (~0.4 us): every argument
    must be a ctypes object of the exact C type (c_void_p component, c_uint arrays, c_size_t
    counts, c_double arrays and times, c_int flags). Each returns the fmi2Status as an int.
    """

    component: c_void_p
    set_real: Callable[..., int]
    get_real: Callable[..., int]
    do_step: Callable[..., int]


def bare_calls(fmu: FMU2Slave) -> BareCalls:
    """The hot-loop calls of an instantiated FMU2Slave (see BareCalls)."""
    prototype = CFUNCTYPE(c_int)

    def pointer(name: str) -> Callable[..., int]:
        return prototype(cast(getattr(fmu.dll, name), c_void_p).value)

    return BareCalls(c_void_p(fmu.component), pointer("fmi2SetReal"), pointer("fmi2GetReal"),
                     pointer("fmi2DoStep"))


class Slave:
    """One instantiated FMU, addressed by variable names; use it as a context manager."""

    def __init__(self, path: str | Path, instance_name: str = "instance", **instantiate_kw):
        self.model_description = read_model_description(str(path))
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        self._unzipdir = extract(str(path))
        self.fmu = FMU2Slave(guid=self.model_description.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=self.model_description.coSimulation.modelIdentifier,
                             instanceName=instance_name)
        self.fmu.instantiate(**instantiate_kw)

    @property
    def library(self) -> Path:
        """The FMU's shared library in the extracted folder."""
        ident = self.model_description.coSimulation.modelIdentifier
        binaries = Path(self._unzipdir) / "binaries" / fmpy.platform
        return binaries / f"{ident}{fmpy.sharedLibraryExtension}"

    def names(self, causality: str) -> list[str]:
        """Names of the variables with the given causality, in XML order."""
        return [n for n, v in self.variables.items() if v.causality == causality]

    def set(self, values: Mapping[str, float | int]) -> None:
        """Set Real or Integer variables by name."""
        for name, value in values.items():
            v = self.variables[name]
            if v.type == "Integer":
                self.fmu.setInteger([v.valueReference], [int(value)])
            else:
                self.fmu.setReal([v.valueReference], [float(value)])

    def get(self, names: Sequence[str]) -> list[float]:
        """Real values by name."""
        return self.fmu.getReal([self.variables[n].valueReference for n in names])

    def initialize(self, parameters: Mapping[str, float | int] | None = None,
                   start_time: float = 0.0) -> None:
        """Set up the experiment, set parameters in initialization mode, and leave it."""
        self.fmu.setupExperiment(startTime=start_time)
        self.fmu.enterInitializationMode()
        self.set(parameters or {})
        self.fmu.exitInitializationMode()

    def close(self) -> None:
        """Free the instance and the extracted files."""
        self.fmu.freeInstance()
        shutil.rmtree(self._unzipdir, ignore_errors=True)

    def __enter__(self) -> Slave:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def run_fmu(path: str | Path, steps: int, step: float = 1e-3,
            inputs: Mapping[str, float | Sequence[float]] | None = None,
            parameters: Mapping[str, float | int] | None = None,
            record: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Run `steps` communication steps; return `time` and each recorded variable, steps + 1 samples.

    `inputs` maps input names to a constant or to `steps` values (value k held over step k);
    `parameters` may include `max_substep` and the Integer `seed`; `record` defaults to all
    outputs and may name any Real variable (states too). The last sample is read after the last
    step, with the last inputs still applied.
    """
    with Slave(path) as s:
        record = list(record) if record is not None else s.names("output")
        series = {n: np.broadcast_to(np.asarray(u, dtype=float), (steps,))
                  for n, u in (inputs or {}).items()}
        s.initialize(parameters)
        out = np.empty((steps + 1, len(record)))
        for k in range(steps):
            s.set({n: u[k] for n, u in series.items()})
            out[k] = s.get(record)
            s.fmu.doStep(k * step, step)
        out[steps] = s.get(record)
        s.fmu.terminate()
    result = {"time": np.arange(steps + 1) * step}
    result.update({n: out[:, i] for i, n in enumerate(record)})
    return result


def run_fmu_libcosim(path: str | Path, steps: int, step: float = 1e-3,
                     inputs: Mapping[str, float | Sequence[float]] | None = None,
                     parameters: Mapping[str, float | int] | None = None,
                     record: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """The same run under libcosim (the second importer), through libcosimpy's own master.

    Parameters (the Integer `seed` included) are initial values, inputs are overridden before
    every step and `record` is read by a last-value observer after every step, so sample k is
    at t = (k + 1) * step: compare with run_fmu's samples 1..steps for variables without direct
    feedthrough.
    """
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.WARNING)  # libcosim traces every FMI call otherwise
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    record = list(record) if record is not None else [
        n for n, v in variables.items() if v.causality == "output"]
    series = {n: np.broadcast_to(np.asarray(u, dtype=float), (steps,))
              for n, u in (inputs or {}).items()}
    execution = CosimExecution.from_step_size(int(round(step * 1e9)))
    index = execution.add_local_slave(CosimLocalSlave(fmu_path=str(path), instance_name="slave"))
    for name, value in (parameters or {}).items():
        v = variables[name]
        ok = (execution.integer_initial_value(index, v.valueReference, int(value))
              if v.type == "Integer" else
              execution.real_initial_value(index, v.valueReference, float(value)))
        if not ok:
            raise RuntimeError(f"libcosim rejected the initial value {name} = {value}")
    manipulator, observer = CosimManipulator.create_override(), CosimObserver.create_last_value()
    execution.add_manipulator(manipulator)
    execution.add_observer(observer)
    input_refs = [variables[n].valueReference for n in series]
    record_refs = [variables[n].valueReference for n in record]
    out = np.empty((steps, len(record)))
    for k in range(steps):
        if input_refs and not manipulator.slave_real_values(
                index, input_refs, [float(u[k]) for u in series.values()]):
            raise RuntimeError(f"libcosim rejected the inputs of step {k}")
        if not execution.step(1):
            raise RuntimeError(f"libcosim failed in step {k}")
        out[k] = observer.last_real_values(index, record_refs)
    result = {"time": (np.arange(steps) + 1) * step}
    result.update({n: out[:, i] for i, n in enumerate(record)})
    return result
