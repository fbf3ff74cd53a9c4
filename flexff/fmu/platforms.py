"""The platforms an FMU's binaries are built for, each with its compiler and link libraries.

An FMU holds one library per platform in binaries/<platform>/. FMI 2.0 names linux64 and win64;
it has no name for 64-bit Arm Linux, for which flexff uses "aarch64-linux", the name FMPy (its
`fmpy.platform` there) and the FMI 3.0 standard use. The host's own platform
(`fmpy.platform`) is compiled by $CC or gcc (fmu.compile.compiler); the others by the GNU
cross-compilers Debian packages, each named here with its package, so that a missing one is a
one-line error saying what to install. Free of fmpy at import, so that the command line can
name the platforms without loading it.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import dataclass

from flexff.fmu.errors import InputError

ALL = "all"  # every platform below, as --platform all


@dataclass(frozen=True)
class Platform:
    """One platform of binaries/: its folder name, library suffix and cross-compiler."""

    name: str  # FMI 2.0's folder name (flexff's for aarch64-linux)
    fmi3: str  # FMI 3.0's platform tuple
    extension: str
    cross_compiler: str  # the compiler where this is not the host's platform
    package: str  # the Debian package that installs cross_compiler
    libraries: tuple[str, ...]  # linked into the FMU's library

    def compiler(self) -> str:
        """The C compiler command: the host's for the host's platform, else the cross one."""
        from flexff.fmu.compile import compiler

        return compiler() if self.name == host() else self.cross_compiler


PLATFORMS = {p.name: p for p in (
    Platform("linux64", "x86_64-linux", ".so", "x86_64-linux-gnu-gcc", "gcc-x86-64-linux-gnu",
             ("-lm", "-ldl", "-lpthread")),
    Platform("aarch64-linux", "aarch64-linux", ".so", "aarch64-linux-gnu-gcc",
             "gcc-aarch64-linux-gnu",
             ("-lm", "-ldl", "-lpthread")),
    # mingw's own runtime (libgcc, and winpthreads for a network's task) linked in, so the DLL
    # needs only what Windows ships; -s drops the debugging sections mingw's start-up objects
    # bring (306 KB -> 106 KB for the plant)
    Platform("win64", "x86_64-windows", ".dll", "x86_64-w64-mingw32-gcc", "gcc-mingw-w64-x86-64",
             ("-lm", "-static-libgcc", "-Wl,-Bstatic", "-lpthread", "-Wl,-Bdynamic", "-s")),
)}


def host() -> str:
    """The platform this Python runs on (FMPy's name for it)."""
    import fmpy

    return str(fmpy.platform)


def resolve(names: Sequence[str] | None) -> tuple[str, ...]:
    """The platforms to build, in PLATFORMS' order: None is the host's alone, "all" every one,
    () none (a source-only FMU). InputError for an unknown name or a platform whose compiler is
    not installed, naming the compiler and its Debian package."""
    wanted = {host()} if names is None else set(PLATFORMS) if ALL in names else set(names)
    unknown = sorted(wanted - set(PLATFORMS))
    if unknown:
        raise InputError(f"unknown platform {', '.join(unknown)}: expected "
                         f"{', '.join([*PLATFORMS, ALL])}")
    chosen = tuple(name for name in PLATFORMS if name in wanted)
    for name in chosen:
        command = PLATFORMS[name].compiler()
        if shutil.which(command) is None:
            package = "gcc, or set $CC" if name == host() else PLATFORMS[name].package
            raise InputError(f"platform {name} needs the C compiler {command}, which is not "
                             f"installed (Debian: apt-get install {package})")
    return chosen
