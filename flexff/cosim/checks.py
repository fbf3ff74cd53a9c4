"""The value checks every table of a run configuration shares (tables, known keys, numbers,
integers, choices, files relative to the configuration, points, FMI versions), each failing with a
ConfigError naming the file and `table.key`. cosim.config's parser is one; a machine package's
hooks (cosim.builtins, cosim.plugins) get one to check their own tables the same way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from flexff.cosim.config_error import ConfigError
from flexff.fmu.errors import not_a_file
from flexff.fmu.fmi_version import FMI_VERSIONS


class TableChecker:
    """Checks the values of one configuration's tables; errors name `origin` and the key."""

    def __init__(self, origin: str, base: Path) -> None:
        self.origin, self.base = origin, base

    def error(self, key: str, message: str) -> ConfigError:
        return ConfigError(self.origin, key, message)

    def table(self, data: Mapping[str, Any], name: str) -> Mapping[str, Any]:
        table = data.get(name, {})
        if not isinstance(table, dict):
            raise self.error(name, f"expected a table [{name}], got {table!r}")
        return table

    def keys(self, t: Mapping[str, Any], table: str, allowed: Sequence[str]) -> None:
        for key in t:
            if key not in allowed:
                raise self.error(f"{table}.{key}", f"unknown key (known in [{table}]: "
                                                   f"{', '.join(allowed)})")

    def number(self, t: Mapping[str, Any], table: str, key: str, default: float | None,
               positive: bool = False) -> float:
        if key not in t:
            if default is None:
                raise self.error(f"{table}.{key}", "required")
            return default
        value = t[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(f"{table}.{key}", f"expected a number, got {value!r} "
                                               f"({type(value).__name__})")
        if not math.isfinite(value) or (positive and value <= 0):
            raise self.error(f"{table}.{key}", f"must be {'positive and ' if positive else ''}"
                                               f"finite, got {value!r}")
        return float(value)

    def fmi_version(self, t: Mapping[str, Any], where: str) -> int:
        """The FMI version a built-in is built in: 2 (default) or 3."""
        value: int = self.integer(t, where, "fmi", FMI_VERSIONS[0])
        if value not in FMI_VERSIONS:
            raise self.error(f"{where}.fmi", f"FMI {value}: built-ins are built as FMI 2 or 3")
        return value

    def integer(self, t: Mapping[str, Any], table: str, key: str, default: int | None) -> Any:
        value = t.get(key, default)
        if key in t and (isinstance(value, bool) or not isinstance(value, int)):
            raise self.error(f"{table}.{key}", f"expected an integer, got {value!r} "
                                               f"({type(value).__name__})")
        return value

    def choice(self, t: Mapping[str, Any], table: str, key: str, options: tuple[str, ...],
               default: str | None) -> str:
        value = t.get(key, default)
        if value is None:
            raise self.error(f"{table}.{key}", f"required: one of {', '.join(options)}")
        if value not in options:
            raise self.error(f"{table}.{key}", f"unknown {key} {value!r}: choose one of "
                                               f"{', '.join(options)}")
        return str(value)

    def path(self, t: Mapping[str, Any], table: str, key: str) -> Path:
        value = t.get(key)
        if not isinstance(value, str) or not value:
            raise self.error(f"{table}.{key}", f"expected a file path, got {value!r}")
        path = (self.base / value).resolve()
        why = not_a_file(path)
        if why is not None:
            raise self.error(f"{table}.{key}", f"{why}: {path}")
        return path

    def point(self, t: Mapping[str, Any], table: str, key: str,
              default: tuple[float, float] | None) -> tuple[float, float]:
        if key not in t and default is None:
            raise self.error(f"{table}.{key}", "required: [x, y] in m")
        value = t.get(key, list(default or ()))
        if not (isinstance(value, list) and len(value) == 2 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value)):
            raise self.error(f"{table}.{key}", f"expected [x, y] in m, got {value!r}")
        return float(value[0]), float(value[1])

    def points(self, t: Mapping[str, Any], table: str, key: str, minimum: int = 3
               ) -> tuple[tuple[float, float], ...]:
        value = t.get(key)
        if not isinstance(value, list) or len(value) < minimum:
            raise self.error(f"{table}.{key}", f"expected at least {minimum} [x, y] points, got "
                                               f"{value!r}")
        return tuple(self.point({key: v}, table, key, (0.0, 0.0)) for v in value)
