"""The closed loop that data collection and the evaluation run: any checked run configuration
(cosim.schema.RunConfig) with flexff's built-in controller, put on one reference, its
feedforward swapped, and the dataset's signals located in its wiring.

A loop is changed with dataclasses.replace, never by editing its text, and every changed loop is
checked again as a file is (cosim.config.checked): `on_reference` sets the reference, run.stop
and the start values (x_start, y_start of the built-in plant, and of an FMU by path that has
such parameters) and the built-in plant's noise seed; `with_feedforward` replaces whatever feeds
the controller's Fx_ff, Fy_ff and i1_ff..i3_ff (a force table, as learning.ilc writes it,
feeds them through learning.machine_loop.with_feedforward). `dataset_taps` finds, in a
resolved loop, where each signal of the dataset is read: the encoders and the feedforward
force as the controller receives them (through the wiring's gain and offset), its feedback
force and currents, and the true position `x`, `y` by name; a loop that lacks one is refused
before anything runs.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from flexff.cosim.config import checked, expanded, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import Recording
from flexff.cosim.scenario import Scenario
from flexff.cosim.schema import FmuConfig, RunConfig, SourceConfig
from flexff.fmu.cache import file_sha256
from flexff.fmu.errors import InputError
from flexff.fmu.importer import read_fmu, typed_value
from flexff.learning.dataset import (
    ENCODER_SIGNALS,
    POSITION_SIGNALS,
    REFERENCE_SIGNALS,
)
from flexff.learning.model_card import read_card
from flexff.plant.signals import (
    CURRENT_FEEDFORWARD,
    CURRENTS,
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    names,
)
from flexff.plant.system import plant_parameters
from flexff.plant.variants import VARIANTS

START_VALUES = ("x_start", "y_start")
FEEDFORWARDS = ("rigid-body-feedforward", "learned-feedforward")


@dataclass(frozen=True)
class Tap:
    """Where a dataset signal is read: gain * recording[signal] + offset."""

    signal: str
    gain: float = 1.0
    offset: float = 0.0

    def read(self, recording: Recording) -> np.ndarray:
        values = recording[self.signal]
        return values if (self.gain, self.offset) == (1.0, 0.0) else \
            self.gain * values + self.offset


# flexff's own loop: every signal by its short name
OWN_TAPS = {n: Tap(n) for n in (*REFERENCE_SIGNALS, *ENCODER_SIGNALS, *POSITION_SIGNALS,
                                *names(FEEDBACK_FORCES, FEEDFORWARD_FORCES, CURRENTS))}


def is_manipulator_loop(loop: RunConfig) -> bool:
    """Whether the manipulator's own tools (its collection, ILC and evaluation) take `loop`:
    one with flexff's manipulator controller (its short form's machine description or an
    explicit one alike: the same run), or one without a machine description; any other goes
    the machine's way (learning.machine_loop)."""
    return loop.machine is None or loop.builtin("controller") is not None


def default_loop(variant: str) -> RunConfig:
    """flexff's own loop: PID alone on the built-in plant `variant` (the short form; its
    reference is a placeholder that `on_reference` replaces)."""
    return parse_config({"reference": {"kind": "thesis-eval"}, "plant": {"variant": variant}},
                        name=f"{variant}-pid", origin=f"the {variant} plant under PID")


def on_reference(loop: RunConfig, reference: Mapping[str, Any], name: str,
                 stop: float | None = None, seed: int | None = None) -> RunConfig:
    """`loop` run on the [reference] table `reference` (checked as parse_config checks it) for
    `stop` seconds (default: the reference's duration), starting at rest on its first point,
    with the built-in plant's noise `seed` (None keeps the loop's)."""
    own = parse_config({"run": {"step": loop.step, **({"stop": stop} if stop else {})},
                        "reference": dict(reference)}, name=name, origin=f"{loop.origin}, {name}")
    plant = own.builtin("plant")
    if plant is None:  # the short form always has one
        raise InputError(f"{name}: the reference run has no built-in plant")
    start = {k: plant.parameters[k] for k in START_VALUES}
    return checked(replace(loop, name=name, reference=own.reference, stop=own.stop,
                           fmus=tuple(_started(f, start, seed) for f in loop.fmus)))


def _started(f: FmuConfig, start: Mapping[str, float], seed: int | None) -> FmuConfig:
    if f.builtin == "plant":
        return replace(f, parameters={**f.parameters, **start},
                       options={**f.options, **({"seed": seed} if seed is not None else {})})
    if f.path is None:
        return f
    variables = read_fmu(f.path).variables
    if not all(k in variables and variables[k].settable for k in START_VALUES):
        return f
    return replace(f, parameters={**f.parameters, **{
        k: typed_value(variables[k].kind, v) for k, v in start.items()}})


def with_feedforward(loop: RunConfig, builtin: str | None = None,
                     options: Mapping[str, Any] | None = None) -> RunConfig:
    """`loop` with its feedforward replaced: the built-in `builtin` ("rigid-body-feedforward"
    or "learned-feedforward" with its `options`) stepped right before the controller, or, for
    None, PID alone (zero Fx_ff, Fy_ff). The loop's own built-in feedforward, its constant
    Fx_ff, Fy_ff (and i1_ff..i3_ff) and the connections to the controller's feedforward inputs
    go. A current-level learned model (its card's outputs i1_ff..i3_ff) feeds the controller's
    current feedforward (controller option current_feedforward), and Fx_ff, Fy_ff get zero;
    whatever feedforward input of the controller the new feedforward does not feed gets zero."""
    controller = _controller(loop)
    fed = names(FEEDFORWARD_FORCES, CURRENT_FEEDFORWARD)  # the controller's feedforward inputs
    produced = _produced(builtin, options or {})
    if produced == names(CURRENT_FEEDFORWARD):
        controller = replace(controller, options={**controller.options,
                                                  "current_feedforward": True})
    inputs = names(FEEDFORWARD_FORCES, CURRENT_FEEDFORWARD
                   if controller.options.get("current_feedforward") else ())
    gone = {f.name for f in loop.fmus if f.builtin in FEEDFORWARDS}
    targets = {f"{controller.name}.{n}" for n in fed}
    connections = tuple(c for c in loop.connections if c.to_name not in targets and not
                        {c.from_name.partition(".")[0], c.to_name.partition(".")[0]} & gone)
    sources = []
    for s in loop.sources:
        values = {k: v for k, v in s.values.items() if k not in fed}
        if s.kind != "constant" or values:
            sources.append(replace(s, values=values))
    fmus = [controller if f.name == controller.name else f
            for f in loop.fmus if f.name not in gone]
    if zeros := [n for n in inputs if n not in produced]:
        sources.insert(0, SourceConfig("constant", dict.fromkeys(zeros, 0.0)))
    if builtin is not None:
        name = "feedforward"
        while any(f.name == name for f in fmus):
            name += "_"
        fmus.insert(fmus.index(controller),
                    FmuConfig(name, builtin=builtin, options=dict(options or {})))
    return checked(replace(loop, fmus=tuple(fmus), sources=tuple(sources),
                           connections=connections))


def _produced(builtin: str | None, options: Mapping[str, Any]) -> tuple[str, ...]:
    """The controller inputs the feedforward `builtin` feeds (a learned model's card says)."""
    if builtin != "learned-feedforward":
        return names(FEEDFORWARD_FORCES) if builtin is not None else ()
    try:
        card = read_card(options["model"])
    except (InputError, KeyError):  # no model: the parser's check (checked) names what to do
        return names(FEEDFORWARD_FORCES)
    return tuple(card.output_signals) if card.machine is None else names(FEEDFORWARD_FORCES)


def _controller(loop: RunConfig) -> FmuConfig:
    controller = loop.builtin("controller")
    if controller is None:
        raise ConfigError(loop.origin, "fmu", "the loop has no flexff controller: data "
                          "collection and the evaluation run flexff's PID; add [fmu.controller] "
                          "builtin = \"controller\" (or use the short form's [controller])")
    return controller


def dataset_taps(scenario: Scenario) -> dict[str, Tap]:
    """Where each signal the dataset needs is read in a run of the resolved loop `scenario`;
    a ConfigError names a missing one and how to provide it."""
    config = scenario.config
    controller = _controller(config).name
    into = {(k.consumer, k.input): k for k in scenario.links}
    taps = {n: Tap(n) for n in REFERENCE_SIGNALS}  # the [reference]: source signals
    for name in (*ENCODER_SIGNALS, *names(FEEDFORWARD_FORCES)):
        link = into.get((controller, name))
        if link is None:
            raise ConfigError(config.origin, f"fmu.{controller}", (
                f"the dataset's {name} is what the controller's input {controller}.{name} "
                f"receives, and it receives no signal: connect it ([[connection]] from = "
                f"\"PLANT.OUTPUT\", to = \"{controller}.{name}\")"))
        taps[name] = Tap(link.from_name, link.gain, link.offset)
    taps.update({n: Tap(f"{controller}.{n}") for n in names(FEEDBACK_FORCES, CURRENTS)})
    outputs = [(s.name, s.described().outputs) for s in scenario.fmus]
    for name in POSITION_SIGNALS:
        found = [f"{fmu}.{name}" for fmu, names in outputs if name in names]
        if len(found) != 1:
            problem = (f"{' and '.join(found)} both output it" if found else
                       "no FMU of the loop outputs it")
            raise ConfigError(config.origin, "fmu", (
                f"the dataset's {name} (the true wrist position, m, a label of the dataset) is "
                f"the plant's output named {name}, and {problem}: give the plant FMU one "
                f"output {name} (logs of a machine without it: flexff data import)"))
        taps[name] = Tap(found[0])
    return taps


def current_limit(loop: RunConfig) -> float | None:
    """The built-in plant's current limit i_max [A] (None for a plant FMU by path)."""
    plant = loop.builtin("plant")
    if plant is None:
        return None
    return float(plant.parameters.get("i_max",
                                      VARIANTS[plant.options["variant"]].parameters.i_max))


def loop_record(scenario: Scenario) -> dict[str, Any]:
    """What a dataset records of the loop it was collected on: the configuration in the general
    form without what each trajectory sets (reference, run.stop, start values, the built-in
    plant's seed) and [record], and every FMU file with its sha256 (built-ins: the built
    FMU)."""
    configuration = expanded(replace(scenario.config, reference=None))
    configuration["run"].pop("stop")
    configuration.pop("record")  # the collection's own choice
    for table in configuration["fmu"].values():
        parameters = table.get("parameters", {})
        for key in START_VALUES:
            parameters.pop(key, None)
        if not parameters:
            table.pop("parameters", None)
        if table.get("builtin") == "plant":
            table.pop("seed", None)
    fmus = {f.name: {**({"builtin": f.builtin} if f.builtin else {"path": str(f.path)}),
                     "sha256": file_sha256(s.path)}
            for f, s in zip(scenario.config.fmus, scenario.fmus)}
    plain: dict[str, Any] = json.loads(json.dumps({"configuration": configuration, "fmus": fmus}))
    return plain


def plant_record(scenario: Scenario, taps: Mapping[str, Tap], record: Mapping[str, Any]
                 ) -> dict[str, Any]:
    """A dataset's plant: the built-in's variant and parameters (its defaults with the loop's
    values), or the FMU that outputs the true position, with its file's sha256 (from the
    loop's `record`)."""
    name = taps["x"].signal.partition(".")[0]
    plant = next(f for f in scenario.config.fmus if f.name == name)
    given = {k: v for k, v in plant.parameters.items() if k not in START_VALUES}
    if plant.builtin != "plant":
        return {"fmu": name, **record["fmus"][name], "parameters": given}
    variant = plant.options["variant"]
    defaults = {p.name: p.start for p in plant_parameters(variant)
                if p.name not in START_VALUES}
    return {"variant": variant, "parameters": {**defaults, **given}}


def loop_differences(found: Mapping[str, Any], wanted: Mapping[str, Any]) -> list[str]:
    """How two loop records differ (`key: found vs wanted`), FMUs by path compared by their
    sha256 and built-ins by their configuration (a built FMU changes with flexff's version)."""
    a, b = _flat(_identity(found)), _flat(_identity(wanted))

    def shown(values: Mapping[str, Any], key: str) -> str:
        return repr(values[key]) if key in values else "(none)"

    return [f"{k}: {shown(a, k)} there, {shown(b, k)} here"
            for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


def _identity(record: Mapping[str, Any]) -> dict[str, Any]:
    configuration = dict(record.get("configuration", {}))
    fmus = {}
    for name, table in configuration.get("fmu", {}).items():
        table = dict(table)
        if "path" in table:
            table["path"] = "sha256:" + record.get("fmus", {}).get(name, {}).get("sha256", "")
        fmus[name] = table
    return {**configuration, "fmu": fmus}


def _flat(value: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    return {prefix: value}
