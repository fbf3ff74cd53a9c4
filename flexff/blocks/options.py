"""The option names of the loop blocks' built-ins and the reading of any block's or machine's
options (`<block>_from_options(options, step)`).

Options come from a run configuration's `[fmu.NAME]` table, so every problem is an InputError
naming the option and what to do. A per-axis option is a number for every axis or a table
{axis = number}; axes left out of the table take the option's default. The names live here,
apart from the blocks (CasADi), so a registry can list them without building anything.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from flexff.fmu.errors import InputError

PID_PER_AXIS_OPTIONS = ("crossover_hz", "mass", "damping", "stiffness", "kp", "ki", "kd",
                        "derivative_filter_hz", "notch_hz", "lowpass_hz", "effort_limit",
                        "tracking_gain")
PID_FORMS = ("series", "parallel")
PID_ANTI_WINDUP = ("conditional", "back-calculation", "clamp")
PID_LOWPASS_ORDERS = (1, 2)
PID_OPTIONS = ("axes", *PID_PER_AXIS_OPTIONS, "form", "anti_windup", "notch_zeta",
               "lowpass_order", "lowpass_zeta", "effort_unit", "position_unit")  # blocks.pid
SUM_OPTIONS = ("inputs", "output", "signs", "unit")  # blocks.sum_gain
GAIN_OPTIONS = ("input", "output", "gain", "unit")  # blocks.sum_gain


class OptionError(InputError):
    """A block's or machine's option is missing, unknown or of the wrong kind."""


def check_keys(options: Mapping[str, Any], allowed: Sequence[str], block: str) -> None:
    """Raise OptionError for the first option `block` does not know."""
    for key in options:
        if key not in allowed:
            raise OptionError(f"{block}: unknown option {key!r}; choose from "
                              f"{', '.join(allowed)}")


def names(options: Mapping[str, Any], key: str, default: Sequence[str] | None = None
          ) -> tuple[str, ...]:
    """A non-empty list of distinct signal names (axes, summed inputs)."""
    value = options.get(key, default)
    if value is None:
        raise OptionError(f"option {key!r} is missing: give a list of names")
    if isinstance(value, str) or not isinstance(value, Sequence) or not value or not all(
            isinstance(v, str) and v.isidentifier() for v in value) or len(set(value)) < len(
            value):
        raise OptionError(f"option {key!r} must be a non-empty list of distinct identifiers, "
                          f"got {value!r}")
    return tuple(value)


def name(options: Mapping[str, Any], key: str, default: str | None = None) -> str:
    """One signal name."""
    value = options.get(key, default)
    if not isinstance(value, str) or not value.isidentifier():
        raise OptionError(f"option {key!r} must be a signal name (an identifier), got {value!r}")
    return value


def unit(options: Mapping[str, Any], key: str, default: str) -> str:
    """A unit string (free text, as in modelDescription.xml)."""
    value = options.get(key, default)
    if not isinstance(value, str):
        raise OptionError(f"option {key!r} must be a unit string such as {default!r}, got "
                          f"{value!r}")
    return value


def number(options: Mapping[str, Any], key: str, default: float | None = None,
           positive: bool = False) -> float | None:
    """A finite number (positive if asked), or `default` when the option is absent."""
    return _checked_number(options.get(key, default), key, positive)


def per_axis(options: Mapping[str, Any], key: str, axes: Sequence[str],
             default: float | None = None, positive: bool = False) -> dict[str, float | None]:
    """A per-axis number: one value for every axis, or a table {axis = value}."""
    value = options.get(key, default)
    if isinstance(value, Mapping):
        unknown = [a for a in value if a not in axes]
        if unknown:
            raise OptionError(f"option {key!r} names unknown axes {unknown}: the axes are "
                              f"{', '.join(axes)}")
        return {a: _checked_number(value.get(a, default), f"{key}.{a}", positive) for a in axes}
    return {a: _checked_number(value, key, positive) for a in axes}


def _checked_number(value: Any, key: str, positive: bool) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(
            value) or (positive and value <= 0):
        raise OptionError(f"option {key!r} must be a finite{' positive' if positive else ''} "
                          f"number, got {value!r}")
    return float(value)
