"""Model-exchange FMUs in a run (fmu.model_exchange): integrated with SUNDIALS CVODE (FMPy's
build) between communication points, with state, time and step events as the standard says.

Checked against:
  - fmpy.simulate_fmu(fmi_type="ModelExchange", solver="CVode") on the Reference-FMUs
    (VanDerPol, Dahlquist; FMI 2.0 and 3.0) and on a bouncing ball compiled here
    (tests/bouncing_ball.c: a state event at every bounce, a time event at t = 1.5 s, at rest
    at the end): bit for bit, in-process and in its own process;
  - the equations: Dahlquist's exp(-k t), Van der Pol by scipy at a tight tolerance, the
    ball's first fall and bounce, and its kick;
  - the keys: `solver` on an [fmu.NAME], the default for an FMU without co-simulation, errors.
"""

from __future__ import annotations

import json

import fmpy
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flexff.cosim.config import parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.run import run_config, simulate_config
from tests.helpers import REFERENCE_FMUS
from tests.probe_fmu import build_ball, build_probe

STEP = 0.01
G, E = 9.81, 0.7  # the ball's gravity and restitution (tests/bouncing_ball.c)


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    return build_ball(tmp_path_factory.mktemp("ball"))


def fmpy_me(fmu, stop, outputs):
    return fmpy.simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode",
                             output_interval=STEP, stop_time=stop, output=outputs,
                             record_events=False)


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolated"])
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model, outputs, stop", [("VanDerPol", ["x0", "x1"], 20.0),
                                                  ("Dahlquist", ["x"], 10.0)])
def test_reference_fmus_as_model_exchange_equal_fmpy(model, outputs, stop, version, isolate):
    fmu = REFERENCE_FMUS / f"fmi{version}" / f"{model}.fmu"
    recording = simulate_config(parse_config({
        "run": {"step": STEP, "stop": stop},
        "fmu": {"m": {"path": str(fmu), "solver": "cvode", "isolate": isolate}}}))
    theirs = fmpy_me(fmu, stop, outputs)
    assert np.array_equal(recording.time, theirs["time"])
    for name in outputs:
        assert np.array_equal(recording[f"m.{name}"], theirs[name]), name
    t = recording.time
    if model == "Dahlquist":  # x' = -k x, x(0) = 1, k = 1; CVODE at rtol 1e-5
        assert np.max(np.abs(recording["m.x"] - np.exp(-t))) < 1e-4
    else:  # x0' = x1, x1' = mu (1 - x0^2) x1 - x0 from (2, 0), mu = 1
        exact = solve_ivp(lambda _, x: [x[1], (1 - x[0] ** 2) * x[1] - x[0]], (0, stop),
                          [2.0, 0.0], t_eval=t, rtol=1e-11, atol=1e-12).y
        # CVODE at rtol 1e-5 over 20 s of a limit cycle: a phase error (measured 1.2e-3 in x1)
        assert np.max(np.abs(recording["m.x0"] - exact[0])) < 5e-3
        assert np.max(np.abs(recording["m.x1"] - exact[1])) < 5e-3


@pytest.mark.parametrize("version", [2, 3])
def test_model_exchange_from_a_start_time_equals_fmpy(version):
    fmu = REFERENCE_FMUS / f"fmi{version}" / "VanDerPol.fmu"
    recording = simulate_config(parse_config({
        "run": {"step": STEP, "start": 2.0, "stop": 12.0},
        "fmu": {"m": {"path": str(fmu), "solver": "cvode"}}}))
    theirs = fmpy.simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode",
                               output_interval=STEP, start_time=2.0, stop_time=12.0,
                               output=["x0", "x1"], record_events=False)
    assert np.array_equal(recording.time, theirs["time"])
    for name in ("x0", "x1"):
        assert np.array_equal(recording[f"m.{name}"], theirs[name]), name


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolated"])
def test_the_bouncing_ball_events_equal_fmpy(ball, isolate, tmp_path):
    config = parse_config({"run": {"step": STEP},  # stop: the FMU's default experiment, 3 s
                           "fmu": {"b": {"path": str(ball), "isolate": isolate}}})
    assert config.fmus[0].solver == "cvode", "an FMU without co-simulation is solved"
    recording = simulate_config(config)
    theirs = fmpy_me(ball, 3.0, ["h", "v"])
    for name in ("h", "v"):
        assert np.array_equal(recording[f"b.{name}"], theirs[name]), name
    t, h, v = recording.time, recording["b.h"], recording["b.v"]
    bounce = np.sqrt(2 / G)  # the first fall from h = 1 m
    fall = t < bounce
    assert np.max(np.abs(h[fall] - (1 - G * t[fall] ** 2 / 2))) < 1e-4
    after = np.argmax(t > bounce)  # the first point after the bounce: v = e v_impact - g dt
    assert v[after] == pytest.approx(E * G * bounce - G * (t[after] - bounce), abs=1e-3)
    assert np.all(h >= -1e-9), "no point below the floor: every bounce is found"
    kick = round(1.5 / STEP)  # the time event, +2 m/s at t = 1.5 s, precedes that point's record
    assert v[kick] - v[kick - 1] == pytest.approx(2 - G * STEP, abs=1e-6)
    assert h[-1] == 0 and v[-1] == 0, "at rest at the end"
    run_config(config, tmp_path)
    assert json.loads((tmp_path / "run.json").read_text())["fmu"]["b"]["solver"] == "cvode"


def test_bad_solver_keys_name_their_key(ball, tmp_path):
    with pytest.raises(ConfigError) as caught:
        parse_config({"fmu": {"b": {"path": str(ball), "solver": "euler"}}})
    assert caught.value.key == "fmu.b.solver"
    probe = build_probe(tmp_path, stopTime=1.0)  # co-simulation only
    with pytest.raises(ConfigError, match="no model-exchange interface") as caught:
        parse_config({"run": {"step": 0.1}, "fmu": {"p": {"path": str(probe), "solver": "cvode"}},
                      "source": [{"kind": "constant", "values": {"u": 0.0}}]})
    assert caught.value.key == "fmu.p.solver"
