"""CasADi Functions as compiled C: generated once, compiled into the build cache (fmu.cache),
loaded with casadi.external, so that evaluating one on 1e5 samples costs what C costs rather
than what CasADi's virtual machine does.

Where no C compiler runs (or the Function cannot be generated as C), it stays as it is,
interpreted, and a warning says so once: the results are the same, only slower.
"""

from __future__ import annotations

import functools
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import casadi as ca

from flexff.fmu import cache
from flexff.fmu.compile import compiler, compiler_version

# -ffp-contract=off: no fused multiply-add, so that the compiled results equal CasADi's own to
# the last bit, as the FMUs' do (fmu.compile)
FLAGS = ("-O1", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off")
SUFFIX = ".dll" if sys.platform == "win32" else ".dylib" if sys.platform == "darwin" else ".so"


def compiled(function: ca.Function) -> ca.Function:
    """`function` compiled (the same inputs, outputs and results); `function` itself where it
    cannot be."""
    try:
        code = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
        code.add(function)
        source = code.dump()
        key = cache.digest({"source": source, "flags": " ".join(FLAGS),
                            "compiler": compiler_version()})
        library = cache.cached_path(key, SUFFIX)
        if not library.is_file():
            _compile(source, key)
    except (subprocess.CalledProcessError, OSError, RuntimeError) as error:  # the compiler
        # failed (its messages), none runs, or the Function has no C
        reason = getattr(error, "stderr", None) or str(error)
        _warn_interpreted(function.name(), reason.strip().splitlines()[0])
        return function
    return ca.external(function.name(), str(library))


def _compile(source: str, key: str) -> None:
    """The shared library of `source` into the cache under `key`; CalledProcessError with the
    compiler's messages where it fails."""
    with tempfile.TemporaryDirectory() as tmp:
        c_file, library = Path(tmp) / "function.c", Path(tmp) / f"function{SUFFIX}"
        c_file.write_text(source)
        subprocess.run([compiler(), *FLAGS, str(c_file), "-o", str(library), "-lm"],
                       check=True, capture_output=True, text=True)
        cache.store(key, SUFFIX, library)


@functools.cache
def _warn_interpreted(name: str, reason: str) -> None:
    warnings.warn(f"CasADi function {name} runs interpreted, about ten times slower: it could "
                  f"not be compiled ({reason}); install gcc or set $CC", RuntimeWarning,
                  stacklevel=4)
