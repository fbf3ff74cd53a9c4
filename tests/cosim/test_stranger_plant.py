"""A stranger's 3-axis plant FMU (tests.array_plant): FMI array and quoted names in
connections, records and the machine description, and an FMU that declares no output
dependencies stepped by Gauss-Seidel once `feedthrough = false` says its outputs are states."""

import json
import re
import zipfile
from pathlib import Path

import pytest

from flexff.cosim.config import expanded, load_config, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import machine_table, parse_machine
from flexff.cosim.metrics import error_norms
from flexff.cosim.recording import load_recording
from flexff.cosim.run import run_config
from flexff.fmu.errors import InputError
from flexff.fmu.importer import read_fmu
from tests.array_plant import AXES, build_array_plant
from tests.helpers import REFERENCE_FMUS

TARGETS = (0.1, 0.05, 0.02)
AXIS_NAMES = ("r", "y", "z")


def loop_config(feedthrough: bool | None, order: str = '["pid", "plant"]') -> str:
    """A PID per axis around the plant, every port by its FMI name."""
    pid = ", ".join(f'{{ name = "{a}", mass = {m}, crossover_hz = 10.0 }}'
                    for a, m in zip(AXIS_NAMES, (0.02, 2.0, 3.0), strict=True))
    values = ", ".join([*(f"{a}_ref = {t}" for a, t in zip(AXIS_NAMES, TARGETS, strict=True)),
                        *(f"{a}_ff = 0.0" for a in AXIS_NAMES)])
    text = [f"[run]\nstep = 0.001\nstop = 1.5\norder = {order}\n",
            f"[fmu.pid]\nbuiltin = \"pid\"\naxes = [{pid}]\n",
            "[fmu.plant]\npath = \"arrayplant.fmu\"",
            *([f"feedthrough = {str(feedthrough).lower()}"] if feedthrough is not None else []),
            f"\n[[source]]\nkind = \"constant\"\nvalues = {{ {values} }}\n"]
    for k, a in enumerate(AXIS_NAMES, start=1):
        text.append(f'[[connection]]\nfrom = "pid.{a}_effort"\nto = "plant.force[{k}]"\n'
                    f'[[connection]]\nfrom = "plant.pos[{k}]"\nto = "pid.{a}"\n')
    text.append("[record]\nsignals = [\"plant.pos[1]\", \"plant.pos[2]\", \"plant.pos[3]\", "
                "\"plant.'tip speed'\", \"pid.z_effort\"]"
                "\n\n[machine]\nname = \"three\"")
    for k, a in enumerate(AXIS_NAMES, start=1):
        text.append(f'[[machine.axis]]\nname = "{a}"\nmeasured = "plant.pos[{k}]"\n'
                    f'feedforward = "pid.{a}_ff"\neffort = "pid.{a}_effort"\n'
                    f"range = [-0.2, 0.2]\nvelocity = 1.0\nacceleration = 10.0")
    return "\n".join(text) + "\n"


@pytest.fixture(scope="module")
def plant(tmp_path_factory) -> Path:
    return build_array_plant(tmp_path_factory.mktemp("arrayplant"))


@pytest.fixture
def folder(tmp_path: Path, plant: Path) -> Path:
    (tmp_path / "arrayplant.fmu").write_bytes(plant.read_bytes())
    return tmp_path


def test_the_plant_declares_no_output_dependencies(plant: Path):
    info = read_fmu(plant)
    assert info.outputs == (*(f"pos[{k}]" for k in range(1, AXES + 1)), "'tip speed'")
    assert info.undeclared == set(info.outputs)
    assert info.dependencies["pos[1]"] == set(info.inputs)


@pytest.mark.parametrize("order", ['["pid", "plant"]', '["plant", "pid"]'])
def test_without_the_setting_every_order_is_a_loop_and_the_error_names_it(folder: Path, order):
    (folder / "run.toml").write_text(loop_config(None, order))
    with pytest.raises(ConfigError, match=r"an algebraic loop; .* plant declares no output "
                                          r"dependencies, .*set feedthrough = false in "
                                          r"\[fmu\.plant\]"):
        run_config(folder / "run.toml", folder / "out")


def test_feedthrough_false_runs_gauss_seidel_by_fmi_names(folder: Path):
    (folder / "run.toml").write_text(loop_config(False))
    config = load_config(folder / "run.toml")
    assert config.algorithm == "gauss-seidel"
    assert not next(f for f in config.fmus if f.name == "plant").feedthrough
    assert parse_config(expanded(config)).fmus == config.fmus  # the setting round-trips
    metrics = run_config(config, folder / "out")
    record = load_recording(folder / "out")
    assert {"plant.pos[1]", "plant.'tip speed'", "pid.z_effort"} <= set(record.signals)
    for k, (axis, target) in enumerate(zip(AXIS_NAMES, TARGETS, strict=True), start=1):
        assert record[f"plant.pos[{k}]"][-1] == pytest.approx(target, rel=0.1)
        error = target - record[f"plant.pos[{k}]"]
        assert metrics[axis]["e2"] == pytest.approx(error_norms(error, 0.001)["e2"], rel=1e-12)
    assert record["pid.z_effort"][-1] == pytest.approx(3.0 * 9.81, rel=0.05)  # holds gravity
    assert json.loads((folder / "out" / "metrics.json").read_text())["z"]["e2"] > 0


def test_a_bad_array_name_says_how_to_write_one(folder: Path):
    (folder / "run.toml").write_text(loop_config(False).replace(
        'measured = "plant.pos[1]"', 'measured = "plant.pos[x]"'))
    with pytest.raises(ConfigError, match=r"machine\.axis\[0\]\.measured: .*no FMI array "
                                          r"element .*whole numbers"):
        load_config(folder / "run.toml")


def test_feedthrough_must_be_a_boolean(folder: Path):
    (folder / "run.toml").write_text(loop_config(False).replace("feedthrough = false",
                                                                'feedthrough = "no"'))
    with pytest.raises(ConfigError, match=r"fmu\.plant\.feedthrough: expected true or false"):
        load_config(folder / "run.toml")


LOGS_ONLY = {"name": "drive", "axis": [{"name": "x", "range": [-0.1, 0.1], "velocity": 0.5,
                                        "acceleration": 5.0}]}


def test_a_description_of_logs_alone_needs_no_loop_signals(folder: Path):
    """Its axes give limits alone; a loop run with it asks for the loop's signals."""
    machine = parse_machine(LOGS_ONLY, "logs.toml")
    assert machine.signals[-2:] == ("x_measured", "x_effort")
    assert parse_machine(machine_table(machine), "manifest") == machine  # a dataset's copy
    with pytest.raises(InputError, match=r"machine axis 'x': no effort given"):
        assert machine.axes[0].effort
    text = loop_config(False).split("[machine]")[0] + (
        '[machine]\nname = "three"\n[[machine.axis]]\nname = "r"\nrange = [-0.2, 0.2]\n'
        "velocity = 1.0\nacceleration = 10.0\n")
    (folder / "run.toml").write_text(text)
    with pytest.raises(ConfigError, match=r"machine\.axis\[0\]\.measured: required where a "
                                          r"loop is run"):
        run_config(folder / "run.toml", folder / "out")


def test_an_output_that_is_a_state_depends_on_no_input_without_a_declaration(tmp_path):
    """The Reference FMUs' VanDerPol with its dependency lists taken out: its outputs x0, x1
    are the states of its Derivatives, which only integration changes."""
    source = REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"
    stripped = tmp_path / "VanDerPol.fmu"
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(stripped, "w") as out:
        for item in original.infolist():
            data = original.read(item)
            if item.filename == "modelDescription.xml":
                data = re.sub(rb'(<Outputs>.*?</Outputs>)', lambda m: re.sub(
                    rb' dependencies="[^"]*"(?: dependenciesKind="[^"]*")?', b"", m.group(1)),
                    data, flags=re.DOTALL)
            out.writestr(item, data)
    info = read_fmu(stripped)
    assert info.declared == set() and info.states == {"x0", "x1"}
    assert info.undeclared == set() and info.dependencies["x0"] == set()


def test_feedthrough_false_is_refused_for_an_fmu_declaring_direct_dependencies(tmp_path):
    """The setting stands in for dependencies an FMU leaves out, never against ones it gives."""
    fmu = REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"
    data = {"fmu": {"ft": {"path": str(fmu), "unconnected": "start", "feedthrough": False}}}
    with pytest.raises(ConfigError, match=r"fmu\.ft\.feedthrough: Feedthrough\.fmu declares "
                                          r"that .*Float64_continuous_output.* depend directly "
                                          r"on its inputs"):
        parse_config(data)
    vdp = {"fmu": {"vdp": {"path": str(REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"),
                           "feedthrough": False}}}
    assert not parse_config(vdp).fmus[0].feedthrough  # declared, and none direct: harmless


def test_a_mistyped_connection_target_is_named_before_the_input_it_leaves_unconnected(
        folder: Path):
    (folder / "run.toml").write_text(loop_config(False).replace('to = "plant.force[1]"',
                                                                'to = "plant.force(1)"'))
    with pytest.raises(ConfigError, match=r"connection\[0\]\.to: arrayplant\.fmu \(plant\) has "
                                          r"no input 'force\(1\)' \(did you mean "
                                          r"'force\[1\]'\?\)"):
        run_config(folder / "run.toml", folder / "out")


def test_feedthrough_false_round_trips_through_ssp(folder: Path):
    """`feedthrough = false` travels in the SSP as flexff's component annotation: read back
    with the configuration, and as a plain system (another tool dropped flexff's copy of
    it), the plant still steps by Gauss-Seidel; without the annotation the plain system is an
    algebraic loop."""
    import warnings

    from flexff.cosim.ssp import SSD, export_ssp, load_ssp
    (folder / "run.toml").write_text(loop_config(False))
    ssp = export_ssp(load_config(folder / "run.toml"), folder / "loop.ssp")

    def rewritten(target: Path, edit) -> Path:
        with zipfile.ZipFile(ssp) as source, zipfile.ZipFile(target, "w") as out:
            for item in source.infolist():
                data = source.read(item)
                out.writestr(item, edit(data.decode()).encode() if item.filename == SSD
                             else data)
        return target
    plain = rewritten(folder / "plain.ssp", lambda text: re.sub(
        r"\s*<flexff:Configuration>.*</flexff:Configuration>", "", text, flags=re.S))
    for path in (ssp, plain):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            config = load_ssp(path)
        assert not next(f for f in config.fmus if f.name == "plant").feedthrough
        assert next(f for f in config.fmus if f.name == "pid").feedthrough
        assert config.algorithm == "gauss-seidel"
    run_config(plain, folder / "plain")
    assert load_recording(folder / "plain")["plant.pos[2]"][-1] == pytest.approx(TARGETS[1],
                                                                                 rel=0.1)
    dropped = rewritten(folder / "dropped.ssp", lambda text: re.sub(
        r"\s*<flexff:Configuration>.*</flexff:Configuration>", "", re.sub(
            r"\s*<ssd:Annotations>\s*<ssc:Annotation type=\"org.flexff\">\s*"
            r"<flexff:Component [^>]*/>\s*</ssc:Annotation>\s*</ssd:Annotations>", "", text),
        flags=re.S))
    with pytest.raises(ConfigError, match=r"plant declares no output dependencies"):
        run_config(dropped, folder / "dropped")
