"""The sandbox of an isolated FMU (cosim.isolation): its process confined before the FMU's
binary is loaded, by the layers of cosim/c/sandbox.c (namespaces, limits, no new privileges,
Landlock, seccomp), each of which holds where the kernel offers it.

The FMU writes only to its scratch folder (its working directory, HOME and TMPDIR, a tmpfs of
SCRATCH_MB), opens no network socket, starts no process, keeps within its memory (and CPU)
limit, has no terminal (a session of its own), changes no file's mode, owner, times or
attributes, and sees none of the master's environment; with sandbox_read it reads only its
own folder, the system's libraries and the paths given. An attempt the sandbox stops ends the
FMU's process with one line naming it (`report`), which the master gives as the run's error.
Reference: docs/how-to/isolate-fmu.md.
"""

from __future__ import annotations

import ctypes
import os
import sys
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from flexff.fmu import cache

MEMORY_MB = 4096.0  # the default memory limit [MB]: a feedforward FMU's process takes ~0.3 GB
SCRATCH_MB = 1024.0  # what its scratch folder holds [MB], and the largest file it writes
THREADS = 256  # the threads it may have (RLIMIT_NPROC: counted per user, so not for root)
STOPPED = 86  # the exit status of a process the sandbox stopped (sandbox.c)
REPORT_BYTES = 1024  # the most of a report read back
LAYERS = (  # sandbox.c's HOLD_* bits, in order
    "user and network namespaces", "memory and CPU limits", "no new privileges",
    "Landlock: writes only to the scratch folder", "Landlock: no TCP",
    "Landlock: no signals or abstract sockets outside", "seccomp", "a session of its own",
    "a scratch folder of its own size", "Landlock: reads only its folder, the system's and "
    "sandbox_read's")
SYSTEM_READ = (  # what a confined reader still reads: the system's libraries and what they read
    "/usr", "/lib", "/lib64", "/lib32", "/etc/ld.so.cache", "/etc/localtime", "/proc/self",
    "/proc/cpuinfo", "/proc/meminfo", "/sys/devices/system/cpu", "/sys/fs/cgroup", "/dev/zero",
    "/dev/urandom")
KEPT_ENVIRONMENT = ("PATH", "LANG", "LC_ALL")
KEYS = ("sandbox", "sandbox_memory", "sandbox_cpu", "sandbox_scratch",
        "sandbox_read")  # an [fmu.NAME]'s keys (cosim.config)


@dataclass(frozen=True)
class Sandbox:
    """The limits of one sandboxed FMU: private writable memory [MB] (and its address space,
    shared mappings included, that and 512 MB), CPU time [s] (None: unbounded), the size of
    its scratch folder [MB], its threads and, where given, what it may read besides its own
    folder and the system's libraries (None: everything its user may read)."""

    memory_mb: float = MEMORY_MB
    cpu_s: float | None = None
    scratch_mb: float = SCRATCH_MB
    threads: int = THREADS
    read: tuple[Path, ...] | None = None


DEFAULT = Sandbox()  # an isolated FMU's sandbox unless its configuration says otherwise
REPORTS = ("it tried to ", "it made a forbidden system call (")  # how sandbox.c's lines begin


def as_list(sandbox: Sandbox) -> list[Any]:
    """The sandbox as JSON's types, for the child's command line."""
    values = [getattr(sandbox, f.name) for f in fields(Sandbox)]
    return [*values[:-1], None if sandbox.read is None else [str(p) for p in sandbox.read]]


def from_list(values: list[Any]) -> Sandbox:
    """The sandbox `as_list` gave."""
    memory, cpu, scratch, threads, read = values
    return Sandbox(memory, cpu, scratch, threads,
                   None if read is None else tuple(Path(p) for p in read))


def environment(scratch: Path, python_path: str) -> dict[str, str]:
    """The child's environment: the few variables it needs, none of the master's secrets."""
    kept = {k: os.environ[k] for k in KEPT_ENVIRONMENT if k in os.environ}
    return {**kept, "HOME": str(scratch), "TMPDIR": str(scratch), "PYTHONPATH": python_path,
            "FLEXFF_CACHE": str(cache.cache_dir()),  # the compiled proxy, found, not rebuilt
            "PYTHONDONTWRITEBYTECODE": "1", "OPENBLAS_NUM_THREADS": "1"}


def readable(folder: Path, sandbox: Sandbox) -> list[Path] | None:
    """What a sandboxed FMU whose folder is `folder` may read (None: everything its user may):
    that folder, the system's libraries, this Python's and flexff's files, and sandbox.read."""
    if sandbox.read is None:
        return None
    python = {sys.prefix, sys.base_prefix, sys.exec_prefix, *sys.path}
    return [folder, *map(Path, SYSTEM_READ), *(Path(p) for p in sorted(python) if p),
            cache.cache_dir(), *sandbox.read]


def enter(library: ctypes.CDLL, folder: Path, sandbox: Sandbox, report: int) -> list[str]:
    """Confine this process (for good) by the proxy `library`'s sandbox_enter (cosim.isolation
    declares it): `folder` holds the FMU and its scratch folder, `folder/work`; the layers that
    hold."""
    paths = readable(folder, sandbox)
    listed = None if paths is None else b"".join(os.fsencode(p) + b"\0" for p in paths) + b"\0"
    held = library.sandbox_enter(os.fsencode(folder / "work"), int(sandbox.memory_mb * (1 << 20)),
                                 sandbox.cpu_s or 0.0, report, int(sandbox.scratch_mb * (1 << 20)),
                                 sandbox.threads, listed)
    return [name for k, name in enumerate(LAYERS) if held & (1 << k)]


def report(fd: int) -> str:
    """The line a stopped child left on its report pipe, printable and short; "" if none, or
    if it is no line of the sandbox's (the FMU's own code can write there too: it cannot
    make flexff say more than that the sandbox stopped something)."""
    os.set_blocking(fd, False)
    try:
        text = os.read(fd, REPORT_BYTES).decode("ascii", "replace")
    except (BlockingIOError, OSError):
        return ""
    line = text.splitlines()[0] if text.strip() else ""
    line = "".join(c if c.isprintable() else "?" for c in line)
    return line if line.startswith(REPORTS) else ""
