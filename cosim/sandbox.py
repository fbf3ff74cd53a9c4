"""The sandbox of an isolated FMU (cosim.isolation): its process confined before the FMU's
binary is loaded, by the layers of cosim/c/sandbox.c (namespaces, limits, no new privileges,
Landlock, seccomp), each of which holds where the kernel offers it.

The FMU writes only to its scratch folder (its working directory, HOME and TMPDIR), opens no
network socket, starts no process, keeps within its memory (and CPU) limit, and sees none of
the master's environment. An attempt the sandbox stops ends the FMU's process with one line
naming it (`report`), which the master gives as the run's error. Reference:
docs/how-to/isolate-fmu.md.
"""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from pathlib import Path

from flexff.fmu import cache

MEMORY_MB = 4096.0  # the default memory limit [MB]: a feedforward FMU's process takes ~0.3 GB
STOPPED = 86  # the exit status of a process the sandbox stopped (sandbox.c)
REPORT_BYTES = 1024  # the most of a report read back
LAYERS = (  # sandbox.c's HOLD_* bits, in order
    "user and network namespaces", "memory and CPU limits", "no new privileges",
    "Landlock: writes only to the scratch folder", "Landlock: no TCP",
    "Landlock: no signals or abstract sockets outside", "seccomp")
KEPT_ENVIRONMENT = ("PATH", "LANG", "LC_ALL")
KEYS = ("sandbox", "sandbox_memory", "sandbox_cpu")  # an [fmu.NAME]'s keys (cosim.config)


@dataclass(frozen=True)
class Sandbox:
    """The limits of one sandboxed FMU: private writable memory [MB] and CPU time [s] (None:
    unbounded)."""

    memory_mb: float = MEMORY_MB
    cpu_s: float | None = None


DEFAULT = Sandbox()  # an isolated FMU's sandbox unless its configuration says otherwise


def environment(scratch: Path, python_path: str) -> dict[str, str]:
    """The child's environment: the few variables it needs, none of the master's secrets."""
    kept = {k: os.environ[k] for k in KEPT_ENVIRONMENT if k in os.environ}
    return {**kept, "HOME": str(scratch), "TMPDIR": str(scratch), "PYTHONPATH": python_path,
            "FLEXFF_CACHE": str(cache.cache_dir()),  # the compiled proxy, found, not rebuilt
            "PYTHONDONTWRITEBYTECODE": "1", "OPENBLAS_NUM_THREADS": "1"}


def enter(library: ctypes.CDLL, scratch: Path, sandbox: Sandbox, report: int) -> list[str]:
    """Confine this process (for good) by the proxy `library`'s sandbox_enter (cosim.isolation
    declares it); the layers that hold."""
    held = library.sandbox_enter(os.fsencode(scratch), int(sandbox.memory_mb * (1 << 20)),
                                 sandbox.cpu_s or 0.0, report)
    return [name for k, name in enumerate(LAYERS) if held & (1 << k)]


def report(fd: int) -> str:
    """The line a stopped child left on its report pipe ("" if none), printable and short."""
    os.set_blocking(fd, False)
    try:
        text = os.read(fd, REPORT_BYTES).decode("ascii", "replace")
    except (BlockingIOError, OSError):
        return ""
    line = text.splitlines()[0] if text.strip() else ""
    return "".join(c if c.isprintable() else "?" for c in line)
