"""The default experiment, honoured: [run] start and tolerance, a per-FMU tolerance, and by
default each FMU's own DefaultExperiment (the start time of the first FMU, each FMU's
tolerance), passed to fmi2SetupExperiment / fmi3EnterInitializationMode. Point k is at
start + k * step everywhere: the master, the recording, CSV sources, libcosim, SSP, run.json.

The probe FMU (tests/probe_fmu.c, compiled here) reports the start time and tolerance it was
given and the time of each communication point; a Reference-FMU run from t = 5 s is checked
against fmpy.simulate_fmu(start_time=5) bit for bit.
"""

from __future__ import annotations

import json

import fmpy
import numpy as np
import pytest

from flexff.cosim.config import expanded, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.libcosim import run_libcosim
from flexff.cosim.run import run_config, simulate_config
from flexff.cosim.scenario import resolve
from flexff.cosim.ssp import export_ssp, load_ssp
from tests.helpers import REFERENCE_FMUS
from tests.probe_fmu import build_probe

START, STOP, STEP, TOLERANCE = 20.0, 21.0, 0.1, 1e-4


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    """The probe with a default experiment from t = 20 s to 21 s, step 0.1, tolerance 1e-4."""
    return build_probe(tmp_path_factory.mktemp("probe"), startTime=START, stopTime=STOP,
                       stepSize=STEP, tolerance=TOLERANCE)


@pytest.fixture(scope="module")
def plain_probe(tmp_path_factory):
    """The probe whose default experiment gives neither a start time nor a tolerance."""
    return build_probe(tmp_path_factory.mktemp("plain"), stopTime=1.0)


def probe_config(path, run=None, fmu=None):
    return parse_config({"run": {"step": STEP, **(run or {})},
                         "fmu": {"p": {"path": str(path), **(fmu or {})}},
                         "source": [{"kind": "constant", "values": {"u": 1.5}}]})


def test_the_default_experiment_is_used(probe):
    config = probe_config(probe)
    assert (config.start, config.stop, config.steps) == (START, STOP, 10)
    recording = simulate_config(config)
    points = START + np.arange(11) * STEP
    assert np.array_equal(recording.time, points)
    # the FMU's clock after the step from t_k is t_k + step, t_k the master's start + k * step
    assert np.array_equal(recording["p.clock"], [START, *(points[:-1] + STEP)])
    assert np.all(recording["p.start_seen"] == START)
    assert np.all(recording["p.tolerance_seen"] == TOLERANCE)


def test_run_and_fmu_keys_override_the_default_experiment(probe):
    run = probe_config(probe, {"start": 2.0, "stop": 2.5, "tolerance": 1e-6})
    recording = simulate_config(run)
    assert recording.time[0] == 2.0 and recording.time.size == 6
    assert np.all(recording["p.start_seen"] == 2.0)
    assert np.all(recording["p.tolerance_seen"] == 1e-6), "[run] tolerance over the FMU's"
    own = simulate_config(probe_config(probe, {"tolerance": 1e-6}, {"tolerance": 1e-3}))
    assert np.all(own["p.tolerance_seen"] == 1e-3), "[fmu.p] tolerance over [run]'s"


def test_without_a_default_experiment_start_is_zero_and_no_tolerance(plain_probe):
    recording = simulate_config(probe_config(plain_probe))
    assert recording.time[0] == 0.0 and recording.time[-1] == 1.0
    assert np.all(recording["p.start_seen"] == 0.0)
    assert np.all(recording["p.tolerance_seen"] == -1.0), "no tolerance defined"


@pytest.mark.parametrize("run, key", [
    ({"start": 21.0}, "run.stop"),  # the end before the start
    ({"start": 20.05, "stop": 21.0}, "run.stop"),  # 0.95 s is no whole number of 0.1 s steps
    ({"tolerance": 0.0}, "run.tolerance"),
    ({"tolerance": "1e-4"}, "run.tolerance"),
])
def test_bad_times_and_tolerances_name_their_key(probe, run, key):
    with pytest.raises(ConfigError) as caught:
        probe_config(probe, run)
    assert caught.value.key == key


def test_a_csv_source_is_read_at_the_runs_times(probe, tmp_path):
    table = tmp_path / "u.csv"
    table.write_text("time,u\n20,0\n21,10\n")
    config = parse_config({"run": {"step": STEP}, "fmu": {"p": {"path": str(probe)}},
                           "source": [{"kind": "csv", "path": str(table)}]})
    recording = simulate_config(config)
    assert np.allclose(recording["p.y"], 2 * 10 * (recording.time - START), atol=1e-12)


def test_run_json_records_what_was_used(probe, tmp_path):
    run_config(probe_config(probe), tmp_path)
    used = json.loads((tmp_path / "run.json").read_text())
    assert (used["run"]["start"], used["run"]["stop"]) == (START, STOP)
    assert used["fmu"]["p"]["tolerance"] == TOLERANCE
    again = parse_config(used)
    assert (again.start, again.stop, again.fmus[0].tolerance) == (START, STOP, TOLERANCE)


def test_ssp_default_experiment_keeps_the_start(probe, tmp_path):
    config = probe_config(probe, {"start": 3.0, "stop": 4.0})
    path = export_ssp(config, tmp_path / "probe.ssp")
    back = load_ssp(path)
    assert (back.start, back.stop, back.steps) == (3.0, 4.0, 10)
    assert expanded(back)["run"]["start"] == 3.0


def test_libcosim_runs_from_the_start(probe, tmp_path):
    scenario = resolve(probe_config(probe), tmp_path)
    recording = run_libcosim(scenario.fmus, scenario.sources, STEP, scenario.steps,
                             start=START)
    # libcosim counts integer nanoseconds: its times are the master's to round-off
    assert np.allclose(recording["p.clock"], START + (np.arange(10) + 1) * STEP, atol=1e-9,
                       rtol=0)
    assert np.array_equal(recording.time, START + (np.arange(10) + 1) * STEP)


@pytest.mark.parametrize("version", [2, 3])
def test_a_reference_fmu_from_a_start_time_equals_fmpy(version):
    fmu = REFERENCE_FMUS / f"fmi{version}" / "VanDerPol.fmu"
    config = parse_config({"run": {"step": 0.01, "start": 5.0, "stop": 10.0},
                           "fmu": {"vdp": {"path": str(fmu)}}})
    recording = simulate_config(config)
    theirs = fmpy.simulate_fmu(str(fmu), fmi_type="CoSimulation", step_size=0.01,
                               output_interval=0.01, start_time=5.0, stop_time=10.0,
                               output=["x0", "x1"])
    assert np.array_equal(recording.time, theirs["time"])
    for name in ("x0", "x1"):
        assert np.array_equal(recording[f"vdp.{name}"], theirs[name]), name
