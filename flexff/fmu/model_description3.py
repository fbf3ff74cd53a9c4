"""modelDescription.xml and sources/buildDescription.xml of a System's FMI 3.0 co-simulation
FMU.

The variables, value references, start values and output dependencies are those of the FMI 2.0
description (fmu.model_description): Reals become Float64, the Integer `seed` an Int32, and the
independent variable `time` that FMI 3.0 requires follows them (VR_TIME of config.h). FMI 3.0
lists the model structure by value reference and the sources in buildDescription.xml. A network
in its own task is offered as scheduled execution too: two periodic input clocks after `time`,
the step's and the network's (fmu/c/fmi3Functions.c).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from flexff.fmu.layout import (
    Layout,
    ScalarVariable,
    clock_value_references,
    time_value_reference,
)
from flexff.fmu.model_description import (
    add_units_logs_experiment,
    format_value,
    initial_attribute,
    output_dependencies,
)
from flexff.fmu.system import System

TYPES = {"Real": "Float64", "Integer": "Int32"}  # FMI 2.0 type -> FMI 3.0 element


def _xml(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _variable(parent: ET.Element, v: ScalarVariable) -> None:
    attrs = {"name": v.name, "valueReference": str(v.value_reference)}
    if v.description:  # the seed's names the FMI 2.0 function
        attrs["description"] = v.description.replace("fmi2", "fmi3")
    attrs["causality"] = v.causality
    attrs["variability"] = v.variability
    how = initial_attribute(v)
    if how is not None:
        attrs["initial"] = how
    if v.start is not None:
        attrs["start"] = format_value(v.start)
    if v.unit:
        attrs["unit"] = v.unit
    ET.SubElement(parent, TYPES[v.type], attrs)


def _clocks(parent: ET.Element, system: System, layout: Layout) -> None:
    """The scheduled-execution clocks: the step's partition, and the network's call, every
    `period` steps, at a lower priority (its result is used one period later)."""
    assert system.network is not None and system.sample_time is not None
    step, period = system.sample_time, system.network.period
    for (name, interval, priority, description), vr in zip((
            ("step_clock", step, 0, "each step: the outputs from the inputs"),
            ("network_clock", step * period, 1,
             f"the network's call on the inputs of the step it ticks with, used {period} steps "
             f"later")), clock_value_references(layout), strict=True):
        ET.SubElement(parent, "Clock", {
            "name": name, "valueReference": str(vr), "description": description,
            "causality": "input", "variability": "discrete", "intervalVariability": "constant",
            "intervalDecimal": format_value(interval), "priority": str(priority)})


def model_description3_xml(system: System, layout: Layout, identifier: str, token: str) -> str:
    """The XML text; `token` (the instantiationToken) ties it to the binary."""
    discrete = system.kind == "discrete"
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0",
        "modelName": system.name,
        "instantiationToken": token,
        "description": system.description,
        "generationTool": "flexff",
        "variableNamingConvention": "flat",
    })
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": identifier,
        "canGetAndSetFMUState": "true",
        "canSerializeFMUState": "true",
        "canHandleVariableCommunicationStepSize": "false" if discrete else "true",
        "hasEventMode": "false",
    })
    scheduled = system.network is not None and system.network.task
    if scheduled:
        ET.SubElement(root, "ScheduledExecution", {"modelIdentifier": identifier})
    add_units_logs_experiment(root, system, layout, "fmi3")
    model_vars = ET.SubElement(root, "ModelVariables")
    ET.SubElement(model_vars, "Float64", {
        "name": "time", "valueReference": str(time_value_reference(layout)),
        "causality": "independent", "variability": "continuous",
        "description": "simulation time"})
    for v in layout.variables:
        _variable(model_vars, v)
    if scheduled:
        _clocks(model_vars, system, layout)

    structure = ET.SubElement(root, "ModelStructure")
    inputs = layout.block("input")
    outputs = layout.block("output")
    for y, deps in zip(outputs, output_dependencies(system), strict=True):
        ET.SubElement(structure, "Output", {
            "valueReference": str(y.value_reference),
            "dependencies": " ".join(str(inputs[j].value_reference) for j in deps)})
    for y in outputs:
        ET.SubElement(structure, "InitialUnknown", {"valueReference": str(y.value_reference)})
    if system.extra:  # FMI 3.0 puts them last, in an Annotation of flexff's
        tool = ET.SubElement(ET.SubElement(root, "Annotations"), "Annotation", {"type": "flexff"})
        for key in sorted(system.extra):
            ET.SubElement(tool, "Annotation", {"name": key, "value": system.extra[key]})
    return _xml(root)


def build_description_xml(identifier: str, source_files: list[str]) -> str:
    """sources/buildDescription.xml: the C files to compile into the library `identifier`."""
    root = ET.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    config = ET.SubElement(root, "BuildConfiguration", {"modelIdentifier": identifier})
    files = ET.SubElement(config, "SourceFileSet", {"language": "C99"})
    for name in source_files:
        ET.SubElement(files, "SourceFile", {"name": name})
    for library in ("m", "dl", "pthread"):
        ET.SubElement(config, "Library", {"name": library, "external": "true"})
    return _xml(root)
