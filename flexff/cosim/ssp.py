"""A run configuration as an SSP 1.0 system (.ssp), and back: the exchange format that libcosim,
FMPy and OMSimulator read.

export_ssp writes one component per FMU, every link of the resolved wiring as a connection
(with its linear transformation), the start values and the run's times, plus flexff's
annotations: the step and algorithm, each component's `feedthrough = false`, and the whole
configuration. load_ssp reads such a file back as that configuration, or a flat system of FMUs
(another tool's, or flexff's changed since) as a general-form RunConfig, flexff's step,
algorithm and feedthrough kept. Every problem is a ConfigError naming the SSD element at
fault. The XML is checked against the SSP
1.0 schema that pyssp_standard ships.

What is exported, which connectors and why: "The master algorithm", section SSP
(docs/explanation/master-algorithm.md).
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import tomllib
import warnings
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import replace
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from lxml import etree

from flexff.cosim.config import checked, expanded, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import atomic_write
from flexff.cosim.scenario import Scenario, resolve
from flexff.cosim.schema import ALGORITHMS, ConnectionConfig, FmuConfig, RunConfig, whole_steps
from flexff.cosim.wiring import SOURCE, Link, carried
from flexff.fmu.archive import extract_archive
from flexff.fmu.cache import cache_dir, file_sha256
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError, not_a_file
from flexff.fmu.importer import FmuError, FmuInfo, read_fmu, typed_value

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
      "flexff": "urn:flexff:ssp"}
SSD = "SystemStructure.ssd"
FMU_TYPE = "application/x-fmu-sharedlibrary"
OSP, FLEXFF = "com.opensimulationplatform", "org.flexff"
INTEGERS = ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")
SSP_TYPES = {"float64": "Real", "float32": "Real", "boolean": "Boolean", "string": "String",
             "enumeration": "Enumeration", "binary": "Binary",
             **dict.fromkeys(INTEGERS, "Integer")}
ALWAYS = ("Real", "Integer", "Boolean")  # unconnected outputs and parameters of these types
# get a connector too; parameter values of enumerations are written as ssv:Integer (libcosim
# aborts on ssv:Enumeration as well, and an integer sets an FMI enumeration)
VALUE_TYPES = {**SSP_TYPES, "enumeration": "Integer"}
Fail = Callable[[str, str], ConfigError]  # (key, message) -> the error to raise


def _q(name: str) -> str:
    """'ssd:System' as lxml's qualified name."""
    prefix, _, local = name.partition(":")
    return f"{{{NS[prefix]}}}{local}"


def _sub(parent: etree._Element, tag: str, /, **attrib: str) -> etree._Element:
    return etree.SubElement(parent, _q(tag), attrib)


# -- export ------------------------------------------------------------------------------
def export_ssp(config: RunConfig, path: str | Path) -> Path:
    """Write `config` as an SSP 1.0 archive at `path` (module doc); ValueError if it has
    time-varying source signals other than the reference feeding FMU inputs."""
    with tempfile.TemporaryDirectory(prefix="flexff-ssp-") as folder:
        scenario = resolve(config, folder)
        reference = scenario.reference()
        varying = sorted({k.signal for k in scenario.links if k.producer == SOURCE
                          and np.ndim(scenario.sources[k.signal])
                          and k.signal not in reference})
        if varying:
            raise InputError(f"{config.origin}: SSP 1.0 cannot carry time-varying source "
                             f"signals, and {', '.join(varying)} feed FMU inputs: an SSP system "
                             f"holds FMUs, their connections and start values only")
        ssd = etree.tostring(_ssd(scenario), xml_declaration=True, encoding="UTF-8",
                             pretty_print=True)

        def write(tmp: Path) -> None:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
                archive.writestr(SSD, ssd)
                for fmu in scenario.fmus:
                    archive.write(fmu.path, f"resources/{fmu.name}.fmu")

        return atomic_write(path, write)


def _ssd(scenario: Scenario) -> etree._Element:
    """The SystemStructureDescription of a resolved scenario (module doc)."""
    config = scenario.config
    root = etree.Element(_q("ssd:SystemStructureDescription"), nsmap=NS,
                         version="1.0", name=config.name, generationTool="flexff")
    system = _sub(root, "ssd:System", name=config.name)
    elements = _sub(system, "ssd:Elements")
    enumerations: dict[str, etree._Element] = {}
    links = [k for k in scenario.links if k.producer != SOURCE]
    used = {(k.producer, k.signal) for k in links} | {(k.consumer, k.input) for k in links}
    stated = {f.name for f in config.fmus if not f.feedthrough}
    for fmu in scenario.fmus:
        info = fmu.described()
        component = _sub(elements, "ssd:Component", name=fmu.name, type=FMU_TYPE,
                         source=f"resources/{fmu.name}.fmu", implementation="CoSimulation")
        connectors = [n for n in (*info.inputs, *info.outputs, *info.parameters)
                      if _has_connector(info, n, (fmu.name, n) in used)]
        if connectors:
            _connectors(_sub(component, "ssd:Connectors"), info, connectors, enumerations)
        values = {**fmu.parameters, **{  # inputs fed by sources: their value at t = 0
            k.input: _at_start(k, scenario) for k in scenario.links
            if k.consumer == fmu.name and k.producer == SOURCE}}
        if values:
            binding = _sub(_sub(component, "ssd:ParameterBindings"), "ssd:ParameterBinding")
            _parameter_set(_sub(binding, "ssd:ParameterValues"), fmu.name, info, values)
        if fmu.name in stated:  # [fmu.NAME] feedthrough = false, flexff's to carry
            _sub(_sub(_sub(component, "ssd:Annotations"), "ssc:Annotation", type=FLEXFF),
                 "flexff:Component", feedthrough="false")
    if links:
        connections = _sub(system, "ssd:Connections")
        for k in links:
            connection = _sub(connections, "ssd:Connection", startElement=k.producer,
                              startConnector=k.signal, endElement=k.consumer, endConnector=k.input)
            if k.affine:
                _sub(connection, "ssc:LinearTransformation", factor=repr(float(k.gain)),
                     offset=repr(float(k.offset)))
    if enumerations:
        _sub(root, "ssd:Enumerations").extend(enumerations.values())
    experiment = _sub(root, "ssd:DefaultExperiment", startTime=repr(float(config.start)),
                      stopTime=repr(float(config.stop)))
    annotations = _sub(experiment, "ssd:Annotations")
    osp = _sub(_sub(annotations, "ssc:Annotation", type=OSP), "osp:Algorithm")
    _sub(osp, "osp:FixedStepAlgorithm", baseStepSize=repr(float(config.step)))
    run = _sub(_sub(annotations, "ssc:Annotation", type=FLEXFF), "flexff:Run",
               step=repr(float(config.step)), algorithm=config.algorithm)
    _sub(run, "flexff:Configuration").text = _configuration_text(config)
    return root


def _at_start(link: Link, scenario: Scenario) -> Any:
    """The value a source's link gives its input at point 0 (cosim.wiring.carried)."""
    try:
        return carried(link, np.ravel(scenario.sources[link.signal])[0])
    except OverflowError as error:
        raise InputError(f"{scenario.config.origin}: {link}: {error}") from None


def _configuration_text(config: RunConfig) -> str:
    """The configuration in the general form, FMUs by path named by their archive member."""
    tables = expanded(config)
    for name, table in tables["fmu"].items():
        if "path" in table:
            table["path"] = f"resources/{name}.fmu"
    return tomli_w.dumps(tables)


def _has_connector(info: FmuInfo, name: str, connected: bool) -> bool:
    """Whether the variable gets a connector (module doc)."""
    v = info.variables[name]
    kind = SSP_TYPES.get(v.kind)
    return bool(kind and v.scalar and (connected or (kind in ALWAYS and name not in info.inputs)))


def _connectors(parent: etree._Element, info: FmuInfo, names: list[str],
                enumerations: dict[str, etree._Element]) -> None:
    """ssd:Connector elements; enumeration types are collected into `enumerations`."""
    for name in names:
        v = info.variables[name]
        connector = _sub(parent, "ssd:Connector", name=name,
                         kind="parameter" if name in info.parameters else v.causality)
        kind = SSP_TYPES[v.kind]
        if kind == "Enumeration":
            enum = _enumeration(info, name)
            enumerations[enum.attrib["name"]] = enum
            _sub(connector, "ssc:Enumeration", name=enum.attrib["name"])
        else:
            _sub(connector, f"ssc:{kind}")


def _enumeration(info: FmuInfo, name: str) -> etree._Element:
    """The ssc:Enumeration of an enumeration variable's declared type."""
    declared = next(v.declaredType for v in info.model_description.modelVariables
                    if v.name == name)
    enum = etree.Element(_q("ssc:Enumeration"), name=declared.name)
    for item in declared.items:
        _sub(enum, "ssc:Item", name=item.name, value=str(int(item.value)))
    return enum


def _parameter_set(parent: etree._Element, name: str, info: FmuInfo,
                   values: dict[str, Any]) -> None:
    parameters = _sub(_sub(parent, "ssv:ParameterSet", version="1.0", name=name),
                      "ssv:Parameters")
    for variable, value in values.items():
        kind = info.variables[variable].kind
        text = (repr(float(value)) if kind in ("float64", "float32") else
                ("true" if value else "false") if kind == "boolean" else
                value.hex() if kind == "binary" else str(value))
        _sub(_sub(parameters, "ssv:Parameter", name=variable), f"ssv:{VALUE_TYPES[kind]}",
             value=text)


# -- import ------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def _schema() -> etree.XMLSchema:
    """The SSP 1.0 schema of the SSD (shipped with pyssp_standard)."""
    xsd = resources.files("pyssp_standard") / "resources" / "SystemStructureDescription.xsd"
    return etree.XMLSchema(etree.parse(str(xsd)))


def load_ssp(path: str | Path) -> RunConfig:
    """The run configuration of an SSP 1.0 file (module doc); ConfigError naming the SSD
    element at fault."""
    path = Path(path)
    origin = str(path)

    def error(key: str, message: str) -> ConfigError:
        return ConfigError(origin, key, message)

    why = not_a_file(path, "SSP file")
    if why is not None:
        raise error("file", why)
    try:
        folder = _extracted(path).resolve()
    except (zipfile.BadZipFile, zlib.error, EOFError) as exc:  # not a zip, or a damaged one
        raise error("file", f"not an SSP archive (a zip file holding SystemStructure.ssd): "
                            f"{exc}") from None
    try:
        root = etree.parse(str(folder / SSD)).getroot()
    except OSError:
        raise error(SSD, "the archive has no SystemStructure.ssd") from None
    except etree.XMLSyntaxError as exc:
        raise error(SSD, f"not well-formed XML: {exc}") from None
    if not _schema().validate(root):
        entry = _schema().error_log[0]
        raise error(entry.path or SSD, f"not valid SSP 1.0 (line {entry.line}): "
                                       f"{entry.message}")
    system = root.find("ssd:System", NS)
    if system is None:  # the schema requires one
        raise error("ssd:System", "the SSD has no system")
    if system.find("ssd:Connectors", NS) is not None:
        raise error("ssd:System/ssd:Connectors", "system connectors are not supported: "
                    "flexff runs a flat system of FMU components")
    fmus = []
    for element in system.iterfind("ssd:Elements/*", NS):
        name = element.get("name", "")  # the schema requires a name
        key = f"ssd:{etree.QName(element).localname}[@name='{name}']"
        if element.tag != _q("ssd:Component") or element.get("type", FMU_TYPE) != FMU_TYPE:
            raise error(key, f"flexff runs a flat system of FMU components (type {FMU_TYPE}),"
                             f" not {element.get('type') or etree.QName(element).localname}")
        if "." in name:
            raise error(key, "flexff names signals `fmu.variable`: a component name must "
                             "not contain a dot")
        fmu = _member(folder, element.get("source"))
        if fmu is None:
            raise error(key, f"its FMU {element.get('source')} is not in the archive")
        try:
            info = read_fmu(fmu)
        except FmuError as exc:
            raise error(key, str(exc)) from None
        fmus.append(FmuConfig(name, path=fmu, unconnected="start",
                              parameters=_bindings(element, info, folder, key, error),
                              feedthrough=_feedthrough(element, key, error)))
    if not fmus:
        raise error("ssd:System/ssd:Elements", "the system has no FMU component")
    step, start, stop, algorithm = _experiment(root, fmus, error)
    plain = RunConfig(name=path.stem, step=step, stop=stop, start=start, fmus=tuple(fmus),
                      connections=_connections(system, {f.name for f in fmus}, error),
                      algorithm=algorithm, origin=origin)
    return _annotated(root, folder, plain) or checked(plain)


def _annotated(root: etree._Element, folder: Path, plain: RunConfig) -> RunConfig | None:
    """The configuration flexff:Configuration carries, if the SSD and FMUs are still the ones
    it exports (module doc); None without one, or with a warning where they changed."""
    text = root.findtext("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation"
                         f"[@type='{FLEXFF}']/flexff:Run/flexff:Configuration", namespaces=NS)
    if text is None:
        return None
    try:
        config = parse_config(tomllib.loads(text), name=plain.name, base=folder,
                              origin=plain.origin)
        with tempfile.TemporaryDirectory(prefix="flexff-ssp-") as built:
            scenario = resolve(replace(config, name=root.get("name", "")), built)
            same = (_without_configuration(_ssd(scenario)) == _without_configuration(root)
                    and all(_member_sha256(folder, s.name) == file_sha256(s.path)
                            for s in scenario.fmus))
    except (ValueError, OSError, etree.Error) as exc:  # etree: C14N refuses the SSD
        same, reason = False, f": {exc}"
    else:
        reason = ""
    if not same:
        warnings.warn(f"{plain.origin}: the system is no longer the flexff configuration it "
                      f"carries{reason}; read as a plain SSP system (FMUs by file, no reference)",
                      stacklevel=3)
        return None
    return config


def _without_configuration(root: etree._Element) -> bytes:
    """The SSD's canonical XML without flexff:Configuration, for comparison."""
    copy = etree.fromstring(etree.tostring(root), etree.XMLParser(remove_blank_text=True))
    for element in copy.findall(".//flexff:Configuration", NS):
        parent = element.getparent()
        if parent is not None:
            parent.remove(element)
    return etree.tostring(copy, method="c14n")


def _member_sha256(folder: Path, name: str) -> str | None:
    """The sha256 of the archive's FMU of component `name` (None if it has none)."""
    member = folder / "resources" / f"{name}.fmu"
    return file_sha256(member) if member.is_file() else None


def _extracted(path: Path) -> Path:
    """The archive's files in the FMU cache, extracted once (by its sha256), so that the
    configuration's FMU paths stay valid after load_ssp returns."""
    digest = file_sha256(path)
    folder = cache_dir() / "ssp" / digest
    if not folder.is_dir():
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=".tmp-"))
        try:
            extract_archive(path, tmp)  # within the bound, member names checked
            os.replace(tmp, folder)
        except OSError:  # another process extracted it first
            if not folder.is_dir():
                raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _member(folder: Path, source: str | None) -> Path | None:
    """The extracted file at the SSD-relative `source`, None if the archive has none."""
    if source is None:
        return None
    path = (folder / source).resolve()
    return path if path.is_relative_to(folder) and path.is_file() else None


def _bindings(element: etree._Element, info: FmuInfo, folder: Path, key: str, error: Fail
              ) -> dict[str, Any]:
    """The start values of a component's parameter bindings, typed for its FMU."""
    values: dict[str, Any] = {}
    for k, binding in enumerate(element.findall("ssd:ParameterBindings/ssd:ParameterBinding",
                                                NS), 1):
        where = f"{key}/ssd:ParameterBinding[{k}]"
        if binding.find("ssd:ParameterMapping", NS) is not None:
            raise error(where, "parameter mappings are not supported")
        if binding.get("source"):
            ssv = _member(folder, binding.get("source"))
            try:
                sets = [etree.parse(str(ssv)).getroot()]
            except (OSError, TypeError, etree.XMLSyntaxError) as exc:
                raise error(where, f"cannot read {binding.get('source')}: {exc}") from None
        else:
            sets = binding.findall("ssd:ParameterValues/ssv:ParameterSet", NS)
        prefix = binding.get("prefix", "")
        for parameter in (p for s in sets for p in s.findall("ssv:Parameters/ssv:Parameter", NS)):
            name = parameter.get("name", "").removeprefix(prefix)  # the schema requires a name
            v = info.variables.get(name)
            if v is None or not v.settable:
                raise error(f"{where}/ssv:Parameter[@name='{name}']",
                            f"{info.path.name} has no parameter or input {name!r}")
            typed = parameter.find("ssv:*", NS)  # ssv:Real, ssv:Integer, ...
            try:
                values[name] = typed_value(v.kind, None if typed is None else typed.get("value"))
            except ValueError as exc:
                raise error(f"{where}/ssv:Parameter[@name='{name}']",
                            f"{v.type} variable: {exc}") from None
    return values


def _feedthrough(element: etree._Element, key: str, error: Fail) -> bool:
    """A component's `[fmu.NAME] feedthrough`: false where flexff's annotation says so (its
    outputs depend on no input directly, whatever its model structure says), else true."""
    ours = element.find(f"ssd:Annotations/ssc:Annotation[@type='{FLEXFF}']/flexff:Component",
                        NS)
    value = "true" if ours is None else ours.get("feedthrough", "true")
    if value not in ("true", "false"):
        raise error(f"{key}/ssd:Annotations", f"flexff:Component feedthrough must be true or "
                                              f"false, got {value!r}")
    return value == "true"


def _experiment(root: etree._Element, fmus: list[FmuConfig], error: Fail
                ) -> tuple[float, float, float, str]:
    """Step, start, stop and algorithm: our annotation, else libcosim's, else the defaults
    (the times: the first FMU's default experiment, a start time of 0 without one)."""
    key = "ssd:DefaultExperiment"
    experiment = root.find(key, NS)
    attrib = dict(experiment.attrib) if experiment is not None else {}
    ours = root.find(f"{key}/ssd:Annotations/ssc:Annotation[@type='{FLEXFF}']/flexff:Run", NS)
    osp = root.find(f"{key}/ssd:Annotations/ssc:Annotation[@type='{OSP}']/osp:Algorithm/"
                    f"osp:FixedStepAlgorithm", NS)
    step = (ours.get("step") if ours is not None else
            osp.get("baseStepSize") if osp is not None else DEFAULT_STEP)
    algorithm = ours.get("algorithm", "jacobi") if ours is not None else "jacobi"
    first = read_fmu(fmus[0].path) if fmus[0].path is not None else None
    stop = attrib.get("stopTime") or (first.default_stop if first is not None else None)
    start = attrib.get("startTime") or (first.default_start if first is not None else None)
    try:
        step, start, stop = _float(step), _float(start or 0.0), _float(stop)
    except (TypeError, ValueError):
        raise error(key, f"no stop time (stopTime, or the first FMU's default experiment), "
                         f"or a step or start time that is not a number ({step!r}, "
                         f"{start!r})") from None
    if not (math.isfinite(step) and step > 0 and math.isfinite(start) and math.isfinite(stop)
            and stop > start):
        raise error(key, f"step {step!r} must be positive, start {start!r} and stop time "
                         f"{stop!r} finite, the stop after the start")
    if not whole_steps(stop - start, step):
        raise error(key, f"the run's length {stop - start!r} s (stopTime - startTime) is not a "
                         f"whole number of steps of {step!r} s")
    if algorithm not in ALGORITHMS:
        raise error(f"{key}/ssd:Annotations", f"unknown algorithm {algorithm!r} "
                                              f"(known: {', '.join(ALGORITHMS)})")
    return step, start, stop, algorithm


def _float(value: str | float | None) -> float:
    """float(value); TypeError for None, as float(None) raises."""
    if value is None:
        raise TypeError("no value")
    return float(value)


def _connections(system: etree._Element, names: set[str], error: Fail
                 ) -> tuple[ConnectionConfig, ...]:
    """The connections between components, with gain and offset of a LinearTransformation."""
    out: list[ConnectionConfig] = []
    targets: dict[str, str] = {}  # connected input -> the connection's key
    for k, c in enumerate(system.findall("ssd:Connections/ssd:Connection", NS), 1):
        key = f"ssd:Connection[{k}]"
        start, end = c.get("startElement"), c.get("endElement")
        if start not in names or end not in names:
            raise error(key, "flexff connects FMU components only (startElement and "
                             f"endElement among {', '.join(sorted(names))})")
        transformation = c.find("ssc:*", NS)
        if transformation is not None and transformation.tag != _q("ssc:LinearTransformation"):
            raise error(key, f"{etree.QName(transformation).localname} is not supported "
                             f"(LinearTransformation is)")
        scale = dict(transformation.attrib) if transformation is not None else {}
        target = f"{end}.{c.get('endConnector')}"
        if target in targets:
            raise error(key, f"{target} is already connected by {targets[target]}")
        targets[target] = key
        out.append(ConnectionConfig(f"{start}.{c.get('startConnector')}", target,
                                    float(scale.get("factor", 1.0)),
                                    float(scale.get("offset", 0.0)), key))
    return tuple(out)
