"""Batches (local processes; Dask only when installed), sweeps, and the `flexff run` and
`flexff config example` commands."""

import itertools
import json
import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim.batch import run_batch, sweep
from flexff.cosim.config import config_examples, load_config, parse_config
from flexff.cosim.recording import load_recording
from flexff.cosim.run import simulate_config
from flexff.cosim.ssp import export_ssp
from tests.helpers import REFERENCE_FMUS

SHORT = """
[run]
stop = 1.0

[reference]
kind = "line-circle"
line_duration = 0.5
radius = 0.005
circle_duration = 0.5
"""


def flexff(*args):
    return subprocess.run([sys.executable, "-m", "flexff", *args], capture_output=True, text=True)


def test_a_broken_run_is_reported_and_the_others_finish(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text(SHORT + '[feedforward]\nkind = "rigid-body"\n')
    broken = tmp_path / "broken.toml"
    broken.write_text(SHORT + "[plant]\nk_t1 = -1.0\n")
    results = run_batch([broken, good], tmp_path / "out", workers=2)
    assert [r.name for r in results] == ["broken", "good"]
    assert not results[0].ok and "plant.k_t1" in results[0].error
    assert results[1].ok and results[1].metrics["x"]["einf"] < 1e-3
    assert json.loads((tmp_path / "out" / "good" / "metrics.json").read_text()) == \
        results[1].metrics
    assert not (tmp_path / "out" / "broken" / "metrics.json").exists()


def test_a_failure_inside_an_fmu_is_reported(tmp_path):
    """A configuration that passes every check but fails in the FMU (1e7 RK4 sub-steps per
    step, past the wrapper's limit) is reported with the FMU's message; one changed in code
    past the checks (dataclasses.replace) is checked before it runs, and refused."""
    config = parse_config(SHORT, name="good")
    failing = parse_config(SHORT + "[plant]\nmax_substep = 1e-10\n", name="failing")
    fmus = tuple(replace(f, parameters={**f.parameters, "k_s1": -5.0})
                 if f.name == "plant" else f for f in config.fmus)
    unchecked = replace(config, name="unchecked", fmus=fmus)
    results = run_batch([config, failing, unchecked], tmp_path, workers=1)
    assert results[0].ok
    assert "CosimError" in results[1].error and "max_substep" in results[1].error
    assert "ConfigError" in results[2].error and "k_s1: must be positive" in results[2].error


def test_sweep(tmp_path):
    path = tmp_path / "base.toml"
    path.write_text(SHORT)
    configs = sweep(path, {"controller.crossover_hz": [2.0, 3.0]})
    assert [c.name for c in configs] == ["base-controller.crossover_hz=2.0",
                                         "base-controller.crossover_hz=3.0"]
    assert [c.builtin("controller").options["crossover_hz"] for c in configs] == [2.0, 3.0]
    with pytest.raises(ValueError, match=r"controller.crossover_hz: expected a number"):
        sweep(path, {"controller.crossover_hz": ["fast"]})


def test_sweep_folder_names_are_safe_and_unique(tmp_path):
    """Values with separators and `..` stay inside the output folder, values that clean up to
    the same name get a suffix, and a value given twice is refused."""
    from flexff.plant.paths import Line, sample

    for name in ("ref.csv", "a b.csv", "a_b.csv"):
        sample(Line((0.0, 0.0), (0.005, 0.0), 0.5), 0.01).to_csv(tmp_path / name)
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "base.toml"
    path.write_text('[reference]\nkind = "csv"\npath = "../ref.csv"\n')
    values = ["../ref.csv", "../sub/../ref.csv", "../a b.csv", "../a_b.csv"]
    names = [c.name for c in sweep(path, {"reference.path": values})]
    assert names == ["base-reference.path=__ref.csv", "base-reference.path=__sub___ref.csv",
                     "base-reference.path=__a_b.csv", "base-reference.path=__a_b.csv-2"]
    for name in names:
        assert re.fullmatch(r"[A-Za-z0-9._=+-]+", name) and ".." not in name
    with pytest.raises(ValueError, match=r"the sweep lists the same value twice: '../ref.csv'"):
        sweep(path, {"reference.path": ["../ref.csv", "../a b.csv", "../ref.csv"]})


def test_a_failed_run_carries_its_traceback_only_when_debugging(tmp_path):
    from flexff.cosim.batch import _run_one

    config = tmp_path / "one.toml"
    config.write_text(SHORT)
    (tmp_path / "file").write_text("")
    plain = _run_one(config, tmp_path / "file" / "one")
    assert plain.error == (f"NotADirectoryError: [Errno 20] is a file, not a folder: "
                           f"'{tmp_path / 'file'}'")
    assert "Traceback" in _run_one(config, tmp_path / "file" / "one", debug=True).error


def test_names_must_differ(tmp_path):
    config = parse_config(SHORT, name="same")
    with pytest.raises(ValueError, match="share the name"):
        run_batch([config, config], tmp_path)


def test_batch_on_a_dask_cluster(tmp_path):
    """A local Dask cluster (threads, one worker) stands in for a remote one: the runs go
    through its scheduler address, and a broken one is reported while the other finishes."""
    from dask.distributed import LocalCluster

    broken = SHORT.replace("radius = 0.005", "radius = 0.2")
    good = parse_config(SHORT, name="good")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        bad = tmp_path / "bad.toml"
        bad.write_text(broken)
        results = run_batch([good, bad], tmp_path / "out", scheduler=cluster.scheduler_address)
    assert [r.ok for r in results] == [True, False]
    assert "outside the workspace" in results[1].error
    assert (tmp_path / "out" / "good" / "metrics.json").is_file()


def test_cli_config_examples(tmp_path):
    listed = flexff("config", "example")
    assert listed.returncode == 0 and listed.stdout.split() == list(config_examples())
    shown = flexff("config", "example", "thesis-eval-rigid-body-ff")
    assert shown.returncode == 0 and shown.stdout == config_examples()["thesis-eval-rigid-body-ff"]
    missing = flexff("config", "example", "nope")
    assert missing.returncode == 2 and "no example 'nope'" in missing.stderr


def test_cli_run_one_and_several(tmp_path):
    one = tmp_path / "one.toml"
    one.write_text(SHORT)
    result = flexff("run", str(one), "-o", str(tmp_path / "single"))
    assert result.returncode == 0, result.stderr
    assert "e2 = (" in result.stdout
    for name in ("signals.parquet", "metrics.json", "run.json", "path.png",
                 "error.png", "forces.png"):
        assert (tmp_path / "single" / name).is_file(), name
    bad = tmp_path / "bad.toml"
    bad.write_text(SHORT.replace("stop = 1.0", "stop = 1.0\nstep = 0.0007"))
    result = flexff("run", str(one), str(bad), "-o", str(tmp_path / "many"), "--workers", "2")
    assert result.returncode == 1
    assert "bad: FAILED: ConfigError" in result.stderr and "run.stop" in result.stderr
    assert (tmp_path / "many" / "one" / "metrics.json").is_file()
    result = flexff("run", str(bad), "-o", str(tmp_path / "x"))
    assert result.returncode == 2 and "run.stop" in result.stderr
    result = flexff("run", str(one), "-o", str(tmp_path / "sweep"), "--sweep",
                    "controller.encoders=2,3")
    assert result.returncode == 0, result.stderr
    for encoders in (2, 3):
        run = json.loads((tmp_path / "sweep" / f"one-controller.encoders={encoders}" /
                          "run.json").read_text())
        assert run["fmu"]["controller"]["encoders"] == encoders


# -- sweeps that compose, on TOML and SSP alike ------------------------------------------------
def vdp_run(folder, text=""):
    """The Reference-FMU VanDerPol (FMI 2.0) alone for 1 s, as a TOML file."""
    path = folder / "vdp.toml"
    path.write_text(f'[run]\nstep = 0.01\nstop = 1.0\n[fmu.vdp]\npath = '
                    f'"{REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"}"\n{text}')
    return path


def test_repeated_sweeps_run_every_combination(tmp_path, capsys):
    """Two --sweep options: four runs, each named by both values and run with both."""
    out = tmp_path / "out"
    assert main(["run", str(vdp_run(tmp_path)), "-o", str(out), "--workers", "2",
                 "--sweep", "fmu.vdp.parameters.mu=0.5,1.5", "--sweep", "run.step=0.01,0.005"]
                ) == 0, capsys.readouterr().err
    for mu, step in itertools.product((0.5, 1.5), (0.01, 0.005)):
        folder = out / f"vdp-fmu.vdp.parameters.mu={mu}-run.step={step}"
        run = json.loads((folder / "run.json").read_text())
        assert run["fmu"]["vdp"]["parameters"] == {"mu": mu} and run["run"]["step"] == step
        expected = simulate_config(parse_config(
            {"run": {"step": step, "stop": 1.0},
             "fmu": {"vdp": {"path": str(REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"),
                             "parameters": {"mu": mu}}}}))
        assert np.array_equal(load_recording(folder)["vdp.x0"], expected["vdp.x0"])
    assert len(list(out.iterdir())) == 4


def test_a_sweep_over_an_ssp_sets_component_parameters(tmp_path, capsys):
    ssp = export_ssp(load_config(vdp_run(tmp_path)), tmp_path / "vdp.ssp")
    out = tmp_path / "out"
    assert main(["run", str(ssp), "-o", str(out), "--sweep", "fmu.vdp.parameters.mu=0.5,2.0"]
                ) == 0, capsys.readouterr().err
    for mu in (0.5, 2.0):
        expected = simulate_config(load_config(vdp_run(tmp_path, f"parameters = {{mu = {mu}}}")))
        got = load_recording(out / f"vdp-fmu.vdp.parameters.mu={mu}")
        assert np.array_equal(got["vdp.x0"], expected["vdp.x0"]), mu


@pytest.mark.parametrize("case, fragment", [
    ("not toml", "bad.toml: file: not valid TOML"),
    ("missing", "missing.toml: file: no such configuration file"),
    ("no such fmu", "vdp.toml: fmu.nosuch.parameters.mu: no FMU 'nosuch' in the file "
                    "(its FMUs: vdp)"),
    ("bad value", "vdp.toml: fmu.vdp.parameters.mu: Real variable: expected a number"),
    ("key twice", "--sweep run.step is given twice"),
])
def test_sweep_errors_name_the_file_and_key(tmp_path, capsys, case, fragment):
    path, sweeps = vdp_run(tmp_path), ["fmu.vdp.parameters.mu=0.5,1.5"]
    if case == "not toml":
        path = tmp_path / "bad.toml"
        path.write_text("[run\n")
    elif case == "missing":
        path = tmp_path / "missing.toml"
    elif case == "no such fmu":
        sweeps = ["fmu.nosuch.parameters.mu=0.5,1.5"]
    elif case == "bad value":
        sweeps = ['fmu.vdp.parameters.mu="fast","slow"']
    else:
        sweeps = ["run.step=0.01,0.005", "run.step=0.002"]
    argv = ["run", str(path), "-o", str(tmp_path / "out")]
    for text in sweeps:
        argv += ["--sweep", text]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("flexff: error: ") and err.count("\n") == 1 and fragment in err, err


PID_AXES = """
[run]
stop = 0.1

[fmu.pid]
builtin = "pid"
axes = [{ name = "x", mass = 2.0, crossover_hz = 20.0 },
        { name = "y", mass = 1.0, crossover_hz = 15.0 }]

[[source]]
kind = "constant"
values = { x_ref = 0.0, y_ref = 0.0 }
"""


def test_a_sweep_sets_one_axis_of_a_list_of_axis_tables(tmp_path):
    """`fmu.pid.axes.x.crossover_hz`: a table in a list, addressed by its name; the other
    axis keeps its own value."""
    path = tmp_path / "pid.toml"
    path.write_text(PID_AXES)
    configs = sweep(path, {"fmu.pid.axes.x.crossover_hz": [10.0, 40.0]})
    assert [c.name for c in configs] == ["pid-fmu.pid.axes.x.crossover_hz=10.0",
                                         "pid-fmu.pid.axes.x.crossover_hz=40.0"]
    axes = [next(f for f in c.fmus if f.name == "pid").options["axes"] for c in configs]
    assert [[a["crossover_hz"] for a in each] for each in axes] == [[10.0, 15.0], [40.0, 15.0]]
    with pytest.raises(ValueError, match=r"fmu.pid.axes.z.crossover_hz: fmu.pid.axes lists no "
                                         r"table named 'z' \(its tables' names: x, y\)"):
        sweep(path, {"fmu.pid.axes.z.crossover_hz": [10.0]})
    with pytest.raises(ValueError, match=r"'axes' lists tables: name one of them "
                                         r"\(fmu.pid.axes.NAME.crossover_hz\)"):
        sweep(path, {"fmu.pid.axes.crossover_hz": [10.0]})
