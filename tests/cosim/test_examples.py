"""`flexff config example third-party-fmus`, as a stranger runs it: printed, saved in a folder
outside the checkout, run there; its FMI 3.0 Van der Pol against FMPy, the gain and offset and
the CSV source against their definitions."""

import csv

import fmpy
import numpy as np

from flexff.cli import main
from flexff.cosim.recording import load_recording
from tests.helpers import REPOSITORY, readme_block


def test_third_party_example_runs_from_any_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["config", "example", "third-party-fmus"]) == 0
    config = tmp_path / "run.toml"
    config.write_text(capsys.readouterr().out)
    assert main(["run", str(config), "-o", "out"]) == 0, capsys.readouterr().err
    rec = load_recording(tmp_path / "out")
    assert rec.time[-1] == 20.0 and rec.time.size == 2001
    vdp_path = next(line.split('"')[1] for line in config.read_text().splitlines()
                    if line.startswith("path") and "VanDerPol" in line)
    fmpy_result = fmpy.simulate_fmu(vdp_path, fmi_type="CoSimulation", step_size=0.01,
                                    output_interval=0.01, stop_time=20.0,
                                    start_values={"mu": 1.5}, output=["x0"])
    assert np.array_equal(rec["vdp.x0"], fmpy_result["x0"])  # the FMU's mu = 1.5, as in FMPy
    # Gauss-Seidel: the Feedthrough gets 2 x0 + 0.5 of the same communication point
    assert np.allclose(rec["ft.Float64_continuous_output"], 2.0 * rec["vdp.x0"] + 0.5,
                       rtol=0, atol=1e-15)
    with open(next(p for p in config.read_text().split('"') if p.endswith(".csv"))) as f:
        rows = [(float(r["time"]), float(r["setpoint"])) for r in csv.DictReader(f)]
    t, setpoint = np.array(rows).T
    assert np.allclose(rec["ft.Float64_discrete_output"], np.interp(rec.time, t, setpoint),
                       rtol=0, atol=1e-12)


def test_readme_shows_the_example_as_shipped():
    shipped = (REPOSITORY / "flexff" / "cosim" / "examples" / "third-party-fmus.toml").read_text()
    assert readme_block("flexff/cosim/examples/third-party-fmus.toml") == shipped
