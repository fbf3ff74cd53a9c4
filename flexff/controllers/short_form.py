"""The manipulator's short form of a run configuration, expanded to the general form's built-in
FMUs feedforward -> controller -> plant (controllers.manipulator registers it).

[plant], [controller] and [feedforward] take the options of the built-ins plant, controller
and rigid-body- or learned-feedforward (`kind` = "none" | "rigid-body" | "learned"), and
`fmi` (2 or 3: the FMI version it is built in). A
current-level model feeds the controller's current feedforward. It needs a [reference]; a
configuration without [fmu.*] tables is this loop with its defaults.

Docs: "Run configuration", sections Built-in FMUs and The manipulator's short form
(docs/reference/configuration.md).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

from flexff.controllers.plant_options import checked_plant_parameters, plant_parameter_names
from flexff.cosim.builtins import checked_options, registered
from flexff.cosim.checks import TableChecker
from flexff.cosim.schema import FmuConfig, SourceConfig
from flexff.plant.signals import CURRENT_FEEDFORWARD, FEEDFORWARD_FORCES, names
from flexff.plant.variants import VARIANTS

SHORT_FORM_TABLES = ("plant", "controller", "feedforward")
FEEDFORWARD_KINDS = ("none", "rigid-body", "learned")  # kind K is the built-in "K-feedforward"
RENAMED_KINDS = {"model": "rigid-body", "onnx": "learned"}  # old [feedforward] kind -> now


def expand(checker: TableChecker, data: Mapping[str, Any], start: tuple[float, ...] | None
           ) -> tuple[list[FmuConfig], list[SourceConfig]]:
    """[feedforward], [controller], [plant] as built-in FMUs in that order; without a
    feedforward, its forces are constant zero sources."""
    if start is None:
        raise checker.error("reference", "the [reference] table is required")
    builtins = registered()
    plant = checker.table(data, "plant")
    variant = checker.choice(plant, "plant", "variant", tuple(VARIANTS), "nominal")
    fmus: list[FmuConfig] = []
    sources: list[SourceConfig] = []
    ff = checker.table(data, "feedforward")
    if isinstance(ff.get("kind"), str) and ff["kind"] in RENAMED_KINDS:
        new = RENAMED_KINDS[ff["kind"]]
        warnings.warn(f"{checker.origin}: [feedforward] kind = {ff['kind']!r} is deprecated, "
                      f"write kind = {new!r} (the same feedforward: the built-in "
                      f"{new}-feedforward)", FutureWarning, stacklevel=3)
        ff = {**ff, "kind": new}
    kind = checker.choice(ff, "feedforward", "kind", FEEDFORWARD_KINDS, "none")
    given: tuple[str, ...] = ()  # the controller's feedforward inputs a feedforward FMU feeds
    if kind != "none":
        feedforward = builtins[f"{kind}-feedforward"]
        checker.keys(ff, "feedforward", ("kind", "fmi", *feedforward.keys))
        options = checked_options(checker, feedforward, _options(ff), "feedforward")
        fmus.append(FmuConfig("feedforward", builtin=feedforward.name, options=options,
                              fmi=checker.fmi_version(ff, "feedforward")))
        given = names(FEEDFORWARD_FORCES)
        if "model" in options:  # a learned model's card says what it feeds
            from flexff.learning.model_card import read_card  # onnx: learned runs only

            given = tuple(read_card(options["model"]).output_signals)
    else:
        checker.keys(ff, "feedforward", ("kind", "fmi"))
    currents = given == names(CURRENT_FEEDFORWARD)  # a current-level model (model_card)
    zeros = [n for n in names(FEEDFORWARD_FORCES, CURRENT_FEEDFORWARD if currents else ())
             if n not in given]
    if zeros:
        sources.append(SourceConfig("constant", dict.fromkeys(zeros, 0.0)))
    controller = checker.table(data, "controller")
    checker.keys(controller, "controller", ("crossover_hz", "notch", "encoders", "fmi"))
    fmus.append(FmuConfig("controller", builtin="controller", options={
        **checked_options(checker, builtins["controller"],
                          {**_options(controller), "variant": variant}, "controller"),
        **({"current_feedforward": True} if currents else {})},
        fmi=checker.fmi_version(controller, "controller")))
    checker.keys(plant, "plant", ("variant", "seed", "fmi", *plant_parameter_names(variant)))
    values = {k: v for k, v in _options(plant).items() if k not in ("variant", "seed")}
    fmus.append(FmuConfig("plant", builtin="plant", options=checked_options(
        checker, builtins["plant"], {k: plant[k] for k in ("seed",) if k in plant} | {
            "variant": variant}, "plant"),
        parameters=checked_plant_parameters(checker, values, variant, "plant", start),
        fmi=checker.fmi_version(plant, "plant")))
    return fmus, sources


def _options(table: Mapping[str, Any]) -> dict[str, Any]:
    """A short-form table's built-in options: all but `fmi`, the FMI version it is built in."""
    return {k: v for k, v in table.items() if k != "fmi"}
