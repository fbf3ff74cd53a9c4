"""Generic FMU builder: a System (CasADi functions + named signals) -> FMI 2.0 co-simulation FMU.

Public API: `build_fmu`, `fmu_key` (build), `validate_fmu`, `run_fmu` / `Slave` (a minimal
single-FMU runner on fmpy), `bench_fmu`, and the description classes `System`, `Variable`,
`Parameter`.
"""

from fmu.bench import bench_fmu
from fmu.build import build_fmu, fmu_key
from fmu.runner import Slave, run_fmu
from fmu.system import Parameter, System, Variable
from fmu.validation import validate_fmu

__all__ = ["Parameter", "Slave", "System", "Variable", "bench_fmu", "build_fmu", "fmu_key",
           "run_fmu", "validate_fmu"]
