"""The general form of a run configuration ([fmu.NAME], [[connection]], cosim.schema) on
third-party FMUs: the Reference-FMUs of the Modelica Association (VanDerPol, Feedthrough; FMI 2.0
and 3.0), kept in the repository (tests.helpers.REFERENCE_FMUS; missing -> the tests fail).

Checked against:
  - fmpy.simulate_fmu of the same FMU, and the reference result shipped inside the FMU
    (extra/org.fmi-standard.fmi-ls-ref/VanDerPol_out.csv): a lone FMU must run exactly as there;
  - arithmetic: a [[connection]] with gain and offset is `gain * from + offset` in the same
    floating-point operations, Gauss-Seidel at the same point, Jacobi one step late (with the
    initial values carried through before the first step); typed (Int32) values pass unchanged;
  - the built-in shorthand: the manipulator's short form and a general form naming the very
    same built FMU files by path give bit-equal recordings;
  - `flexff config expand`: parsing its output gives the same configuration;
  - bad input: each mistake raises ConfigError naming its `table.key` before anything runs, and
    `flexff run` reports it as "flexff: error: ..." with exit code 2 and no traceback;
  - the recording's names: `fmu.output`, plus the manipulator's short names.
"""

from __future__ import annotations

import copy
import io
import json
import shutil
import tomllib
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
import tomli_w

from flexff.cli import main
from flexff.cosim.config import config_examples, expanded, expanded_text, load_config, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import PARQUET_NAME, PARTS_NAME, load_recording
from flexff.cosim.run import run_config, simulate_config
from flexff.cosim.scenario import resolve
from tests.helpers import REFERENCE_FMUS

VDP_REFERENCE_CSV = "extra/org.fmi-standard.fmi-ls-ref/VanDerPol_out.csv"
FT_IN, FT_OUT = "ft.Float64_continuous_input", "ft.Float64_continuous_output"
GAIN, OFFSET = 2.0, 0.5
DROP = object()  # in `merged`: remove this key


# -- helpers ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ref_fmu():
    """`ref_fmu("VanDerPol", 3)`: the path of a Reference-FMU; fails (never skips) without one."""
    assert REFERENCE_FMUS.is_dir(), f"the Reference-FMUs are missing: expected {REFERENCE_FMUS}"

    def path(model: str, version: int = 2) -> Path:
        fmu = REFERENCE_FMUS / f"fmi{version}" / f"{model}.fmu"
        assert fmu.is_file(), f"Reference-FMU missing: {fmu}"
        return fmu

    return path


def write_config(folder: Path, data: dict, name: str = "run.toml") -> Path:
    path = folder / name
    path.write_text(tomli_w.dumps(data))
    return path


def link(source: str, target: str, **scale: float) -> dict:
    return {"from": source, "to": target, **scale}


def merged(base: dict, override: dict) -> dict:
    """`base` with `override`'s tables merged in (lists replaced, DROP removes a key)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if value is DROP:
            out.pop(key, None)
        elif isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def vdp_ft(ref_fmu, ft_version: int = 2, algorithm: str = "gauss-seidel") -> dict:
    """VanDerPol (FMI 2.0, mu = 1.5) -> gain, offset -> Feedthrough `ft` (FMI `ft_version`),
    whose Int32_input is given 7 and feeds a second Feedthrough `ft2`."""
    feedthrough = str(ref_fmu("Feedthrough", ft_version))
    return {
        "run": {"step": 0.01, "stop": 20.0, "algorithm": algorithm},
        "fmu": {"vdp": {"path": str(ref_fmu("VanDerPol")), "parameters": {"mu": 1.5}},
                "ft": {"path": feedthrough, "unconnected": "start",
                       "parameters": {"Int32_input": 7}},
                "ft2": {"path": feedthrough, "unconnected": "start"}},
        "connection": [link("vdp.x0", FT_IN, gain=GAIN, offset=OFFSET),
                       link("ft.Int32_output", "ft2.Int32_input")],
    }


def reference_csv(fmu: Path) -> dict[str, np.ndarray]:
    """The reference result shipped inside a Reference-FMU, by column."""
    with zipfile.ZipFile(fmu) as archive:
        text = archive.read(VDP_REFERENCE_CSV).decode()
    header = text.splitlines()[0].split(",")
    data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, j] for j, name in enumerate(header)}


def run_cli(argv: list, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_cli_error(path: Path, out: Path, key: str, fragment: str, capsys) -> None:
    """`flexff run` reports the problem at `key` as a one-line error, exit code 2."""
    code, _, err = run_cli(["run", path, "-o", out], capsys)
    assert code == 2, err
    assert err.startswith("flexff: error:") and f"{key}: " in err and fragment in err, err
    assert "Traceback" not in err


def assert_config_error(path: Path, out: Path, key: str, fragment: str, capsys) -> None:
    """load_config + run_config raise ConfigError at `key` before anything runs, and the CLI
    says so (exit code 2)."""
    with pytest.raises(ConfigError) as error:
        run_config(load_config(path), out)
    assert error.value.key == key and fragment in str(error.value), str(error.value)
    assert not (out / PARQUET_NAME).exists() and not (out / PARTS_NAME).exists()
    assert_cli_error(path, out, key, fragment, capsys)


# -- 1. a lone third-party FMU --------------------------------------------------------------
@pytest.mark.parametrize("version", [2, 3])
def test_van_der_pol_alone_runs_as_fmpy_and_its_reference(ref_fmu, version):
    fmu = ref_fmu("VanDerPol", version)
    config = parse_config({"fmu": {"vdp": {"path": str(fmu)}},
                           "run": {"step": 0.01, "stop": 20.0}})
    recording = simulate_config(config)
    assert recording.time.size == 2001
    fmpy_result = fmpy.simulate_fmu(str(fmu), fmi_type="CoSimulation", step_size=0.01,
                                    output_interval=0.01, stop_time=20.0, output=["x0", "x1"])
    reference = reference_csv(fmu)
    # fmpy steps the FMU with the same calls from the same start values: bit-equal. The shipped
    # reference CSV samples the default experiment (step 0.01) with up to 17 significant
    # digits, which read back exactly; the FMU integrates with forward Euler at its fixed
    # internal step (FIXED_SOLVER_STEP = 0.01, sources/config.h) whatever the importer, so it
    # is bit-equal too (measured difference 0.0 for x0 and x1, FMI 2.0 and 3.0).
    assert np.array_equal(fmpy_result["time"], recording.time), "time vs fmpy: exact"
    assert np.array_equal(reference["time"], recording.time), "time vs reference CSV: exact"
    for name in ("x0", "x1"):
        assert np.array_equal(recording[f"vdp.{name}"], fmpy_result[name]), \
            f"{name} vs fmpy.simulate_fmu: exact (bit-equal)"
        assert np.array_equal(recording[f"vdp.{name}"], reference[name]), \
            f"{name} vs the reference CSV in the FMU: exact (bit-equal)"


# -- 2. connections between third-party FMUs --------------------------------------------------
@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("ft_version", [2, 3])
def test_gain_offset_and_typed_connections(ref_fmu, ft_version, algorithm):
    recording = simulate_config(parse_config(vdp_ft(ref_fmu, ft_version, algorithm)))
    x0, out = recording["vdp.x0"], recording[FT_OUT]
    driven = GAIN * x0 + OFFSET
    assert np.any(np.diff(x0) != 0)  # x0 moves: a lag would show
    # at t = 0 the value has gone through under either algorithm (Jacobi carries the initial
    # values through the connections before the first step; else it would be the start 0)
    assert out[0] == driven[0]
    if algorithm == "gauss-seidel":
        assert np.array_equal(out, driven)  # the same point, exactly
    else:
        assert np.array_equal(out[1:], driven[:-1])  # one step late, exactly
        assert not np.array_equal(out, driven)
    # Int32 output -> Int32 input: the value given to ft's input, unchanged at every point
    assert np.array_equal(recording["ft.Int32_output"], np.full(x0.size, 7))
    assert np.array_equal(recording["ft2.Int32_output"], np.full(x0.size, 7))


# -- 3. the built-in shorthand is the general form --------------------------------------------
SHORT_FORM = {"run": {"stop": 1.0},
              "reference": {"kind": "circle", "radius": 0.01, "duration": 1.0},
              "plant": {"variant": "nominal"}}


def test_built_fmus_by_path_equal_the_shorthand(tmp_path):
    short = parse_config(SHORT_FORM)
    built = {s.name: s for s in resolve(short, tmp_path / "build").fmus}
    assert list(built) == ["controller", "plant"]
    copies = tmp_path / "copies"
    copies.mkdir()
    paths = {name: shutil.copy(s.path, copies / f"{name}.fmu") for name, s in built.items()}
    start = dict(built["plant"].parameters)
    assert set(start) == {"x_start", "y_start"}  # the reference's first point
    general = load_config(write_config(tmp_path, {
        "run": SHORT_FORM["run"], "reference": SHORT_FORM["reference"],
        "source": [{"kind": "constant", "values": {"Fx_ff": 0.0, "Fy_ff": 0.0}}],
        "fmu": {"controller": {"path": str(paths["controller"])},
                "plant": {"path": str(paths["plant"]), "parameters": start}}}))
    expected, got = simulate_config(short), simulate_config(general)
    assert np.array_equal(got.time, expected.time)
    assert sorted(got.signals) == sorted(expected.signals)
    for name, values in expected.signals.items():
        assert np.array_equal(got.signals[name], values), name


# -- 4. flexff config expand -------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(config_examples()))
def test_expand_round_trip(tmp_path, capsys, name):
    config = parse_config(config_examples()[name], name=name)
    again = parse_config(expanded_text(config), name=name)
    assert expanded(again) == expanded(config)
    assert again.fmus == config.fmus and again.connections == config.connections
    assert again.sources == config.sources and again.reference == config.reference
    assert (again.step, again.stop, again.algorithm) == (config.step, config.stop,
                                                         config.algorithm)
    path = tmp_path / f"{name}.toml"
    path.write_text(config_examples()[name])
    code, out, err = run_cli(["config", "expand", path], capsys)
    assert code == 0, err
    assert out == expanded_text(load_config(path))
    assert parse_config(out).fmus == config.fmus
    assert tomllib.loads(out) == expanded(config)


# -- 5. bad input, each naming its key ----------------------------------------------------
BAD = [
    pytest.param({"fmu": {"vdp": {"parameters": {"nu": 1.0}}}}, "fmu.vdp.parameters.nu",
                 "no parameter or input 'nu'", id="unknown-parameter"),
    pytest.param({"fmu": {"vdp": {"parameters": {"mu": "fast"}}}}, "fmu.vdp.parameters.mu",
                 "expected a number", id="parameter-type"),
    pytest.param({"connection": [link("vdp.x0", "ft.Int32_input")]}, "connection[0]",
                 "type mismatch", id="type-mismatch"),
    pytest.param({"connection": [link("vdp.x0", FT_IN), link("vdp.x1", FT_IN)]},
                 "connection[1].to", "already connected", id="input-connected-twice"),
    pytest.param({"fmu": {"ft": {"unconnected": DROP}}}, "fmu.ft", "is not connected",
                 id="unconnected-input"),
    pytest.param({"connection": [link("vdp.x0", "ft.Nope")]}, "connection[0].to",
                 "has no input 'Nope'", id="unknown-input"),
    pytest.param({"connection": [link("vdp.nope", FT_IN)]}, "connection[0].from",
                 "has no output 'nope'", id="unknown-output"),
    pytest.param({"connection": [link("nofmu.x0", FT_IN)]}, "connection[0].from",
                 "no FMU 'nofmu'", id="unknown-fmu"),
    pytest.param({"fmu": {"vdp": {"path": "missing.fmu"}}}, "fmu.vdp.path", "no such file",
                 id="missing-fmu-file"),
    pytest.param({"run": {"order": ["vdp", "ft"]}}, "run.order", "every FMU name once",
                 id="order-incomplete"),
    pytest.param({"run": {"algorithm": "newton"}}, "run.algorithm", "unknown algorithm",
                 id="unknown-algorithm"),
    pytest.param({"connection": [link("ft.Float64_continuous_output",
                                      "ft2.Float64_continuous_input"),
                                 link("ft2.Float64_continuous_output", FT_IN)]},
                 "connection[1]", "algebraic loop", id="algebraic-loop"),
]


@pytest.mark.parametrize("override, key, fragment", BAD)
def test_bad_input_names_its_key(ref_fmu, tmp_path, capsys, override, key, fragment):
    path = write_config(tmp_path, merged(vdp_ft(ref_fmu), override))
    assert_config_error(path, tmp_path / "out", key, fragment, capsys)


def test_algebraic_loop_runs_under_jacobi(ref_fmu, tmp_path):
    """The loop of BAD's "algebraic-loop" is fine under Jacobi: every value is one step old,
    so each Feedthrough passes on what the other gave a step earlier (plus 1 on the way)."""
    loop = merged(vdp_ft(ref_fmu, algorithm="jacobi"), {"connection": [
        link("ft.Float64_continuous_output", "ft2.Float64_continuous_input", offset=1.0),
        link("ft2.Float64_continuous_output", FT_IN)]})
    run_config(load_config(write_config(tmp_path, loop)), tmp_path / "out")
    recording = load_recording(tmp_path / "out")
    ft, ft2 = recording[FT_OUT], recording["ft2.Float64_continuous_output"]
    assert np.array_equal(ft[1:], ft2[:-1]) and np.array_equal(ft2[1:], ft[:-1] + 1.0)
    assert np.array_equal(ft2[2:], ft2[:-2] + 1.0)  # a lap takes two steps and adds 1


def test_units_must_agree(tmp_path, capsys):
    """No Reference-FMU variable declares a unit, so the mismatch is built from the built-ins:
    plant.x (m) into controller.Fx_ff (N)."""
    config = {"reference": SHORT_FORM["reference"],
              "source": [{"kind": "constant", "values": {"Fy_ff": 0.0}}],
              "fmu": {"controller": {"builtin": "controller"}, "plant": {"builtin": "plant"}},
              "connection": [link("plant.x", "controller.Fx_ff")]}
    path = write_config(tmp_path, config)
    assert_config_error(path, tmp_path / "out", "connection[0]", "units differ", capsys)


def test_reference_fmus_declare_no_units(ref_fmu):
    """Why test_units_must_agree uses the built-ins (if this fails, use a Reference-FMU)."""
    from flexff.fmu.importer import read_fmu

    for model in ("VanDerPol", "Feedthrough", "Dahlquist"):
        for version in (2, 3):
            info = read_fmu(ref_fmu(model, version))
            assert all(v.unit is None for v in info.variables.values()), (model, version)


# -- 6. recording names ----------------------------------------------------------------------
def test_recording_names_are_qualified(ref_fmu, tmp_path, capsys):
    """Through `flexff run`, which also reports a run without the manipulator's x, y."""
    path = write_config(tmp_path, merged(vdp_ft(ref_fmu), {"run": {"stop": 1.0}}))
    code, out, err = run_cli(["run", path, "-o", tmp_path / "out"], capsys)
    assert code == 0 and "real-time factor" in out, err
    names = {"time", *load_recording(tmp_path / "out").signals}
    assert {"time", "vdp.x0", "vdp.x1", FT_OUT, "ft.Int32_output", "ft2.Int32_output"} <= names
    assert all("." in n for n in names - {"time"})  # no short names outside the manipulator
    recording = load_recording(tmp_path / "out")
    assert np.array_equal(recording["x0"], recording["vdp.x0"])  # a unique output's own name


def test_manipulator_recording_has_short_names(tmp_path):
    config = merged(SHORT_FORM, {"run": {"stop": 0.2}, "reference": {"duration": 0.2}})
    run_config(load_config(write_config(tmp_path, config)), tmp_path / "out")
    data = load_recording(tmp_path / "out").signals
    assert {"plant.x", "x", "controller.Fx_fb", "Fx_fb"} <= set(data)
    assert np.array_equal(data["plant.x"], data["x"])
    assert np.array_equal(data["controller.Fx_fb"], data["Fx_fb"])



def test_csv_source_feeds_an_input_by_connection(ref_fmu, tmp_path):
    """A CSV series (linearly interpolated onto the step) drives Feedthrough through a
    connection with a gain; a second column reaches an input of its own name."""
    (tmp_path / "u.csv").write_text("time,u,Float64_discrete_input\n0,0,5\n1,2,5\n2,2,7\n")
    data = {"run": {"step": 0.1, "stop": 3.0},
            "source": [{"kind": "csv", "path": "u.csv"}],
            "fmu": {"ft": {"path": str(ref_fmu("Feedthrough")), "unconnected": "start"}},
            "connection": [link("u", FT_IN, gain=3.0)]}
    recording = simulate_config(load_config(write_config(tmp_path, data)))
    t = recording.time
    u = np.interp(t, [0, 1, 2], [0, 2, 2])  # held at its last value after t = 2
    assert np.array_equal(recording[FT_OUT], 3.0 * u)
    assert np.array_equal(recording["ft.Float64_discrete_output"],
                          np.interp(t, [0, 1, 2], [5, 5, 7]))
    (tmp_path / "u.csv").write_text("time,u\n0,0\n0,1\n")
    with pytest.raises(ConfigError, match=r"source\[0\].path: .*data row 2 \(line 3\): time "
                                          r"does not increase"):
        simulate_config(load_config(write_config(tmp_path, data)))


def test_short_names_only_in_manipulator_runs(ref_fmu, tmp_path, capsys):
    """Dahlquist's output is called x: a run of it alone records dq.x, not a manipulator x."""
    config = tmp_path / "dq.toml"
    config.write_text(f'[run]\nstep = 0.1\nstop = 1.0\n[fmu.dq]\npath = "{ref_fmu("Dahlquist")}"\n'
                      '[record]\ncsv = true\n')
    code, _, err = run_cli(["run", config, "-o", tmp_path / "out"], capsys)
    assert code == 0, err
    assert sorted(load_recording(tmp_path / "out").signals) == ["dq.x"]
    header = (tmp_path / "out" / "signals.csv").read_text().splitlines()[0]
    assert header == "time,dq.x"
    assert "x" not in json.loads((tmp_path / "out" / "metrics.json").read_text())
