"""What an FMU declares, for `flexff fmu info`: its ports (causality, type, unit, start, value
reference), each output's direct dependencies on inputs (or that it declares none, which FMI
reads as every input, but for a continuous state: cosim.wiring's algebraic-loop check), its
default experiment, its interfaces and the platforms it carries binaries for, and whether it
carries sources.

Read by fmu.importer.read_fmu, unchecked (a description fmpy's validation would refuse is still
shown: `flexff fmu validate` says what is wrong with it), and by the archive's file names.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

from flexff.fmu.importer import FmuInfo, read_fmu

CAUSALITIES = ("input", "output", "parameter", "structuralParameter", "calculatedParameter",
               "independent", "local")  # the order ports are listed in


def fmu_summary(path: str | Path) -> dict[str, Any]:
    """The FMU at `path` as plain data (JSON): see the module doc; FmuError naming the file
    where it is no FMU."""
    info = read_fmu(path, checked=False)
    with zipfile.ZipFile(info.path) as archive:
        names = archive.namelist()
    platforms = sorted({n.split("/")[1] for n in names
                        if n.startswith("binaries/") and n.count("/") >= 2 and n.split("/")[2]})
    return {
        "file": str(info.path), "fmi_version": info.fmi_version, "model_name": info.model_name,
        "token": info.token,
        "generation_tool": getattr(info.model_description, "generationTool", None),
        "interfaces": _interfaces(info), "platforms": platforms,
        "sources": any(n.startswith("sources/") and not n.endswith("/") for n in names),
        "default_experiment": {"start": info.default_start, "stop": info.default_stop,
                               "step": info.default_step, "tolerance": info.default_tolerance},
        "variables": [{"name": v.name, "causality": v.causality, "type": v.type,
                       "variability": v.variability, "unit": v.unit, "start": _plain(v.start),
                       "value_reference": v.value_reference,
                       **({"array": True} if not v.scalar else {}),
                       **({"description": v.description} if v.description else {})}
                      for v in sorted(info.variables.values(), key=_port_order)],
        "dependencies": {name: {"declared": name in info.declared, "state": name in info.states,
                                "inputs": sorted(info.dependencies[name])}
                         for name in info.outputs},
    }


def _interfaces(info: FmuInfo) -> dict[str, str]:
    """Interface -> its model identifier."""
    found = {"co-simulation": info.identifier if info.co_simulation else None,
             "model exchange": info.me_identifier, "scheduled execution": info.se_identifier}
    return {kind: identifier for kind, identifier in found.items() if identifier}


def _port_order(variable: Any) -> tuple[int, int]:
    causality = variable.causality
    rank = CAUSALITIES.index(causality) if causality in CAUSALITIES else len(CAUSALITIES)
    return rank, variable.value_reference


def _plain(value: Any) -> Any:
    """A start value as JSON holds it (bytes as hexadecimal text)."""
    return value.hex() if isinstance(value, bytes) else value


def format_summary(summary: dict[str, Any], everything: bool = False) -> str:
    """The summary as text; without `everything`, local variables are counted, not listed."""
    experiment = ", ".join(f"{k} {v:g}" for k, v in summary["default_experiment"].items()
                           if v is not None) or "none"
    lines = [f"{summary['file']}: FMI {summary['fmi_version']}, model {summary['model_name']}"
             + (f", by {summary['generation_tool']}" if summary["generation_tool"] else ""),
             "interfaces: " + ", ".join(f"{k} ({v})" for k, v in summary["interfaces"].items()),
             "platforms: " + (", ".join(summary["platforms"]) or "none")
             + (" (and sources)" if summary["sources"] else ""),
             f"default experiment: {experiment}"]
    shown = [v for v in summary["variables"] if everything or v["causality"] != "local"]
    width = max((len(v["name"]) for v in shown), default=4)
    lines.append(f"{'name':<{width}}  {'causality':<11} {'type':<11} {'unit':<8} "
                 f"{'start':>12}  value ref.")
    for v in shown:
        start = "" if v["start"] is None else f"{v['start']:.6g}" \
            if isinstance(v["start"], float) else str(v["start"])
        lines.append(f"{v['name']:<{width}}  {v['causality']:<11} {v['type']:<11} "
                     f"{v['unit'] or '':<8} {start:>12}  {v['value_reference']}"
                     + ("  (array)" if v.get("array") else ""))
    hidden = len(summary["variables"]) - len(shown)
    if hidden:
        lines.append(f"({hidden} local variables: --all lists them)")
    lines.append("output dependencies (direct, on inputs):")
    for name, dependency in summary["dependencies"].items():
        inputs = ", ".join(dependency["inputs"]) or "none"
        lines.append(f"  {name}: {inputs}" if dependency["declared"] else
                     f"  {name}: none (not declared; a continuous state)" if dependency["state"]
                     else f"  {name}: not declared, so by FMI every input")
    if not all(d["declared"] or d["state"] for d in summary["dependencies"].values()):
        lines.append("(where the outputs not declared are states, feedthrough = false in the "
                     "FMU's [fmu.NAME] table lets Gauss-Seidel step it before their readers)")
    return "\n".join(lines)
