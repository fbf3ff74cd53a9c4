"""Generic FMU builder: a System (CasADi functions + named signals) -> FMI 2.0 co-simulation FMU.

Public API: `build_fmu`, `fmu_key` (build), `validate_fmu`, `FmpyInstance` (one FMU on fmpy, by
variable names), the description classes `System`, `Variable`,
`Parameter`, and `read_network` / `Network` for an ONNX graph embedded in a System's FMU.
"""

from flexff.fmu.build import build_fmu, fmu_key
from flexff.fmu.fmpy_instance import FmpyInstance
from flexff.fmu.network import Network, read_network
from flexff.fmu.system import Parameter, System, Variable
from flexff.fmu.validation import validate_fmu

__all__ = [
           "FmpyInstance",
           "Network",
           "Parameter",
           "System",
           "Variable",
           "build_fmu",
           "fmu_key",
           "read_network",
           "validate_fmu",
]
