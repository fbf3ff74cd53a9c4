"""Fixed-step runners of one FMU for the tests: through fmpy (fmu.fmpy_instance) and through
libcosim, the second importer.

Inputs are given as arrays, there are no connections. With `run_fmu` sample k is read at
t_k = k * step after setting the inputs of step k, so direct feedthrough shows up as it would
in a Gauss-Seidel master. `simulate_with_fmpy` runs fmpy.simulate_fmu itself, inputs as
functions of time (it reads a direct feedthrough one input late: use it for constant inputs
or states).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
from fmpy import read_model_description, simulate_fmu
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave

from flexff.fmu.fmpy_instance import FmpyInstance


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
    with FmpyInstance(path) as s:
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

    log_output_level(CosimLogLevel.WARNING)  # libcosim traces every FMI call otherwise
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    record = list(record) if record is not None else [
        n for n, v in variables.items() if v.causality == "output"]
    series = {n: np.broadcast_to(np.asarray(u, dtype=float), (steps,))
              for n, u in (inputs or {}).items()}
    execution = CosimExecution.from_step_size(round(step * 1e9))
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


def simulate_with_fmpy(path: str | Path, inputs: Mapping[str, Callable[[float], float]],
                       stop: float, outputs: Sequence[str], step: float = 1e-3,
                       **start: float) -> np.ndarray:
    """fmpy.simulate_fmu at `step` with `inputs` {name: f(t)} sampled at every step."""
    t = np.arange(0.0, stop + step / 2, step)
    table = np.array(list(zip(t, *[np.vectorize(f, otypes=[float])(t) for f in inputs.values()])),
                     dtype=[("time", float)] + [(n, float) for n in inputs])
    result: np.ndarray = simulate_fmu(str(path), stop_time=stop, step_size=step,
                                      output_interval=step, input=table, output=list(outputs),
                                      start_values=start)
    return result
