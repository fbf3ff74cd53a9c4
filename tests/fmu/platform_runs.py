"""Running an FMU's library of another platform on this machine, for tests/fmu/test_platforms.py.

tests/fmu/fmu_runner.c, a minimal FMI 2.0 importer, is compiled for the platform by the same
compiler as the FMU and run natively (linux64), under qemu-user (aarch64-linux) or under Wine
(win64); it returns the outputs at every communication point, exactly (hex bits of each double).
Each helper skips the test with the reason where a tool is absent.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest

from flexff.fmu.compile import HOST_HEADER, fmi_headers
from flexff.fmu.platforms import PLATFORMS, host

RUNNER = Path(__file__).with_name("fmu_runner.c")
QEMU = ("qemu-aarch64", "-L", "/usr/aarch64-linux-gnu")  # Debian's aarch64 libc as the root
WINE64 = Path("/usr/lib/wine/wine64")  # where Debian's wine64 puts it (no /usr/bin link)
TIMEOUT = 300  # [s] a first Wine run also creates its prefix (~10 s)


def available_platforms() -> list[str]:
    """The platforms whose compiler is installed here."""
    return [name for name in PLATFORMS if shutil.which(PLATFORMS[name].compiler())]


def wine() -> str | None:
    """The Wine command for 64-bit programs, None where Wine is not installed."""
    return shutil.which("wine64") or (str(WINE64) if WINE64.exists() else None)


def launcher(platform: str) -> list[str]:
    """The command prefix that runs a program of `platform` here; skips where none is."""
    if platform == host():
        return []
    if platform == "aarch64-linux" and shutil.which(QEMU[0]):
        return list(QEMU)
    if platform == "win64" and wine() is not None:
        return [str(wine())]
    pytest.skip(f"nothing runs {platform} programs here (qemu-user, wine64 on Debian)")


def compile_runner(platform: str, folder: Path) -> Path:
    """fmu_runner.c built for `platform` into `folder`; skips where its compiler is absent."""
    command = PLATFORMS[platform].compiler()
    if shutil.which(command) is None:
        pytest.skip(f"no {command} here (Debian: {PLATFORMS[platform].package})")
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in fmi_headers().items():
        (folder / name).write_text(text)
    program = folder / ("fmu_runner.exe" if platform == "win64" else "fmu_runner")
    libraries = ["-static-libgcc"] if platform == "win64" else ["-ldl"]
    subprocess.run([command, "-O2", "-std=c99", "-Wall", "-Werror", f"-I{folder}",
                    f"-I{HOST_HEADER.parent}", str(RUNNER), "-o", str(program), *libraries],
                   check=True)
    return program


def _hex(values: np.ndarray) -> str:
    return " ".join(struct.pack(">d", v).hex() for v in values.ravel())


def run_library(program: Path, platform: str, fmu: Path, folder: Path,
                inputs: np.ndarray) -> np.ndarray:
    """The FMU's outputs (steps x outputs) from its `platform` library, run by `program` with
    `inputs` (steps x inputs, in the order of the FMU's inputs) at its default step size."""
    description = fmpy.read_model_description(str(fmu))
    identifier = description.coSimulation.modelIdentifier
    unpacked = folder / f"{fmu.stem}-{platform}"
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(unpacked)
    library = unpacked / "binaries" / platform / f"{identifier}{PLATFORMS[platform].extension}"
    by_causality = {c: [v.valueReference for v in description.modelVariables
                        if v.causality == c and v.type == "Real"] for c in ("input", "output")}
    plan = [f"{len(by_causality['input'])} {len(by_causality['output'])} {len(inputs)}",
            " ".join(map(str, by_causality["input"])), " ".join(map(str, by_causality["output"])),
            *map(_hex, inputs)]
    step = str(description.defaultExperiment.stepSize)
    done = subprocess.run([*launcher(platform), str(program), str(library), description.guid,
                           (unpacked / "resources").as_uri(), step],
                          input="\n".join(plan) + "\n", capture_output=True, text=True,
                          timeout=TIMEOUT, env=_environment(folder), cwd=folder)
    assert done.returncode == 0, done.stderr
    rows = [[struct.unpack(">d", bytes.fromhex(h))[0] for h in line.split()]
            for line in done.stdout.splitlines()]
    return np.array(rows)


def _environment(folder: Path) -> dict[str, str]:
    """Wine's prefix in the test's folder and its messages off; the rest as it is."""
    return {**os.environ, "WINEPREFIX": str(folder / "wine-prefix"), "WINEDEBUG": "-all"}
