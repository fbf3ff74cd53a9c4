"""What computes an FMU's embedded network (fmu.network): its graph as generated C compiled into
the FMU ("c", the default: fmu.network_c), or onnxruntime's library bundled with the graph
("onnxruntime"). A module of its own, free of CasADi and onnx, so that the command line and
the run configurations' built-ins can name the runtimes without loading them."""

from __future__ import annotations

from flexff.fmu.errors import InputError

RUNTIMES = ("c", "onnxruntime")  # the default first


def check_runtime(runtime: str) -> None:
    """InputError naming the runtimes if `runtime` is not one."""
    if runtime not in RUNTIMES:
        raise InputError(f"unknown network runtime {runtime!r}: choose one of "
                         f"{', '.join(RUNTIMES)}")


def runtime_label(runtime: str) -> str:
    """How a description names the runtime: 'generated C' or 'onnxruntime'."""
    return "generated C" if runtime == "c" else runtime
