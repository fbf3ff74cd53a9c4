"""Connections by signal name, in the style of python-control's `interconnect`.

FMUs run in a fixed order. An input takes the output of the same name of an FMU earlier in the
order (at the same communication point), else an external source signal (the reference), else
the output of an FMU later in the order (or itself), which is then a feedback connection: it
carries that FMU's value from the end of its previous step. A feedback output must not depend
directly on its FMU's inputs, or the order would hide an algebraic loop. Every input must be
connected, and every signal must have a single producer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

SOURCE = "sources"  # producer name of the external signals


@dataclass(frozen=True)
class Port:
    """The named signals of one FMU; `feedthrough` lists outputs that depend on inputs."""

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    feedthrough: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Connection:
    """Signal `signal` from `source` (an FMU name or SOURCE) to an input of `target`."""

    signal: str
    source: str
    target: str
    feedback: bool = False


def producers(sources: Sequence[str], ports: Sequence[Port]) -> dict[str, str]:
    """Who produces each signal; a ValueError if a name is produced twice."""
    owner: dict[str, str] = {}
    for name in sources:
        if name in owner:
            raise ValueError(f"source signal {name!r} is given twice")
        owner[name] = SOURCE
    for port in ports:
        for name in port.outputs:
            if name in owner:
                raise ValueError(f"signal {name!r} is produced by both {owner[name]!r} and "
                                 f"{port.name!r}: signal names must be unique")
            owner[name] = port.name
    return owner


def connect(sources: Sequence[str], ports: Sequence[Port]) -> list[Connection]:
    """Every input's connection, in order of the FMUs and their inputs (see module doc)."""
    names = [p.name for p in ports]
    if len(set(names)) != len(names) or SOURCE in names:
        raise ValueError(f"FMU instance names must be unique and not {SOURCE!r}: {names}")
    owner = producers(sources, ports)
    position = {p.name: i for i, p in enumerate(ports)}
    feedthrough = {p.name: p.feedthrough for p in ports}
    connections = []
    for i, port in enumerate(ports):
        for name in port.inputs:
            source = owner.get(name)
            if source is None:
                raise ValueError(f"input {name!r} of {port.name!r} is not connected: no source "
                                 f"signal and no FMU output has that name")
            feedback = source != SOURCE and position[source] >= i
            if feedback and name in feedthrough[source]:
                raise ValueError(
                    f"input {name!r} of {port.name!r} would be fed back from {source!r}, which "
                    f"comes later in the order and whose output {name!r} depends directly on "
                    f"its inputs (an algebraic loop)")
            connections.append(Connection(name, source, port.name, feedback))
    return connections
