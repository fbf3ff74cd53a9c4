"""The error of a configuration problem, in a module of its own: every layer that checks a
configuration raises it (cosim.schema, cosim.machine, cosim.config and learning's loops),
without importing the schema it checks."""

from __future__ import annotations

from flexff.fmu.errors import InputError


class ConfigError(InputError):
    """A configuration problem, naming the file and the `table.key` at fault."""

    def __init__(self, origin: str, key: str, message: str) -> None:
        super().__init__(f"{origin}: {key}: {message}")
        self.key = key
