"""The wiring of a run, in the style of python-control's `interconnect`: explicit connections
where the configuration gives them, names everywhere else, and the result kept as data (a list
of Links) that can be printed and checked.

Every input of every FMU gets one Link: from an explicit [[connection]] ("fmu.output" or a
source signal, with an optional gain and offset), else by name from the one source signal or
FMU output of the same name. An input with no producer is an error, unless its FMU keeps the
start values of unconnected inputs or the configuration gives it a value. Connected values
must be of the same kind (cosim's importer: an FMI 2.0 Real and an FMI 3.0 Float64 agree),
gains and offsets apply to floats, and units must agree where both sides declare one.

Order (Gauss-Seidel): a Link whose producer steps at or after its consumer is `feedback`: it
carries the producer's value from the end of its previous step. Such an output must not depend
directly on its FMU's inputs, or the order would hide an algebraic loop. Under Jacobi every
Link carries the value read after the previous step, so there is no loop to hide.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

from flexff.cosim.schema import ConnectionConfig
from flexff.fmu.errors import InputError
from flexff.fmu.importer import FmuInfo

SOURCE = "sources"  # producer name of the external signals
FLOAT_KINDS = ("float64", "float32")


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
    """One input's producer: `source`.`signal` (source SOURCE: an external signal) into
    `target`.`input`, as gain * value + offset."""

    source: str
    signal: str
    target: str
    input: str
    kind: str = "float64"
    gain: float = 1.0
    offset: float = 0.0
    feedback: bool = False

    @property
    def producer(self) -> str:
        """The signal's name on the bus: a source signal, or `fmu.output`."""
        return self.signal if self.source == SOURCE else f"{self.source}.{self.signal}"

    @property
    def affine(self) -> bool:
        return self.gain != 1.0 or self.offset != 0.0

    def __str__(self) -> str:
        scale = f" (x {self.gain:g} + {self.offset:g})" if self.affine else ""
        return (f"{self.producer} -> {self.target}.{self.input}{scale}"
                f"{' [feedback]' if self.feedback else ''}")


def wire(ports: Sequence[Port], sources: Collection[str],
         connections: Sequence[ConnectionConfig] = (), algorithm: str = "gauss-seidel"
         ) -> list[Link]:
    """Every connected input's Link, in order of the FMUs and their inputs (module doc)."""
    names = [p.name for p in ports]
    if len(set(names)) != len(names) or SOURCE in names:
        raise WiringError("fmu", f"FMU names must be unique and not {SOURCE!r}: {names}")
    by_name = {p.name: p for p in ports}
    position = {n: i for i, n in enumerate(names)}
    explicit = {c.target: c for c in connections}
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
                source, _, signal = found[0].rpartition(".")
                link = Link(source or SOURCE, signal, port.name, name)
                c = None
            links.append(_checked(link, c, by_name, position, algorithm))
    for c in connections:
        target, _, name = c.target.partition(".")
        if name not in by_name[target].info.inputs:
            raise WiringError(f"{c.key}.to", _unknown(by_name[target], name, "input"))
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
    target, _, name = c.target.partition(".")
    if name not in ports[target].info.inputs:
        raise WiringError(f"{c.key}.to", _unknown(ports[target], name, "input"))
    if "." in c.source:
        source, _, signal = c.source.partition(".")
        if signal not in ports[source].info.outputs:
            raise WiringError(f"{c.key}.from", _unknown(ports[source], signal, "output"))
    elif c.source in sources:
        source, signal = SOURCE, c.source
    else:
        raise WiringError(f"{c.key}.from", f"{c.source!r} is neither \"fmu.output\" nor a "
                          f"source signal (sources: {', '.join(sources) or 'none'})")
    return Link(source, signal, target, name, gain=c.gain, offset=c.offset)


def _unknown(port: Port, name: str, causality: str) -> str:
    known = getattr(port.info, f"{causality}s")
    return (f"{port.info.path.name} ({port.name}) has no {causality} {name!r} (its "
            f"{causality}s: {', '.join(known) or 'none'})")


def _checked(link: Link, c: ConnectionConfig | None, ports: Mapping[str, Port],
             position: Mapping[str, int], algorithm: str) -> Link:
    """The link with its kind and feedback flag, after the type, unit and loop checks."""
    key = c.key if c is not None else f"fmu.{link.target}"
    to = ports[link.target].info.variables[link.input]
    if link.source == SOURCE:
        kind, unit, feeds_back = "float64", None, False
    else:
        producer = ports[link.source].info
        frm = producer.variables[link.signal]
        kind, unit = frm.kind, frm.unit
        feeds_back = algorithm == "jacobi" or position[link.source] >= position[link.target]
        if feeds_back and algorithm != "jacobi" and producer.dependencies[link.signal]:
            raise WiringError(key, f"{link.producer} feeds {link.target}.{link.input}, which "
                              f"steps before {link.source} (run.order), and depends directly on "
                              f"{link.source}'s inputs: an algebraic loop; reorder the FMUs, or "
                              f"run with algorithm = \"jacobi\"")
        if not frm.scalar or not to.scalar:
            raise WiringError(key, f"{link.producer} -> {link.target}.{link.input}: array "
                                   f"variables cannot be connected")
    if kind != to.kind:
        raise WiringError(key, f"type mismatch: {link.producer} is {kind}, "
                               f"{link.target}.{link.input} is {to.kind} ({to.type})")
    if link.affine and kind not in FLOAT_KINDS:
        raise WiringError(key, f"gain and offset apply to float signals, {link.producer} is "
                               f"{kind}")
    if unit and to.unit and unit != to.unit:
        raise WiringError(key, f"units differ: {link.producer} is in {unit}, "
                               f"{link.target}.{link.input} in {to.unit}")
    return Link(link.source, link.signal, link.target, link.input, kind, link.gain,
                link.offset, feeds_back)
