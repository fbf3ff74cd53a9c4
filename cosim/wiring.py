"""The wiring of a run, in the style of python-control's `interconnect`: explicit connections
where the configuration gives them, names everywhere else, and the result kept as data (a list
of Links) that can be printed and checked.

Every input of every FMU gets one Link: from an explicit [[connection]] ("fmu.output" or a
source signal, with an optional gain and offset), else by name from the one source signal or
FMU output of the same name. An input with no producer is an error, unless its FMU keeps the
start values of unconnected inputs or the configuration gives it a value. Units must agree
where both sides declare one.

What a Link does with each pair of kinds (fmu.importer.TYPE_KINDS: an FMI 2.0 Real and an FMI
3.0 Float64 are both float64, an FMI 2.0 Integer and an FMI 3.0 Int32 both int32; source
signals are float64), one rule, `refusal` and `carried`:
  - float64 and float32 feed each other: gain * value + offset is computed in float64 (a
    float32 value widens exactly), then converted to the input's kind. Into float32 that is
    rounding to the nearest float32, ties to even (numpy.float32); a finite value beyond
    float32's range stops the run with an error naming the connection and the time, rather
    than giving the input an infinity.
  - every other kind (int8 .. uint64, boolean, string, binary, enumeration, clock) feeds the
    same kind only, unchanged, with no gain or offset; anything else is refused when the run
    is wired, naming the connection. For integers that is a choice: SSP 1.0 defines its
    LinearTransformation for continuous (Real) connectors only, float64 arithmetic would
    silently change int64 and uint64 values beyond 2**53, and how to round (nearest, floor,
    toward zero) or to narrow a width is a modelling decision that belongs in an FMU.

Order (Gauss-Seidel): a Link whose producer steps at or after its consumer is `feedback`: it
carries the producer's value from the end of its previous step. Such an output must not depend
directly on its FMU's inputs, or the order would hide an algebraic loop. Under Jacobi every
Link carries the value read after the previous step, so there is no loop to hide.
"""

from __future__ import annotations

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
    for c in connections:
        consumer, _, name = c.to_name.partition(".")
        if name not in by_name[consumer].info.inputs:
            raise WiringError(f"{c.key}.to", _unknown(by_name[consumer], name, "input"))
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
    return (f"{port.info.path.name} ({port.name}) has no {causality} {name!r} (its "
            f"{causality}s: {', '.join(known) or 'none'})")


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
        if feeds_back and algorithm != "jacobi" and producer.dependencies[link.signal]:
            raise WiringError(key, f"{link.from_name} feeds {link.consumer}.{link.input}, which "
                              f"steps before {link.producer} (run.order), and depends directly on "
                              f"{link.producer}'s inputs: an algebraic loop; reorder the FMUs, or "
                              f"run with algorithm = \"jacobi\"")
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
