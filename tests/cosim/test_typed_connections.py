"""Connections between FMU variables of every numeric type (cosim.wiring's rule): gain and
offset on floats, Float64 <-> Float32 converted, integers passed unchanged, everything else
refused at wiring time with exit code 2 naming `connection[k]`.

The FMUs: the Reference-FMUs Feedthrough (FMI 3.0: Float32, Float64, (U)Int8 .. (U)Int64;
FMI 2.0: Real, Integer), two of them, `a` feeding `b`, and VanDerPol (FMI 2.0, x0) driving
the float chains with a signal that moves. Each run is checked against an expectation computed
here with numpy, not by the code under test: a float64 value into a Float32 input is
`numpy.float32(value)` (round to nearest even); gain and offset are `gain * value + offset` in
float64, then converted to the input's type; Gauss-Seidel gives each value at the same point,
Jacobi one step late per connection (after the initial values carried through at t = 0).
Every case runs from the TOML configuration, from the SSP exported from it (flexff's
annotation read back) and from the same SSP without the annotation (a plain SSP system).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tomli_w

from flexff.cli import main
from flexff.cosim.config import load_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import PARQUET_NAME, load_recording
from flexff.cosim.run import simulate_config
from flexff.cosim.schema import RunConfig
from flexff.cosim.ssp import NS, export_ssp, load_ssp
from tests.cosim.test_ssp import assert_valid_ssp_1_0, rewritten, ssd_of, without_configuration
from tests.helpers import REFERENCE_FMUS

STEP, STOP = 0.01, 0.3
GAIN, OFFSET = 3.0, 1.0  # a -> b
DRIVE_GAIN, DRIVE_OFFSET = 2.0, 0.5  # vdp.x0 -> a
ALGORITHMS = ("gauss-seidel", "jacobi")
# (FMI version, the Feedthrough's variable prefix, numpy type): every numeric type
FLOATS = [(3, "Float32", np.float32), (3, "Float64", np.float64), (2, "Float64", np.float64)]
INTEGERS = [(3, "Int8", np.int8), (3, "UInt8", np.uint8), (3, "Int16", np.int16),
            (3, "UInt16", np.uint16), (3, "Int32", np.int32), (3, "UInt32", np.uint32),
            (3, "Int64", np.int64), (3, "UInt64", np.uint64), (2, "Int32", np.int32)]
SSP_INT_MAX = 2**31 - 1  # an ssv:Integer start value is an xs:int in SSP 1.0


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """load_ssp extracts archives into the FMU cache: a fresh one per test."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))


def feedthrough(version: int, **start: object) -> dict:
    table: dict = {"path": str(REFERENCE_FMUS / f"fmi{version}" / "Feedthrough.fmu"),
                   "unconnected": "start"}
    if start:
        table["parameters"] = start
    return table


def connection(source: str, target: str, gain: float = 1.0, offset: float = 0.0) -> dict:
    scale = {"gain": gain, "offset": offset} if (gain, offset) != (1.0, 0.0) else {}
    return {"from": source, "to": target, **scale}


def config_file(folder: Path, algorithm: str, fmus: dict, connections: list, **tables) -> Path:
    path = folder / "run.toml"
    path.write_text(tomli_w.dumps({
        "run": {"step": STEP, "stop": STOP, "algorithm": algorithm},
        "fmu": fmus, "connection": connections, **tables}))
    return path


def three_ways(path: Path, folder: Path) -> dict[str, RunConfig]:
    """The configuration from TOML, from its exported SSP, and from that SSP made plain."""
    ssp = export_ssp(load_config(path), folder / "system.ssp")
    assert_valid_ssp_1_0(ssd_of(ssp))
    plain = rewritten(ssp, folder / "plain.ssp", without_configuration)
    return {"toml": load_config(path), "ssp": load_ssp(ssp), "plain ssp": load_ssp(plain)}


def run_cli(argv: list, capsys) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def late(values: np.ndarray, algorithm: str) -> np.ndarray:
    """What a Feedthrough's output records for its input's `values`: the same point under
    Gauss-Seidel, one step late under Jacobi (point 0 carried through before the first step)."""
    return values if algorithm == "gauss-seidel" else np.concatenate([values[:1], values[:-1]])


def affine(values: np.ndarray, gain: float, offset: float, dtype: type) -> np.ndarray:
    """gain * values + offset in float64, then rounded to the target's type (numpy's cast)."""
    return (gain * values.astype(np.float64) + offset).astype(dtype)


def assert_exact(recorded: np.ndarray, expected: np.ndarray, what: str) -> None:
    assert recorded.shape == expected.shape, what
    assert np.array_equal(recorded, expected.astype(np.float64)), (
        f"{what}: max |difference| {np.max(np.abs(recorded - expected))}")


# -- the defect: a gain on a Float32 connection was accepted and ignored ----------------------
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_float32_gain_and_offset_apply(tmp_path, capsys, algorithm):
    """a.Float32_continuous_output -> b.Float32_continuous_input with gain 3 and offset 1, a's
    input 1.25: b's output is float32(3 * 1.25 + 1) = 4.75 at every point (it was 1.25)."""
    path = config_file(tmp_path, algorithm,
                       {"a": feedthrough(3, Float32_continuous_input=1.25), "b": feedthrough(3)},
                       [connection("a.Float32_continuous_output", "b.Float32_continuous_input",
                                   GAIN, OFFSET)],
                       record={"signals": ["b.Float32_continuous_output"]})
    code, err = run_cli(["run", path, "-o", tmp_path / "out"], capsys)
    assert code == 0, err
    recorded = load_recording(tmp_path / "out")["b.Float32_continuous_output"]
    expected = affine(np.full(recorded.size, 1.25, np.float32), GAIN, OFFSET, np.float32)
    assert_exact(recorded, expected, "TOML, flexff run")
    ssp = export_ssp(load_config(path), tmp_path / "system.ssp")
    (transformation,) = ssd_of(ssp).findall(".//ssc:LinearTransformation", NS)
    assert transformation.attrib == {"factor": "3.0", "offset": "1.0"}
    for how, config in three_ways(path, tmp_path).items():
        assert_exact(simulate_config(config)["b.Float32_continuous_output"], expected, how)


# -- every float type: a moving signal through gain and offset -----------------------------
@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize(("version", "prefix", "dtype"), FLOATS,
                         ids=[f"fmi{v}-{p}" for v, p, _ in FLOATS])
def test_float_chain(tmp_path, version, prefix, dtype, algorithm):
    """vdp.x0 (float64) -> a.T input (x 2 + 0.5, converted to T) -> a.T output -> b.T input
    (x 3 + 1, in float64, converted to T) -> b.T output, for T Float32, Float64 and Real."""
    a_in, a_out = f"a.{prefix}_continuous_input", f"a.{prefix}_continuous_output"
    b_in, b_out = f"b.{prefix}_continuous_input", f"b.{prefix}_continuous_output"
    path = config_file(tmp_path, algorithm, {
        "vdp": {"path": str(REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu")},
        "a": feedthrough(version), "b": feedthrough(version)}, [
        connection("vdp.x0", a_in, DRIVE_GAIN, DRIVE_OFFSET),
        connection(a_out, b_in, GAIN, OFFSET)])
    for how, config in three_ways(path, tmp_path).items():
        recording = simulate_config(config)
        x0 = recording["vdp.x0"]
        assert np.unique(x0).size > 10, "the driving signal moves"
        a = late(affine(x0, DRIVE_GAIN, DRIVE_OFFSET, dtype), algorithm)
        b = late(affine(a, GAIN, OFFSET, dtype), algorithm)
        assert_exact(recording[a_out], a, f"{how}: {a_out}")
        assert_exact(recording[b_out], b, f"{how}: {b_out}")
        if dtype is np.float32:  # rounded to float32 indeed: not the float64 values
            assert not np.array_equal(recording[a_out], late(DRIVE_GAIN * x0 + DRIVE_OFFSET,
                                                             algorithm))


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_float32_output_into_float64_input(tmp_path, algorithm):
    """a.Float32 output -> b.Float64 input (x 3 + 1): computed in float64, not rounded."""
    path = config_file(tmp_path, algorithm, {
        "vdp": {"path": str(REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu")},
        "a": feedthrough(3), "b": feedthrough(3)}, [
        connection("vdp.x0", "a.Float32_continuous_input"),
        connection("a.Float32_continuous_output", "b.Float64_continuous_input", GAIN, OFFSET)])
    for how, config in three_ways(path, tmp_path).items():
        recording = simulate_config(config)
        a = late(recording["vdp.x0"].astype(np.float32), algorithm)
        b = late(GAIN * a.astype(np.float64) + OFFSET, algorithm)
        assert_exact(recording["a.Float32_continuous_output"], a, how)
        assert_exact(recording["b.Float64_continuous_output"], b, how)
        assert not np.array_equal(b, b.astype(np.float32)), "float64 values, not narrowed"


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_constant_source_into_float32_input(tmp_path, algorithm):
    """A constant source (float64) 0.1 -> a.Float32 input (x 3 + 1): float32(1.3)."""
    path = config_file(tmp_path, algorithm, {"a": feedthrough(3)},
                       [connection("c", "a.Float32_continuous_input", GAIN, OFFSET)],
                       source=[{"kind": "constant", "values": {"c": 0.1}}])
    expected = np.full(round(STOP / STEP) + 1, np.float32(GAIN * 0.1 + OFFSET))
    for how, config in three_ways(path, tmp_path).items():
        assert_exact(simulate_config(config)["a.Float32_continuous_output"], expected, how)


# -- every integer type: passed unchanged; gain and offset refused ------------------------
@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize(("version", "prefix", "dtype"), INTEGERS,
                         ids=[f"fmi{v}-{p}" for v, p, _ in INTEGERS])
def test_integer_connection_passes_values_unchanged(tmp_path, version, prefix, dtype,
                                                    algorithm):
    """a.IntN output -> b.IntN input: the extremes of the type, exactly (no float64 on the way:
    2**64 - 1 is not a float64); from SSP, the largest value SSP 1.0 can write."""
    info = np.iinfo(dtype)
    for value in (int(info.max), int(info.min)):
        folder = tmp_path / str(value)
        folder.mkdir()
        path = config_file(folder, algorithm,
                           {"a": feedthrough(version, **{f"{prefix}_input": value}),
                            "b": feedthrough(version)},
                           [connection(f"a.{prefix}_output", f"b.{prefix}_input")])
        recorded = simulate_config(load_config(path))[f"b.{prefix}_output"]
        assert recorded.tolist() == [value] * recorded.size, "TOML"
    path = config_file(tmp_path, algorithm,
                       {"a": feedthrough(version, **{f"{prefix}_input": min(int(info.max),
                                                                            SSP_INT_MAX)}),
                        "b": feedthrough(version)},
                       [connection(f"a.{prefix}_output", f"b.{prefix}_input")])
    for how, config in three_ways(path, tmp_path).items():
        recorded = simulate_config(config)[f"b.{prefix}_output"]
        assert recorded.tolist() == [min(int(info.max), SSP_INT_MAX)] * recorded.size, how


@pytest.mark.parametrize(("version", "prefix", "dtype"), INTEGERS,
                         ids=[f"fmi{v}-{p}" for v, p, _ in INTEGERS])
def test_integer_gain_is_refused(tmp_path, capsys, version, prefix, dtype):
    """Gain or offset on an integer connection: exit 2, one line naming connection[1], from
    TOML (and no SSP exported from it); a plain SSP with a LinearTransformation on Integer
    connectors is refused likewise, naming its ssd:Connection."""
    for algorithm in ALGORITHMS:
        for gain, offset in ((GAIN, 0.0), (1.0, OFFSET)):
            path = config_file(tmp_path, algorithm, {"a": feedthrough(version),
                                                     "b": feedthrough(version)}, [
                connection("a.Float64_continuous_output", "b.Float64_continuous_input"),
                connection(f"a.{prefix}_output", f"b.{prefix}_input", gain, offset)])
            assert_refused(path, tmp_path, "connection[1]", "gain and offset", capsys)
            with pytest.raises(ConfigError, match="gain and offset") as error:
                export_ssp(load_config(path), tmp_path / "refused.ssp")
            assert error.value.key == "connection[1]"
    plain = integer_ssp_with_transformation(tmp_path, version, prefix)
    with pytest.raises(ConfigError) as error:
        simulate_config(load_ssp(plain))
    assert error.value.key == "ssd:Connection[1]" and "gain and offset" in str(error.value)


def integer_ssp_with_transformation(folder: Path, version: int, prefix: str) -> Path:
    """A plain SSP of a.IntN_output -> b.IntN_input with a LinearTransformation added."""
    path = config_file(folder, "jacobi", {"a": feedthrough(version), "b": feedthrough(version)},
                       [connection(f"a.{prefix}_output", f"b.{prefix}_input")])
    ssp = export_ssp(load_config(path), folder / "identity.ssp")

    def transformed(text: str) -> str:
        end = f'endConnector="{prefix}_input"/>'
        assert end in text
        return without_configuration(text).replace(
            end, f'endConnector="{prefix}_input"><ssc:LinearTransformation factor="3.0"/>'
                 f"</ssd:Connection>")

    return rewritten(ssp, folder / "transformed.ssp", transformed)


def assert_refused(path: Path, folder: Path, key: str, fragment: str, capsys) -> None:
    """`flexff run` refuses the configuration with one line naming `key`, exit code 2."""
    code, err = run_cli(["run", path, "-o", folder / "out"], capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("flexff: error:"), err
    assert f"{key}: " in err and fragment in err, err
    assert not (folder / "out" / PARQUET_NAME).exists()


# -- everything else: refused, naming the connection ---------------------------------------
REFUSED = {  # (from, to, gain, offset) of connection[0] -> what the error says
    "boolean gain": (("a.Boolean_output", "b.Boolean_input", 2.0, 0.0), "gain and offset"),
    "enumeration offset": (("a.Enumeration_output", "b.Enumeration_input", 1.0, 1.0),
                           "gain and offset"),
    "float64 into int32": (("a.Float64_continuous_output", "b.Int32_input", 1.0, 0.0),
                           "float64"),
    "int32 into float64": (("a.Int32_output", "b.Float64_continuous_input", 1.0, 0.0),
                           "int32"),
    "int8 into int16": (("a.Int8_output", "b.Int16_input", 1.0, 0.0), "int8"),
    "float32 into int32": (("a.Float32_continuous_output", "b.Int32_input", 1.0, 0.0),
                           "float32"),
    "source into uint8": (("c", "b.UInt8_input", 1.0, 0.0), "float64"),
    "boolean into float64": (("a.Boolean_output", "b.Float64_continuous_input", 1.0, 0.0),
                             "boolean"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_refused_connections(tmp_path, capsys, case):
    (source, target, gain, offset), fragment = REFUSED[case]
    path = config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3), "b": feedthrough(3)},
                       [connection(source, target, gain, offset)],
                       source=[{"kind": "constant", "values": {"c": 1.0}}])
    assert_refused(path, tmp_path, "connection[0]", fragment, capsys)


def test_float32_overflow_fails_naming_the_connection(tmp_path, capsys):
    """A finite float64 beyond float32's range has no nearest float32: the run fails (exit 1)
    naming the connection and the time, rather than giving the input an infinity."""
    path = config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3)},
                       [connection("c", "a.Float32_continuous_input", 1e30, 0.0)],
                       source=[{"kind": "constant", "values": {"c": 1e9}}])
    code, err = run_cli(["run", path, "-o", tmp_path / "out"], capsys)
    assert code == 1, err
    assert "c -> a.Float32_continuous_input" in err and "t = 0 s" in err, err
    assert "float32" in err and "Traceback" not in err, err
