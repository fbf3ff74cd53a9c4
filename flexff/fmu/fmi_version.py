"""The FMI versions flexff builds FMUs in, without the builder's imports (the CLI's choices)."""

from __future__ import annotations

from flexff.fmu.errors import InputError

FMI_VERSIONS = (2, 3)  # FMI 2.0 (the default) and 3.0 co-simulation


def check_fmi_version(fmi_version: int) -> int:
    """`fmi_version` if flexff builds FMUs in it, else InputError."""
    if fmi_version not in FMI_VERSIONS:
        raise InputError(f"FMI version {fmi_version!r}: flexff builds FMI 2.0 and 3.0 FMUs "
                         f"(2 or 3)")
    return fmi_version
