"""The C compiler step: FMI headers from fmpy, flags, and one gcc call per shared library.

`-fvisibility=hidden` keeps everything but the FMI functions private, so two FMUs loaded in one
process cannot bind to each other's CasADi symbols; `-ffp-contract=off` keeps floating point
results identical to CasADi's own evaluation on machines with fused multiply-add.
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import fmpy

from flexff.fmu import cache
from flexff.fmu.errors import InputError, RunError

# the FMI headers of each version's FMU sources, as fmpy ships them; an FMI 3.0 FMU has the FMI
# 2.0 types too, for the core its FMI 3.0 functions call (c/fmi3Functions.c)
FMI_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
               3: ("fmi2FunctionTypes.h", "fmi2TypesPlatform.h", "fmi3Functions.h",
                   "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
CFLAGS = ("-O2", "-std=c99", "-fPIC", "-fvisibility=hidden", "-ffp-contract=off")


SANITIZE_ENV = "FLEXFF_SANITIZE"


def sanitizer_flags() -> tuple[str, ...]:
    """Flags of a sanitizer build of the FMU binaries: `$FLEXFF_SANITIZE=address,undefined`
    (any list of gcc's -fsanitize= names) adds `-fsanitize=address,undefined
    -fno-omit-frame-pointer -g`; unset or empty, none. They are part of the build's cache key,
    so sanitized and plain builds never replace each other. A host that loads a sanitized FMU
    must preload the runtime: `LD_PRELOAD="$(gcc -print-file-name=libasan.so)
    $(gcc -print-file-name=libubsan.so)"` (and `ASAN_OPTIONS=detect_leaks=0` for Python)."""
    value = os.environ.get(SANITIZE_ENV, "").strip()
    if not value:
        return ()
    if not re.fullmatch(r"[a-z0-9_-]+(,[a-z0-9_-]+)*", value):
        raise InputError(f"${SANITIZE_ENV} = {value!r}: expected a comma-separated list of "
                         f"sanitizers such as 'address,undefined'")
    return (f"-fsanitize={value}", "-fno-omit-frame-pointer", "-g")


def compiler() -> str:
    """The C compiler command: $CC or gcc."""
    return os.environ.get("CC", "gcc")


@functools.cache
def compiler_version(command: str | None = None) -> str:
    """First line of `command --version` (default: compiler()), part of every cache key;
    remembered in the cache per compiler binary (its path, size and time), so that a run of
    cached FMUs starts no compiler."""
    command = command or compiler()
    binary = shutil.which(command)
    remembered = None
    if binary is not None:
        stat = os.stat(binary)
        remembered = cache.cached_path(cache.digest({
            "binary": binary, "size": str(stat.st_size), "mtime": str(stat.st_mtime_ns)}),
            ".compiler-version")
        if remembered.is_file():
            return remembered.read_text()
    out = subprocess.run([command, "--version"], capture_output=True, text=True, check=True)
    version = out.stdout.splitlines()[0]
    if remembered is not None:
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "version").write_text(version)
            cache.store(remembered.name.removesuffix(".compiler-version"), ".compiler-version",
                        Path(tmp) / "version")
    return version


def fmi_headers(fmi_version: int = 2) -> dict[str, str]:
    """The headers of an FMI `fmi_version` (2 or 3) FMU's sources, shipped with fmpy, by file
    name."""
    folder = Path(fmpy.__file__).parent / "c-code"
    return {name: (folder / name).read_text() for name in FMI_HEADERS[fmi_version]}


def run_compiler(sources: list[Path], output: Path, include_dirs: list[Path],
                 extra_flags: tuple[str, ...] = ("-shared",),
                 libraries: tuple[str, ...] = ("-lm",), command: str | None = None) -> None:
    """Compile `sources` into `output` (a shared library by default) with `command` (default:
    compiler()); raise with gcc's messages."""
    cmd = [command or compiler(), *CFLAGS, *extra_flags, *(f"-I{d}" for d in include_dirs),
           *map(str, sources), "-o", str(output), *libraries]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise RunError(f"compilation failed: {' '.join(cmd)}\n{result.stderr}")


HOST_HEADER = Path(__file__).parent / "c" / "fmi2_host_logger.h"


def cached_program(name: str, sources: Sequence[Path], headers: Sequence[Path] = ()) -> Path:
    """A stand-alone C program (FMI headers, fmi2_host_logger.h and the folders of `headers` on
    the include path, linked with -ldl) compiled from `sources` into the build cache; rebuilt
    only when a source, a header or the compiler changes."""
    files = [*sources, *headers, HOST_HEADER]
    key = cache.digest({**{f.name: f.read_text() for f in files},
                        "cflags": " ".join(CFLAGS), "compiler": compiler_version()})
    program = cache.cached_path(key, f".{name}")
    if not program.exists():
        with tempfile.TemporaryDirectory() as tmp:
            for header, header_text in fmi_headers().items():
                (Path(tmp) / header).write_text(header_text)
            exe = Path(tmp) / name
            folders = dict.fromkeys(h.parent for h in [*headers, HOST_HEADER])
            run_compiler(list(sources), exe, [Path(tmp), *folders], extra_flags=(),
                         libraries=("-ldl",))
            cache.store(key, f".{name}", exe)
    return program
