"""Success paths of the command line that no other test takes, run in-process through
flexff.cli.main as `flexff ...` would run them (the paced run in a process of its own, since
--cpu pins the process that runs it): exit code 0 and what README.md promises each writes."""

import json
import math
import os
import re
import subprocess
import sys
import zipfile
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

import flexff
from flexff.cli import main
from flexff.cosim.config import config_examples
from flexff.cosim.recording import load_recording
from flexff.fmu.importer import read_fmu
from flexff.fmu.validation import validate_fmu
from flexff.learning import collect
from flexff.learning.dataset import MANIFEST, REFERENCE_SIGNALS, load_dataset
from flexff.learning.export import export
from flexff.learning.synthetic import synthetic_dataset
from flexff.learning.train import train
from flexff.plant.references import thesis_evaluation
from tests.controllers.test_learned_feedforward import independent_forces
from tests.cosim.test_ssp import write_config
from tests.helpers import NETWORK_RTOL
from tests.runners import run_fmu

RUN_FILES = ("signals.parquet", "metrics.json", "run.json")  # a plain run: no CSV, no plot
TRAIN_FILES = ("run.json", "model.pt", "metrics.json", "loss.png")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    return synthetic_dataset(tmp_path_factory.mktemp("tiny") / "data", n_train=3, n_test=1,
                             duration=3.0, rate_hz=100.0, seed=3)


@pytest.fixture(scope="module")
def model(tiny, tmp_path_factory) -> Path:
    """A small LSTM (12 units, one epoch) exported as `flexff export` exports it."""
    folder = tmp_path_factory.mktemp("model")
    train("lstm", "fast", tiny, folder / "run", progress=False, epochs=1, val_fraction=0.2,
          hidden=12)
    return export(folder / "run", folder / "lstm.onnx")


def _signals(folder: Path) -> dict[str, np.ndarray]:
    recording = load_recording(folder)
    return {"time": recording.time, **recording.signals}


def test_ssp_export_and_run(tmp_path, monkeypatch, capsys):
    """`flexff ssp export` writes an SSP archive with the FMUs; `flexff run SYSTEM.ssp` runs it
    to the same record as the TOML it came from (VanDerPol -> gain 2, offset 0.5 ->
    Feedthrough, Jacobi, 0.01 s steps to 2 s)."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))  # the archive unpacks there
    config, ssp = write_config(tmp_path), tmp_path / "system.ssp"
    assert main(["ssp", "export", str(config), "-o", str(ssp)]) == 0
    assert capsys.readouterr().out == f"wrote {ssp}\n"
    with zipfile.ZipFile(ssp) as archive:
        assert {"SystemStructure.ssd", "resources/vdp.fmu", "resources/ft.fmu"} <= set(
            archive.namelist())
    assert main(["run", str(ssp), "-o", str(tmp_path / "ssp")]) == 0
    assert re.fullmatch(rf"\S+: real-time factor \d+ -> {re.escape(str(tmp_path / 'ssp'))}\n",
                        capsys.readouterr().out)
    assert all((tmp_path / "ssp" / name).is_file() for name in RUN_FILES)
    assert main(["run", str(config), "-o", str(tmp_path / "toml")]) == 0
    ours, original = _signals(tmp_path / "ssp"), _signals(tmp_path / "toml")
    assert np.array_equal(ours["time"], np.linspace(0.0, 2.0, 201))
    assert sorted(ours) == sorted(original)
    for name in ours:
        assert np.array_equal(ours[name], original[name]), name
    # VanDerPol (the Reference-FMU steps it by explicit Euler) with the mu = 1.5 the archive
    # binds, from x0 = 2, x1 = 0; the gain and offset into Feedthrough, a step late (Jacobi)
    x = np.empty((201, 2))
    x[0] = 2.0, 0.0
    for k in range(200):
        x0, x1 = x[k]
        x[k + 1] = x0 + 0.01 * x1, x1 + 0.01 * (1.5 * (1 - x0**2) * x1 - x0)
    assert np.allclose(ours["vdp.x0"], x[:, 0], rtol=0, atol=1e-12)
    out = ours["ft.Float64_continuous_output"]
    assert np.allclose(out[1:], 2.0 * x[:-1, 0] + 0.5, rtol=0, atol=1e-12)


def test_fmu_build_feedforward(model, tmp_path, capsys):
    """`flexff fmu build learned-feedforward --model M.onnx`: a valid FMU whose forces are those
    of an independent onnxruntime runner of the model; with `--step 0.002` the network still runs at
    the model's 100 Hz, so at every call the forces are the 1 ms FMU's."""
    fmus = {step: tmp_path / f"ff{step}.fmu" for step in (0.001, 0.002)}
    assert main(["fmu", "build", "learned-feedforward", "--model", str(model), "-o",
                 str(fmus[0.001])]) == 0
    assert main(["fmu", "build", "learned-feedforward", "--model", str(model), "--step", "0.002",
                 "-o", str(fmus[0.002])]) == 0
    assert capsys.readouterr().out == "".join(f"wrote {f}\n" for f in fmus.values())
    for step, fmu in fmus.items():
        assert validate_fmu(fmu) == []
        assert float(read_model_description(str(fmu)).defaultExperiment.stepSize) == step
        variables = read_fmu(fmu).variables
        assert [n for n, v in variables.items() if v.causality == "input"] == list(
            REFERENCE_SIGNALS)
        assert [n for n, v in variables.items() if v.causality == "output"] == ["Fx_ff", "Fy_ff"]
    steps = 600  # 0.6 s of the thesis evaluation reference, on its circle
    signals = thesis_evaluation().signals()
    reference = {n: signals[n][5000:5000 + steps + 1] for n in REFERENCE_SIGNALS}
    out = run_fmu(fmus[0.001], steps, 1e-3, {n: reference[n][:steps] for n in reference})
    fine = np.column_stack([out["Fx_ff"], out["Fy_ff"]])[:steps]
    expected = independent_forces(model, reference)[:steps]
    assert np.abs(fine - expected).max() <= NETWORK_RTOL * np.abs(expected).max()
    out = run_fmu(fmus[0.002], steps // 2, 2e-3, {n: reference[n][:steps:2] for n in reference})
    coarse = np.column_stack([out["Fx_ff"], out["Fy_ff"]])[:steps // 2]
    calls = slice(0, None, 10)  # the network's calls: every 10 ms
    assert np.abs(fine[calls]).max() > 0
    assert np.abs(coarse[::5] - fine[calls]).max() <= 1e-12 * np.abs(fine[calls]).max()


def _table(text: str) -> dict[str, dict[str, str]]:
    """The first markdown table of `text`: row label -> column header -> cell."""
    lines = text[text.index("\n|"):].strip().split("\n\n")[0].splitlines()
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    assert set(lines[1].replace("|", "").replace(":", "")) == {"-"}  # the alignment row
    rows = {}
    for line in lines[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert len(cells) == len(header), line
        rows[cells[0]] = dict(zip(header[1:], cells[1:]))
    return rows


def test_evaluate_for_real(tiny, tmp_path, capsys):
    """`flexff evaluate` on a tiny dataset with one model for one epoch, nothing mocked: the
    files it promises, and a table whose figures are the summary's and whose ratios are its
    own columns' quotients."""
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(tiny), "--models", "lstm", "--epochs", "1",
                 "-o", str(out)]) == 0
    for name in ("summary.json", "table.md", "paths.png", "errors.png", "forces.png",
                 "lstm.onnx"):
        assert (out / name).is_file(), name
    table_text = (out / "table.md").read_text()
    printed = capsys.readouterr().out
    assert table_text in printed and f"results in {out}/" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["scenarios"]) == ["pid", "rigid-body", "identified", "lstm", "limit"]
    rows = _table(table_text)
    columns = {"pid": "PID alone", "rigid-body": "rigid-body FF", "lstm": "LSTM FF"}
    for axis in ("x", "y"):
        row = rows[f"e2 {axis} (rms/√T)"]
        pid = float(row[columns["pid"]])
        assert 1e-4 < 1e-4 * pid < 1e-2  # m/sqrt(s): millimetres of error over 15 s
        for scenario, column in columns.items():
            value, _, ratio = row[column].partition(" (")
            assert float(value) * 1e-4 == pytest.approx(  # printed to 3 digits at least
                summary["scenarios"][scenario][axis]["e2"], rel=5e-3), (scenario, axis)
            if scenario != "pid":  # "(2.6x)", "(420x)": to the last digit printed
                ratio = ratio.rstrip("x)")
                last = 0.5 * 10.0 ** -len(ratio.partition(".")[2])
                printed = summary["scenarios"][scenario][axis]["e2_ratio"]
                assert abs(float(ratio) - printed) <= last * (1 + 1e-9), (scenario, axis)
                assert float(ratio) == pytest.approx(pid / float(value), rel=0.01, abs=last)
        assert summary["scenarios"]["rigid-body"][axis]["e2_ratio"] > 300  # the exact model
        assert math.isfinite(summary["scenarios"]["lstm"][axis]["e2_ratio"])
    training = _table(table_text.split("Training")[1])["LSTM FF"]
    assert training["epochs (kept)"] == "1 (1)"
    assert int(training["parameters"]) == summary["training"]["lstm"]["parameters"] > 0
    assert float(training["test MSE"]) == pytest.approx(summary["training"]["lstm"]["test_mse"],
                                                       rel=1e-2)


HEAVY = """[reference]
kind = "thesis-eval"

[plant]
m_up1 = 0.13      # nominal: 0.1 kg
k_t1 = 0.0332     # nominal: 0.0369 N*m/A
"""


def test_data_collect_on_your_own_loop(tmp_path, monkeypatch, capsys):
    """`flexff data collect --set sim --config CONFIG.toml` on the nominal plant with a heavier
    first arm and a weaker first motor. The whole set takes 20 s on 2 cores (the slow
    tests/learning/test_collect.py::test_the_whole_sim_set runs it): here the collection is held
    to the set's first two trajectories."""
    monkeypatch.setattr(collect, "run_collection", partial(collect.run_collection, limit=2))
    config, out = tmp_path / "heavy.toml", tmp_path / "data"
    config.write_text(HEAVY)
    assert main(["data", "collect", "--set", "sim", "--config", str(config), "-o",
                 str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"sim: 2 trajectories -> {out}: 2 run, 0 skipped (already there), 0 failed" in printed
    current = float(re.search(r"largest commanded motor current: ([\d.]+) A", printed)[1])
    assert 0.1 < current < 10.0  # inside the amplifier's 10 A
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["set"] == "sim" and manifest["sample_rate_hz"] == 1000
    plant = manifest["loop"]["configuration"]["fmu"]["plant"]
    assert plant["parameters"] == {"m_up1": 0.13, "k_t1": 0.0332}
    # the same trajectories on the set's own loop (the nominal plant): the heavier arm and the
    # weaker motor make PID lag further behind the same references
    assert main(["data", "collect", "--set", "sim", "-o", str(tmp_path / "nominal")]) == 0
    nominal = {t.name: t for t in load_dataset(tmp_path / "nominal").trajectories}
    dataset = load_dataset(out)
    assert [t.name for t in dataset.trajectories] == list(nominal) and len(nominal) == 2
    for t in dataset.trajectories:
        assert (out / f"{t.name}.npz").is_file()
        errors = [np.sqrt(np.mean((s["x"] - s["x_ref"])**2 + (s["y"] - s["y_ref"])**2))
                  for s in (t.signals, nominal[t.name].signals)]
        assert np.array_equal(t.signals["x_ref"], nominal[t.name].signals["x_ref"])
        assert errors[1] < errors[0] < 0.5 * np.ptp(t.signals["x_ref"]), errors
        force = np.hypot(t.signals["Fx"], t.signals["Fy"])
        assert np.all(np.isfinite(force)) and force.max() > 0.01  # N: the labels


def test_data_collect_on_your_own_loop_as_ssp(tmp_path, monkeypatch, capsys):
    """The same loop exported with `flexff ssp export` and collected with `--config
    SYSTEM.ssp`: the SSP reads back as the loop it was written from (built-in controller and
    plant, the heavier arm), so the trajectories equal the TOML's bit for bit, and the TOML's
    dataset folder takes it as the same loop."""
    monkeypatch.setattr(collect, "run_collection", partial(collect.run_collection, limit=2))
    config, system = tmp_path / "heavy.toml", tmp_path / "heavy.ssp"
    config.write_text(HEAVY)
    assert main(["ssp", "export", str(config), "-o", str(system)]) == 0
    for given, out in ((config, "from-toml"), (system, "from-ssp")):
        assert main(["data", "collect", "--set", "sim", "--config", str(given), "-o",
                     str(tmp_path / out)]) == 0
    toml, ssp = (load_dataset(tmp_path / out) for out in ("from-toml", "from-ssp"))
    assert [t.name for t in ssp.trajectories] == [t.name for t in toml.trajectories]
    for a, b in zip(toml.trajectories, ssp.trajectories):
        assert a.signals.keys() == b.signals.keys()
        assert all(np.array_equal(a.signals[n], b.signals[n]) for n in a.signals), a.name
    capsys.readouterr()
    assert main(["data", "collect", "--set", "sim", "--config", str(system), "-o",
                 str(tmp_path / "from-toml")]) == 0
    assert "0 run, 2 skipped (already there)" in capsys.readouterr().out


def test_train_thesis_preset(tiny, tmp_path, capsys):
    """`flexff train --preset thesis` (one epoch): the thesis's LSTM of two layers of 100 units
    on the 63 features, and its run folder."""
    run = tmp_path / "run"
    assert main(["train", "--model", "lstm", "--preset", "thesis", "--data", str(tiny), "-o",
                 str(run), "--epochs", "1"]) == 0
    assert sorted(p.name for p in run.iterdir()) == sorted(TRAIN_FILES)
    metrics = json.loads((run / "metrics.json").read_text())
    assert json.loads(capsys.readouterr().out) == metrics | {"run": str(run)}
    assert metrics["preset"] == "thesis" and metrics["epochs"] == 1
    assert len(metrics["history"]["train"]) == 1 and 0 < metrics["test_mse"] < 10
    inputs, hidden = 63, 100  # PyTorch's LSTM: four gates, each with two biases, then 2 forces
    lstm = 4 * hidden * (inputs + hidden + 2) + 4 * hidden * (hidden + hidden + 2)
    assert metrics["parameters"] == lstm + hidden * 2 + 2
    config = json.loads((run / "run.json").read_text())["config"]
    assert config["preset"] == "thesis" and config["epochs"] == 1


def test_paced_run_pinned_to_cpu_0(tmp_path):
    """`flexff run CONFIG.toml --realtime --cpu 0`, 0.5 s of the PID loop paced at 1 kHz: it
    takes the wall-clock time it simulates and reports the paced steps, pinned to CPU 0."""
    config = tmp_path / "paced.toml"
    config.write_text(config_examples()["thesis-eval-pid"].replace("stop = 15.0", "stop = 0.5"))
    out = tmp_path / "out"
    root = str(Path(flexff.__file__).resolve().parents[1])  # the flexff this test imports
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(filter(None, (root, os.environ.get("PYTHONPATH"))))}
    result = subprocess.run([sys.executable, "-m", "flexff", "run", str(config), "-o", str(out),
                             "--realtime", "--cpu", "0"], capture_output=True, text=True,
                            env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "paced at 1x real time" in result.stdout
    for name in ("signals.parquet", "metrics.json", "run.json", "path.png",
                 "error.png", "forces.png", "tet.png"):
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    timing = metrics["realtime"]
    assert timing["period_us"] == 1000.0 and timing["target_real_time_factor"] == 1.0
    assert timing["steps"] == 500 and timing["process"]["cpu"] == 0
    # paced: the loop took the 0.5 s it simulated (unpaced, it takes about 5 ms)
    assert 0.5 <= metrics["wall_s"] < 5.0
    assert 0.1 < timing["achieved_real_time_factor"] <= 1.001
    assert 0 < timing["tet_us"]["p50"] <= timing["tet_us"]["max"] and timing["overruns"] >= 0
    assert np.isfinite(metrics["x"]["e2"]) and metrics["x"]["einf"] < 0.02
