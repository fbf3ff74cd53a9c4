"""The wiring of a run, in the style of python-control's `interconnect`: explicit connections
where the configuration gives them, names everywhere else, and the result kept as data (a list
of Links) that can be printed and checked.

Every input gets one Link, from a [[connection]] or by name; an input with no producer, a
mismatch of units or types, and a feedthrough output fed back against the stepping order are
errors. What a Link does with each pair of types is one rule (`refusal`, `carried`): float64
and float32 feed each other with gain and offset; every other type feeds its own, unchanged.

The rules and why: "The master algorithm", section Connections and types
(docs/explanation/master-algorithm.md).
"""

from __future__ import annotations

import difflib
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexff.cosim.schema import ConnectionConfig
from flexff.fmu.errors import InputError
from flexff.fmu.importer import FmuInfo

SOURCE = "sources"  # producer name of the external signals
SOURCE_KIND = "float64"  # the kind of every source signal
FLOAT_KINDS = ("float64", "float32")  # the kinds that convert into each other (module doc)
FLOAT32_MAX = float(np.finfo(np.float32).max)


class WiringError(InputError):
    """A connection problem; `key` names the configuration table at fault."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}")
        self.key, self.message = key, message


@dataclass(frozen=True)
class Port:
    """One FMU of the run as the wiring sees it: its name and its model description."""

    name: str
    info: FmuInfo
    unconnected: str = "error"  # or "start": unconnected inputs keep their start values
    given: frozenset[str] = frozenset()  # inputs the configuration gives a value
    feedthrough: bool = True  # False: no output depends directly on an input, whatever the
    # model structure says ([fmu.NAME] feedthrough = false)

    def depends(self, output: str) -> bool:
        """Whether `output` depends directly on an input of this FMU."""
        return self.feedthrough and bool(self.info.dependencies[output])


@dataclass(frozen=True)
class Link:
    """One input's feed: `producer`.`signal` (producer SOURCE: an external signal) into
    `consumer`.`input`, as gain * value + offset; `kind` is the producer's kind, `into` the
    input's (`carried`)."""

    producer: str
    signal: str
    consumer: str
    input: str
    kind: str = "float64"
    gain: float = 1.0
    offset: float = 0.0
    feedback: bool = False
    into: str = "float64"

    @property
    def from_name(self) -> str:
        """The signal as a connection's `from` names it: a source signal, or `fmu.output`."""
        return self.signal if self.producer == SOURCE else f"{self.producer}.{self.signal}"

    @property
    def affine(self) -> bool:
        return self.gain != 1.0 or self.offset != 0.0

    @property
    def on_bus(self) -> bool:
        """float64 into float64: carried on the bus, in compiled code (cosim.master)."""
        return self.kind == self.into == "float64"

    def __str__(self) -> str:
        scale = f" (x {self.gain:g} + {self.offset:g})" if self.affine else ""
        into = f" [{self.kind} -> {self.into}]" if self.kind != self.into else ""
        return (f"{self.from_name} -> {self.consumer}.{self.input}{scale}{into}"
                f"{' [feedback]' if self.feedback else ''}")


def refusal(kind: str, into: str, affine: bool) -> str | None:
    """Why a value of `kind` cannot feed an input of kind `into` (through a gain or offset if
    `affine`) under the module doc's rule; None where it can."""
    if kind != into and not (kind in FLOAT_KINDS and into in FLOAT_KINDS):
        return (f"type mismatch: {kind} cannot feed {into} (only float64 and float32 convert "
                f"into each other; other kinds connect to their own kind only)")
    if affine and into not in FLOAT_KINDS:
        return (f"gain and offset apply to float64 and float32 signals only, not to {into} "
                f"(an FMU can do the arithmetic and the rounding it means)")
    return None


def carried(link: Link, value: Any) -> Any:
    """The value `link` gives its input for its producer's `value` (module doc): a float
    through gain and offset in float64, then converted to the input's kind; any other value
    unchanged. OverflowError for a finite value beyond the range of a float32 input."""
    if link.into not in FLOAT_KINDS:
        return value
    result = link.gain * float(value) + link.offset if link.affine else float(value)
    if link.into == "float64":
        return result
    with np.errstate(over="ignore"):
        narrowed = np.float32(result)
    if np.isinf(narrowed) and np.isfinite(result):
        raise OverflowError(f"{result!r} is beyond the range of float32 (+-{FLOAT32_MAX!r})")
    return float(narrowed)


def wire(ports: Sequence[Port], sources: Collection[str],
         connections: Sequence[ConnectionConfig] = (), algorithm: str = "gauss-seidel"
         ) -> list[Link]:
    """Every connected input's Link, in order of the FMUs and their inputs (module doc)."""
    names = [p.name for p in ports]
    if len(set(names)) != len(names) or SOURCE in names:
        raise WiringError("fmu", f"FMU names must be unique and not {SOURCE!r}: {names}")
    by_name = {p.name: p for p in ports}
    position = {n: i for i, n in enumerate(names)}
    explicit = {c.to_name: c for c in connections}
    for target in connections:  # a mistyped target first: it is why its input is unconnected
        consumer, _, name = target.to_name.partition(".")
        if name not in by_name[consumer].info.inputs:
            raise WiringError(f"{target.key}.to", _unknown(by_name[consumer], name, "input"))
    producers = _producers(ports, sources)
    links = []
    for port in ports:
        for name in port.info.inputs:
            c = explicit.get(f"{port.name}.{name}")
            if c is not None:
                link = _explicit(c, by_name, sources)
            elif name in port.given:
                continue
            else:
                found = producers.get(name, [])
                if len(found) > 1:
                    raise WiringError(f"fmu.{port.name}", f"input {name!r} matches "
                                      f"{' and '.join(found)} by name: add a [[connection]] "
                                      f"to {port.name}.{name} to choose")
                if not found:
                    if port.unconnected == "start":
                        continue
                    raise WiringError(f"fmu.{port.name}", f"input {name!r} is not connected: "
                                      f"no [[connection]] to it and no source signal or FMU "
                                      f"output of that name (connect it, give it a value in "
                                      f"parameters, or set unconnected = \"start\" to keep the "
                                      f"start values of unconnected inputs)")
                producer, _, signal = found[0].rpartition(".")
                link = Link(producer or SOURCE, signal, port.name, name)
                c = None
            links.append(_checked(link, c, by_name, position, algorithm))
    return links


def _producers(ports: Sequence[Port], sources: Collection[str]) -> dict[str, list[str]]:
    """Every signal name -> who produces it ("fmu.output", or the source signal's name)."""
    out: dict[str, list[str]] = {name: [name] for name in sources}
    for port in ports:
        for name in port.info.outputs:
            out.setdefault(name, []).append(f"{port.name}.{name}")
    return out


def _explicit(c: ConnectionConfig, ports: Mapping[str, Port], sources: Collection[str]
              ) -> Link:
    consumer, _, name = c.to_name.partition(".")
    if name not in ports[consumer].info.inputs:
        raise WiringError(f"{c.key}.to", _unknown(ports[consumer], name, "input"))
    if "." in c.from_name:
        producer, _, signal = c.from_name.partition(".")
        if signal not in ports[producer].info.outputs:
            raise WiringError(f"{c.key}.from", _unknown(ports[producer], signal, "output"))
    elif c.from_name in sources:
        producer, signal = SOURCE, c.from_name
    else:
        raise WiringError(f"{c.key}.from", f"{c.from_name!r} is neither \"fmu.output\" nor a "
                          f"source signal (sources: {', '.join(sources) or 'none'})")
    return Link(producer, signal, consumer, name, gain=c.gain, offset=c.offset)


def _unknown(port: Port, name: str, causality: str) -> str:
    known = getattr(port.info, f"{causality}s")
    close = difflib.get_close_matches(name, known, n=1)
    return (f"{port.info.path.name} ({port.name}) has no {causality} {name!r}"
            f"{f' (did you mean {close[0]!r}?)' if close else ''} (its {causality}s: "
            f"{', '.join(known) or 'none'})")


def _undeclared(ports: Mapping[str, Port]) -> str:
    """The hint for FMUs whose outputs declare no dependencies (FMI: on every input), which
    make every stepping order a loop where their outputs do not in fact depend on inputs."""
    names = [n for n, p in ports.items() if p.feedthrough and p.info.undeclared]
    if not names:
        return ""
    tables = " or ".join(f"[fmu.{n}]" for n in names)
    return (f"; {' and '.join(names)} {'declares' if len(names) == 1 else 'declare'} no output "
            f"dependencies, which FMI reads as depending on every input: where outputs do not "
            f"depend directly on inputs (positions, states), set feedthrough = false in {tables}")


def _checked(link: Link, c: ConnectionConfig | None, ports: Mapping[str, Port],
             position: Mapping[str, int], algorithm: str) -> Link:
    """The link with its kind and feedback flag, after the type, unit and loop checks."""
    key = c.key if c is not None else f"fmu.{link.consumer}"
    to = ports[link.consumer].info.variables[link.input]
    if link.producer == SOURCE:
        kind, unit, feeds_back = SOURCE_KIND, None, False
    else:
        producer = ports[link.producer].info
        frm = producer.variables[link.signal]
        kind, unit = frm.kind, frm.unit
        feeds_back = algorithm == "jacobi" or position[link.producer] >= position[link.consumer]
        if feeds_back and algorithm != "jacobi" and ports[link.producer].depends(link.signal):
            raise WiringError(key, f"{link.from_name} feeds {link.consumer}.{link.input}, which "
                              f"steps before {link.producer} (run.order), and depends directly on "
                              f"{link.producer}'s inputs: an algebraic loop; reorder the FMUs, or "
                              f"run with algorithm = \"jacobi\"{_undeclared(ports)}")
        if not frm.scalar or not to.scalar:
            raise WiringError(key, f"{link.from_name} -> {link.consumer}.{link.input}: array "
                                   f"variables cannot be connected")
    refused = refusal(kind, to.kind, link.affine)
    if refused:
        raise WiringError(key, f"{link.from_name} ({kind}) -> {link.consumer}.{link.input} "
                               f"({to.type}): {refused}")
    if unit and to.unit and unit != to.unit:
        raise WiringError(key, f"units differ: {link.from_name} is in {unit}, "
                               f"{link.consumer}.{link.input} in {to.unit}")
    return Link(link.producer, link.signal, link.consumer, link.input, kind, link.gain,
                link.offset, feeds_back, to.kind)
