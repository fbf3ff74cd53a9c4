"""Generic FMU builder: a System (CasADi functions + named signals) -> FMI 2.0 co-simulation FMU.

Public API: `build_fmu`, `fmu_key` (build), `validate_fmu`, `FmpyInstance` (one FMU on fmpy, by
variable names), the description classes `System`, `Variable`,
`Parameter`, and `read_network` / `Network` for an ONNX graph embedded in a System's FMU.
They load on first use (PEP 562), so that a run of third-party FMUs, which needs only the
importer, never pays for CasADi, onnx and the code generator.
"""

from importlib import import_module
from typing import Any

_HOMES = {"build_fmu": "build", "fmu_key": "build", "FmpyInstance": "fmpy_instance",
          "Network": "network", "read_network": "network", "Parameter": "system",
          "System": "system", "Variable": "system", "validate_fmu": "validation"}

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    """The public name `name`, imported from its module on first use."""
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{_HOMES[name]}"), name)
