"""modelDescription.xml (FMI 2.0, co-simulation) of a System's FMU, and what the FMI 3.0 one
(fmu.model_description3) shares with it.

Output dependencies come from the structural sparsity of d output / d u, so a master can tell
direct feedthrough (an algebraic path from inputs to outputs) from outputs that only depend on
the state.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.layout import Layout, ScalarVariable
from flexff.fmu.system import System

LOG_CATEGORIES = {
    "logStatusError": "errors (on unless switched off with fmi2SetDebugLogging)",
    "logStatusWarning": "warnings and unavailable status requests",
    "logAll": "every FMI call",
    "logNetworkTimes": "an embedded network's call times, at fmi2Terminate (on unless "
                       "switched off)",
}


def output_dependencies(system: System) -> list[list[int]]:
    """For each output, the indices of the inputs it depends on structurally (through an
    embedded network's result too)."""
    ny, nu = len(system.outputs), len(system.inputs)
    if nu == 0:
        return [[] for _ in range(ny)]
    direct = np.array(system.output.sparsity_jac(1, 0), dtype=bool)
    net = system.network
    if net is not None and net.n_outputs > 0:
        via_result = np.array(system.output.sparsity_jac(4, 0), dtype=bool)
        of_input = np.array(net.input_function.sparsity_jac(1, 0), dtype=bool)
        # each result of the graph may depend on each of its inputs
        direct |= via_result.any(axis=1, keepdims=True) & of_input.any(axis=0, keepdims=True)
    return [np.flatnonzero(row).tolist() for row in direct]


def format_value(value: float | int) -> str:
    """A start value as the XML writes it (floats round-trip exactly)."""
    return repr(value) if isinstance(value, float) else str(value)


def unit_names(layout: Layout) -> list[str]:
    """The units the variables use, sorted (each needs a UnitDefinitions entry)."""
    return sorted({v.unit for v in layout.variables if v.unit})


def add_units_logs_experiment(root: ET.Element, system: System, layout: Layout,
                              api: str = "fmi2") -> None:
    """UnitDefinitions, LogCategories (their texts naming the `api`'s functions) and the
    DefaultExperiment, alike in FMI 2.0 and 3.0."""
    units = unit_names(layout)
    if units:
        unit_defs = ET.SubElement(root, "UnitDefinitions")
        for unit in units:
            ET.SubElement(unit_defs, "Unit", {"name": unit})
    categories = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES.items():
        ET.SubElement(categories, "Category", {"name": name,
                                               "description": text.replace("fmi2", api)})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0.0",
                                              "stepSize": repr(default_step(system))})


def default_step(system: System) -> float:
    """The default experiment's step: the sample time of a discrete system, else DEFAULT_STEP."""
    step = system.sample_time if system.kind == "discrete" else DEFAULT_STEP
    if step is None:
        raise ValueError("a discrete system needs a positive sample_time")
    return float(step)


def initial_attribute(v: ScalarVariable) -> str | None:
    """The `initial` attribute of a variable: exact for what is set, calculated for what the
    FMU computes, None (the default) for inputs."""
    if v.role in ("parameter", "max_substep", "seed"):
        return "exact"
    if v.role in ("output", "state"):
        return "calculated"
    return None


def model_description_xml(system: System, layout: Layout, identifier: str, guid: str,
                          source_files: list[str]) -> str:
    """The XML text; `guid` ties it to the binary, `source_files` are the sources/ to compile."""
    discrete = system.kind == "discrete"
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0",
        "modelName": system.name,
        "guid": guid,
        "description": system.description,
        "generationTool": "flexff",
        "variableNamingConvention": "flat",
        "numberOfEventIndicators": "0",
    })
    cs = ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": identifier,
        "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "false" if discrete else "true",
        "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0",
        "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false",
    })
    files = ET.SubElement(cs, "SourceFiles")
    for name in source_files:
        ET.SubElement(files, "File", {"name": name})

    add_units_logs_experiment(root, system, layout)

    if system.extra:
        # the FMI 2.0 schema allows one element inside <Tool>: wrap the entries in it
        tool = ET.SubElement(ET.SubElement(root, "VendorAnnotations"), "Tool", {"name": "flexff"})
        annotations = ET.SubElement(tool, "Annotations")
        for key in sorted(system.extra):
            ET.SubElement(annotations, "Annotation", {"name": key, "value": system.extra[key]})

    model_vars = ET.SubElement(root, "ModelVariables")
    index = {}
    for i, v in enumerate(layout.variables, start=1):
        index[v.name] = i
        attrs = {"name": v.name, "valueReference": str(v.value_reference)}
        if v.description:
            attrs["description"] = v.description
        attrs["causality"] = v.causality
        attrs["variability"] = v.variability
        how = initial_attribute(v)
        if how is not None:
            attrs["initial"] = how
        sv = ET.SubElement(model_vars, "ScalarVariable", attrs)
        type_attrs = {}
        if v.unit:
            type_attrs["unit"] = v.unit
        if v.start is not None:
            type_attrs["start"] = format_value(v.start)
        ET.SubElement(sv, v.type, type_attrs)

    structure = ET.SubElement(root, "ModelStructure")
    inputs = layout.block("input")
    if layout.block("output"):  # the schema forbids empty Outputs / InitialUnknowns
        outputs = ET.SubElement(structure, "Outputs")
        initial = ET.SubElement(structure, "InitialUnknowns")
    for y, deps in zip(layout.block("output"), output_dependencies(system), strict=True):
        dep_text = " ".join(str(index[inputs[j].name]) for j in deps)
        ET.SubElement(outputs, "Unknown", {"index": str(index[y.name]), "dependencies": dep_text})
        ET.SubElement(initial, "Unknown", {"index": str(index[y.name])})

    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
