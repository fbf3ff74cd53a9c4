"""cosim.ssp: a run configuration as an SSP 1.0 archive and back, checked against the SSP 1.0
schema and run on the same file by flexff, libcosim (libcosimpy) and FMPy.

The system: the Reference-FMUs VanDerPol (mu = 1.5) -> Feedthrough, x0 into
Float64_continuous_input through gain 2 and offset 0.5, Jacobi, 0.01 s steps to 2 s.
"""

import re
import zipfile
from dataclasses import replace
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from lxml import etree

from flexff.cosim.config import expanded, load_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import load_recording
from flexff.cosim.run import run_config, simulate_config
from flexff.cosim.ssp import NS, SSD, export_ssp, load_ssp
from flexff.fmu.importer import read_fmu
from flexff.plant.references import thesis_evaluation
from tests.helpers import REFERENCE_FMUS

STEPS = 200
X0, X1, FT = "vdp.x0", "vdp.x1", "ft.Float64_continuous_output"


def write_config(folder: Path, fmi: str = "fmi2", algorithm: str = "jacobi",
                 mu: float | None = 1.5, **tables) -> Path:
    """The configuration as a TOML file (mu None: VanDerPol's default, 1); `tables` adds
    [[source]] tables and further connections."""
    vdp = {"path": str(REFERENCE_FMUS / fmi / "VanDerPol.fmu")}
    if mu is not None:
        vdp["parameters"] = {"mu": mu}
    data = {"run": {"step": 0.01, "stop": 2.0, "algorithm": algorithm},
            "fmu": {"vdp": vdp, "ft": {"path": str(REFERENCE_FMUS / fmi / "Feedthrough.fmu"),
                                       "unconnected": "start"}},
            "connection": [{"from": "vdp.x0", "to": "ft.Float64_continuous_input",
                            "gain": 2.0, "offset": 0.5}, *tables.pop("connection", [])],
            **tables}
    path = folder / f"vdp_ft_{fmi}_{algorithm}_{mu}.toml"
    path.write_text(tomli_w.dumps(data))
    return path


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """load_ssp extracts archives into the FMU cache: a fresh one per test."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))


@pytest.fixture
def ssp(tmp_path) -> Path:
    return export_ssp(load_config(write_config(tmp_path)), tmp_path / "vdp_ft.ssp")


@pytest.fixture
def flexff(tmp_path):
    """flexff's recording of the configuration, and of the same with mu at its default 1."""
    return (simulate_config(load_config(write_config(tmp_path))),
            simulate_config(load_config(write_config(tmp_path, mu=None))))


def ssd_of(path: Path) -> etree._Element:
    with zipfile.ZipFile(path) as archive:
        return etree.fromstring(archive.read(SSD))


def assert_valid_ssp_1_0(root: etree._Element) -> None:
    xsd = resources.files("pyssp_standard") / "resources" / "SystemStructureDescription.xsd"
    schema = etree.XMLSchema(etree.parse(str(xsd)))
    assert schema.validate(root), schema.error_log


def test_export_is_valid_ssp_1_0(ssp):
    root = ssd_of(ssp)
    assert_valid_ssp_1_0(root)
    with zipfile.ZipFile(ssp) as archive:
        assert {"resources/vdp.fmu", "resources/ft.fmu"} <= set(archive.namelist())
    (connection,) = root.findall(".//ssd:Connection", NS)
    assert connection.attrib == {"startElement": "vdp", "startConnector": "x0",
                                 "endElement": "ft", "endConnector": "Float64_continuous_input"}
    assert connection.find("ssc:LinearTransformation", NS).attrib == {"factor": "2.0",
                                                                      "offset": "0.5"}
    mu = root.find(".//ssd:Component[@name='vdp']//ssv:Parameter[@name='mu']/ssv:Real", NS)
    assert mu.get("value") == "1.5"
    assert root.find(".//osp:FixedStepAlgorithm", NS).get("baseStepSize") == "0.01"
    # unconnected inputs have no connector (they keep their start values); outputs do
    ft = {c.get("name") for c in root.findall(".//ssd:Component[@name='ft']//ssd:Connector", NS)}
    assert "Float64_continuous_input" in ft and "Float64_discrete_input" not in ft
    assert {"Float64_continuous_output", "Int32_output", "Boolean_output"} <= ft


def without_configuration(text: str) -> str:
    """The SSD text without flexff's copy of the configuration: a plain SSP system."""
    return re.sub(r"\s*<flexff:Configuration>.*</flexff:Configuration>", "", text, flags=re.S)


def test_round_trip_runs_bit_equal_in_flexff(tmp_path, ssp):
    toml = load_config(write_config(tmp_path))
    config = load_ssp(ssp)  # flexff's annotation: the configuration it was written from
    assert expanded(replace(config, fmus=toml.fmus)) == expanded(toml)
    assert [read_fmu(f.path).token for f in config.fmus] == [read_fmu(f.path).token
                                                             for f in toml.fmus]
    plain = load_ssp(rewritten(ssp, tmp_path / "plain.ssp", without_configuration))
    assert plain.algorithm == "jacobi" and (plain.step, plain.stop) == (0.01, 2.0)
    assert [(f.name, dict(f.parameters), f.unconnected) for f in plain.fmus] == [
        ("vdp", {"mu": 1.5}, "start"), ("ft", {}, "start")]
    (c,) = plain.connections
    assert (c.from_name, c.to_name, c.gain, c.offset) == ("vdp.x0", "ft.Float64_continuous_input",
                                                      2.0, 0.5)
    run_config(write_config(tmp_path), tmp_path / "toml")
    for name, path in (("ssp", ssp), ("plain", tmp_path / "plain.ssp")):
        run_config(path, tmp_path / name)
        original = load_recording(tmp_path / "toml")
        loaded = load_recording(tmp_path / name)
        assert sorted(original.signals) == sorted(loaded.signals)
        assert np.array_equal(original.time, loaded.time)
        for signal in original.signals:
            assert np.array_equal(original[signal], loaded[signal]), (name, signal)


def test_an_ssp_changed_by_another_tool_is_read_as_it_now_is(tmp_path, ssp):
    """Another tool set mu = 2.5 in the SSD: flexff's copy of the configuration no longer
    describes the system, so the SSD is read as it stands, with a warning."""
    edited = rewritten(ssp, tmp_path / "edited.ssp",
                       lambda text: text.replace('<ssv:Real value="1.5"/>',
                                                 '<ssv:Real value="2.5"/>'))
    with pytest.warns(UserWarning, match="no longer the flexff configuration it carries"):
        config = load_ssp(edited)
    assert config.fmus[0].parameters == {"mu": 2.5} and config.fmus[0].unconnected == "start"


def test_the_manipulator_loop_round_trips_with_its_reference(tmp_path):
    """A manipulator run: its [reference] is flexff's to carry (SSP 1.0 has no time-varying
    sources), the controller's reference inputs start at the reference's first point, and the
    built-in FMUs read back as built-ins."""
    path = tmp_path / "loop.toml"
    path.write_text('[run]\nstop = 0.3\n[reference]\nkind = "thesis-eval"\n'
                    '[plant]\nm_up1 = 0.13\n')
    toml = load_config(path)
    ssp = export_ssp(toml, tmp_path / "loop.ssp")
    root = ssd_of(ssp)
    assert_valid_ssp_1_0(root)
    x_ref = root.find(".//ssd:Component[@name='controller']//ssv:Parameter[@name='x_ref']/"
                      "ssv:Real", NS)
    assert float(x_ref.get("value")) == thesis_evaluation().signals()["x_ref"][0]
    config = load_ssp(ssp)
    assert expanded(config) == expanded(toml) and config.builtin("controller") is not None
    original, again = simulate_config(toml), simulate_config(config)
    assert original.signals.keys() == again.signals.keys()
    for name in original.signals:
        assert np.array_equal(original[name], again[name]), name


def test_libcosim_runs_the_ssp(ssp, flexff):
    """libcosim reads the step from the osp annotation, applies the parameter binding and the
    LinearTransformation, and steps as flexff's Jacobi does: its sample after step k is
    flexff's sample k, bit for bit (max abs difference 0.0 over the 200 steps)."""
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.FATAL)  # it complains of Feedthrough's enumerations
    ours, mu_one = flexff
    execution = CosimExecution.from_ssp_file(str(ssp))  # the step: from the annotation
    observer = CosimObserver.create_time_series()
    execution.add_observer(observer)
    variables = {}
    for name in (X0, X1, FT):
        slave, variable = name.split(".")
        info = read_fmu(REFERENCE_FMUS / "fmi2" / ("VanDerPol.fmu" if slave == "vdp" else
                                         "Feedthrough.fmu"))
        variables[name] = (execution.slave_index_from_instance_name(slave),
                           info.variables[variable].value_reference)
        observer.start_time_series(*variables[name], CosimVariableType.REAL)
    assert execution.step(1) and execution.status().current_time == 10_000_000  # ns
    assert execution.simulate_until(2_000_000_000)
    for name, (slave, vr) in variables.items():
        # from step 1: libcosimpy 0.0.6 trims a sample off the end for every step number 0
        # it returns (it takes them for unfilled buffer), so asking from step 0 loses one
        times, steps, values = observer.time_series_real_samples(slave, vr, 1, STEPS)
        assert steps == list(range(1, STEPS + 1))
        assert times == [k * 10_000_000 for k in steps]
        assert np.max(np.abs(np.array(values) - ours[name][1:])) == 0.0, name
        if name == X1:  # the binding mu = 1.5 took: mu = 1 is 0.665 away
            assert np.max(np.abs(np.array(values) - mu_one[name][1:])) > 0.5
    # the LinearTransformation: ft's output in the step from 0 is 2 x0(0) + 0.5
    assert ours[FT][1] == 2 * ours[X0][0] + 0.5 == 4.5


def test_fmpy_runs_the_ssp(ssp, flexff):
    """FMPy's simulate_ssp runs the same file on what it reads: connections and the FMUs'
    own start values. Its row at `time` t_k holds the values after the step from t_k, that is
    flexff's sample k + 1. What it leaves out, measured over the 200 steps:
    - parameter bindings (mu = 1.5): without its `parameter_set` argument vdp runs with
      mu = 1, bit-equal to flexff with mu = 1 and 0.665 away in x1 from mu = 1.5; given
      parameter_set, vdp is bit-equal to flexff's;
    - the LinearTransformation: ft receives x0 itself, so ft's output at row k >= 1 is
      flexff's x0 at k bit for bit, where flexff's ft output is 2 x0 + 0.5 (at most 2.5
      apart);
    - initial outputs: connectors start at 0.0, so ft's input in the first step is 0.0
      (row 0), not x0(0) = 2 (4.5 apart, with the transformation).
    It also ignores the SSD's DefaultExperiment (stop_time and step_size must be given) and
    adds up time (row 199 is at 1.9900000000000015 s)."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet

    ours, mu_one = flexff
    plain = simulate_ssp(str(ssp), stop_time=2.0, step_size=0.01)
    bound = simulate_ssp(str(ssp), stop_time=2.0, step_size=0.01, parameter_set=ParameterSet(
        parameters=[Parameter(name="vdp.mu", value=1.5)]))
    assert len(plain) == STEPS
    assert np.max(np.abs(plain["time"] - np.arange(STEPS) * 0.01)) < 1e-14
    for name in (X0, X1):
        assert np.array_equal(bound[name], ours[name][1:]), name
        assert np.array_equal(plain[name], mu_one[name][1:]), name
    assert np.max(np.abs(plain[X1] - ours[X1][1:])) > 0.5  # 0.665
    ft = bound[FT]
    assert ft[0] == 0.0 and np.array_equal(ft[1:], ours[X0][1:STEPS])
    gap = np.abs(ft - ours[FT][1:])
    assert gap[0] == 4.5 and gap[1:].max() == 2.5  # |x0 + 0.5|, largest at x0(t_1) = 2


def test_fmi3_system_runs_in_flexff(tmp_path):
    """FMI 3.0 FMUs in an SSP (here Gauss-Seidel, carried by our annotation): flexff runs
    them bit-equal to the configuration; FMPy's simulate_ssp and libcosim run FMI 1.0 and
    2.0 only."""
    from fmpy.ssp.simulation import simulate_ssp
    from libcosimpy.CosimExecution import CosimExecution

    config = load_config(write_config(tmp_path, "fmi3", "gauss-seidel"))
    path = export_ssp(config, tmp_path / "vdp_ft3.ssp")
    loaded = load_ssp(path)
    assert loaded.algorithm == "gauss-seidel"
    original, again = simulate_config(config), simulate_config(loaded)
    assert list(original.signals) == list(again.signals)
    for name in original.signals:
        assert np.array_equal(original[name], again[name]), name
    assert again[FT][0] == 2 * again[X0][0] + 0.5  # Gauss-Seidel: no step of delay
    with pytest.raises(Exception, match="shared library"):
        simulate_ssp(str(path), stop_time=2.0, step_size=0.01)
    with pytest.raises(AssertionError):
        CosimExecution.from_ssp_file(str(path))


def test_typed_connections_and_start_values_round_trip(tmp_path):
    """Integer, Boolean, String and Enumeration signals and start values (Feedthrough ->
    Feedthrough, Gauss-Seidel): valid SSP 1.0 (the enumeration type is declared in
    ssd:Enumerations) and bit-equal in flexff after the round trip."""
    values = {"Int32_input": 7, "Boolean_input": True, "String_input": "hello",
              "Enumeration_input": 2, "Float64_continuous_input": 1.25}
    signals = ("Int32", "Boolean", "String", "Enumeration")
    feedthrough = str(REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu")
    path = tmp_path / "typed.toml"
    path.write_text(tomli_w.dumps({
        "run": {"step": 0.5, "stop": 2.0},
        "fmu": {"a": {"path": feedthrough, "unconnected": "start", "parameters": values},
                "b": {"path": feedthrough, "unconnected": "start"}},
        "connection": [{"from": f"a.{s}_output", "to": f"b.{s}_input"} for s in signals]}))
    config = load_config(path)
    ssp = export_ssp(config, tmp_path / "typed.ssp")
    root = ssd_of(ssp)
    assert_valid_ssp_1_0(root)
    assert root.find(".//ssd:Connector[@name='Enumeration_input']/ssc:Enumeration", NS).get(
        "name") == "Option"
    assert [i.get("name") for i in root.findall(
        "ssd:Enumerations/ssc:Enumeration[@name='Option']/ssc:Item", NS)] == ["Option 1",
                                                                              "Option 2"]
    loaded = load_ssp(ssp)
    assert loaded.fmus[0].parameters == values and loaded.algorithm == "gauss-seidel"
    original, again = simulate_config(config), simulate_config(loaded)
    for name in original.signals:
        assert np.array_equal(original[name], again[name]), name
    for s in signals:
        assert np.all(again[f"b.{s}_output"] == values[f"{s}_input"])


def test_sources_in_an_ssp(tmp_path):
    """A constant source becomes the start value of the input it feeds (gain and offset
    applied); a time-varying one other than the reference cannot be exported."""
    constant = write_config(
        tmp_path, source=[{"kind": "constant", "values": {"u": 0.25}}],
        connection=[{"from": "u", "to": "ft.Float64_discrete_input", "gain": 4.0,
                     "offset": 1.0}])
    config = load_config(constant)
    path = export_ssp(config, tmp_path / "constant.ssp")
    assert load_ssp(path).sources == config.sources  # flexff's copy of the configuration
    loaded = load_ssp(rewritten(path, tmp_path / "plain.ssp", without_configuration))
    assert loaded.fmus[1].parameters == {"Float64_discrete_input": 2.0}
    original, again = simulate_config(config), simulate_config(loaded)
    assert np.all(again["ft.Float64_discrete_output"][1:] == 2.0)
    for name in again.signals:
        assert np.array_equal(original[name], again[name]), name
    (tmp_path / "u.csv").write_text("time,u\n0,0\n2,1\n")
    varying = write_config(tmp_path, source=[{"kind": "csv", "path": "u.csv"}],
                           connection=[{"from": "u", "to": "ft.Float64_discrete_input"}])
    with pytest.raises(ValueError, match="cannot carry time-varying source signals, and u"):
        export_ssp(load_config(varying), tmp_path / "varying.ssp")


def rewritten(ssp: Path, target: Path, ssd=None, drop: str | None = None) -> Path:
    """A copy of the archive with another SSD text (`ssd(text) -> text`) or a member left out."""
    with zipfile.ZipFile(ssp) as source, zipfile.ZipFile(target, "w") as out:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == drop:
                continue
            if item.filename == SSD and ssd is not None:
                data = ssd(data.decode()).encode()
            out.writestr(item, data)
    return target


@pytest.mark.parametrize("broken, key, message", [
    ("not a zip", "file", "not an SSP archive"),
    ("damaged", "file", "not an SSP archive"),
    ("no ssd", SSD, "no SystemStructure.ssd"),
    ("malformed", SSD, "not well-formed XML"),
    ("invalid", "/ssd:SystemStructureDescription/ssd:System/ssd:Elements/ssd:Component[1]",
     "not valid SSP 1.0"),
    ("no fmu", "ssd:Component[@name='ft']", "resources/ft.fmu is not in the archive"),
    ("unknown element", "ssd:Connection[1]", "FMU components only"),
    ("unknown parameter", "ssd:Component[@name='vdp']/ssd:ParameterBinding[1]/"
                          "ssv:Parameter[@name='nu']", "has no parameter or input 'nu'"),
])
def test_broken_ssp_is_a_config_error(tmp_path, ssp, broken, key, message):
    path = tmp_path / "broken.ssp"
    if broken == "not a zip":
        path.write_text("SystemStructure.ssd")
    elif broken == "damaged":
        path.write_bytes(ssp.read_bytes()[:1000])
    elif broken == "no ssd":
        rewritten(ssp, path, drop=SSD)
    elif broken == "malformed":
        rewritten(ssp, path, lambda text: text[:200])
    elif broken == "invalid":
        rewritten(ssp, path, lambda text: text.replace('source="resources/vdp.fmu"', ""))
    elif broken == "no fmu":
        rewritten(ssp, path, drop="resources/ft.fmu")
    elif broken == "unknown element":
        rewritten(ssp, path, lambda text: text.replace('startElement="vdp"',
                                                       'startElement="pdv"'))
    else:
        rewritten(ssp, path, lambda text: text.replace('name="mu"', 'name="nu"'))
    with pytest.raises(ConfigError, match=message) as error:
        load_ssp(path)
    assert error.value.key == key
