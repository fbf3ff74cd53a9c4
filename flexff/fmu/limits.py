"""Bounds on the sizes that input files set (an ONNX tensor's elements, a CSV table's columns),
checked before memory is spent on them: an 83-byte ONNX file that declares 10^9 inputs is one
line naming the limit, not a machine out of memory. Each limit is generous for real use and can
be raised with an environment variable, which the message names."""

from __future__ import annotations

import os
from dataclasses import dataclass

from flexff.fmu.errors import InputError


@dataclass(frozen=True)
class Limit:
    """The most `what` one input may have; the environment variable `variable` overrides
    `default`."""

    variable: str
    default: int
    what: str

    def value(self) -> int:
        given = os.environ.get(self.variable)
        if given is None:
            return self.default
        try:
            return int(given)
        except ValueError:
            raise InputError(f"{self.variable}={given!r}: expected a whole number") from None

    def check(self, size: int, where: str) -> None:
        """InputError naming `where`, the size, the limit and how to raise it, if `size` is
        over the limit."""
        limit = self.value()
        if size > limit:
            raise InputError(f"{where}: {size:,} {self.what}, more than the limit of {limit:,}; "
                             f"if that is meant, raise it: {self.variable}={size} flexff ...")


ONNX_ELEMENTS = Limit("FLEXFF_MAX_ONNX_ELEMENTS", 100_000,
                      "tensor elements (each an FMU variable)")
CSV_COLUMNS = Limit("FLEXFF_MAX_CSV_COLUMNS", 100_000, "columns")
# a CSV reference's smoothing window in samples: its filter costs a window's products per
# sample (a 10^-9 s step made 25 * 10^6, which crashed scipy)
SMOOTHING_SAMPLES = Limit("FLEXFF_MAX_SMOOTHING_SAMPLES", 10_001, "samples")
