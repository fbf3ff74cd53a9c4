"""One FMU instantiated through fmpy's low-level FMU2Slave and addressed by variable names
(`FmpyInstance`), and its bare hot-loop C calls (`bare_calls`): what the benches and the tests'
single-FMU runners (tests/runners.py) stand on. It is not the co-simulation master (that lives
in cosim/): one FMU, no connections.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Mapping, Sequence
from ctypes import CFUNCTYPE, c_int, c_void_p, cast
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import fmpy
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

from flexff.fmu.archive import extract_archive


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
        address = cast(getattr(fmu.dll, name), c_void_p).value
        if address is None:
            raise RuntimeError(f"the FMU's {name} is a null pointer")
        return prototype(address)

    return BareCalls(c_void_p(fmu.component), pointer("fmi2SetReal"), pointer("fmi2GetReal"),
                     pointer("fmi2DoStep"))


class FmpyInstance:
    """One instantiated FMU, addressed by variable names; use it as a context manager."""

    def __init__(self, path: str | Path, instance_name: str = "instance",
                 **instantiate_kw: Any) -> None:
        self.model_description = read_model_description(str(path))
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        self._unzipdir = str(extract_archive(path))
        self.fmu = FMU2Slave(guid=self.model_description.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=self.model_description.coSimulation.modelIdentifier,
                             instanceName=instance_name)
        self.fmu.instantiate(**instantiate_kw)

    @property
    def library(self) -> Path:
        """The FMU's shared library in the extracted folder."""
        ident = self.model_description.coSimulation.modelIdentifier
        binaries = Path(self._unzipdir, "binaries", fmpy.platform)
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
        values: list[float] = self.fmu.getReal([self.variables[n].valueReference for n in names])
        return values

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

    def __enter__(self) -> FmpyInstance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
