"""FMUs in their own process (cosim.isolation): `isolate = true` on an [fmu.NAME] and `flexff
run --isolate`.

- an isolated Reference-FMU system (FMI 3.0 VanDerPol into FMI 2.0 Feedthrough, with a gain and
  offset, an Int32 start value and outputs of every type recorded) gives the in-process run's
  record bit for bit;
- the probe FMU (tests/probe_fmu.c) crashing with SIGSEGV in fmi2DoStep at a given time, or
  hanging there past --step-timeout, ends `flexff run` with exit code 1 and one line naming the
  FMU, the call, the time (and the signal or the timeout), with the record up to the last
  completed point written;
- the keys are checked like any other.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim.config import parse_config, with_isolation
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import load_recording
from flexff.cosim.run import simulate_config
from tests.helpers import REFERENCE_FMUS
from tests.probe_fmu import build_probe

STEP = 0.1


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return build_probe(tmp_path_factory.mktemp("probe"), startTime=0.0, stopTime=1.0,
                       stepSize=STEP)


def probe_toml(tmp_path, probe, parameters, run=""):
    path = tmp_path / "probe.toml"
    path.write_text(f'[run]\nstep = {STEP}\nstop = 1.0\n{run}\n'
                    f'[fmu.p]\npath = "{probe}"\nisolate = true\n'
                    f'parameters = {{ {", ".join(f"{k} = {v}" for k, v in parameters.items())} }}'
                    f'\n[[source]]\nkind = "constant"\nvalues = {{ u = 1.0 }}\n')
    return path


def test_an_isolated_system_equals_the_in_process_one():
    config = parse_config({
        "run": {"step": 0.01, "stop": 2.0},
        "fmu": {"vdp": {"path": str(REFERENCE_FMUS / "fmi3" / "VanDerPol.fmu")},
                "ft": {"path": str(REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"),
                       "unconnected": "start", "parameters": {"Int32_input": 3}}},
        "connection": [{"from": "vdp.x0", "to": "ft.Float64_continuous_input", "gain": 2.0,
                        "offset": 0.5}]})
    inside = simulate_config(config)
    alone = simulate_config(with_isolation(config, True, None))
    assert inside.signals.keys() == alone.signals.keys()
    assert np.array_equal(inside.time, alone.time)
    for name in inside.signals:
        assert np.array_equal(inside[name], alone[name]), name
    assert np.any(np.diff(alone["vdp.x0"]) != 0)
    assert np.all(alone["ft.Int32_output"] == 3), "values of other types through the child"


def test_a_crash_in_do_step_ends_the_run_with_the_record_up_to_it(tmp_path, probe, capsys):
    config = probe_toml(tmp_path, probe, {"crash_at": 0.35})
    assert main(["run", str(config), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "p: the step at t = 0.4 s failed: its process ended with SIGSEGV" in err
    recording = load_recording(tmp_path / "out")
    assert np.allclose(recording.time, np.arange(5) * STEP)  # points 0 .. 4: t = 0.4 recorded
    assert np.array_equal(recording["p.y"], np.full(5, 2.0))
    assert (tmp_path / "out" / "run.json").is_file()


def test_a_hang_past_the_step_timeout_ends_the_run(tmp_path, probe, capsys):
    config = probe_toml(tmp_path, probe, {"hang_at": 0.2})
    began = time.monotonic()
    assert main(["run", str(config), "-o", str(tmp_path / "out"), "--step-timeout", "0.5"]) == 1
    assert time.monotonic() - began < 30
    err = capsys.readouterr().err.strip()
    assert "p: the step at t = 0.2 s did not end within the step timeout of 0.5 s" in err
    assert np.allclose(load_recording(tmp_path / "out").time, np.arange(3) * STEP)


def test_run_isolate_puts_every_fmu_in_its_own_process(tmp_path, probe, capsys):
    config = tmp_path / "plain.toml"
    config.write_text(f'[run]\nstep = {STEP}\nstop = 1.0\n[fmu.p]\npath = "{probe}"\n'
                      f'parameters = {{ crash_at = 0.5 }}\n'
                      f'[[source]]\nkind = "constant"\nvalues = {{ u = 1.0 }}\n')
    assert main(["run", str(config), "-o", str(tmp_path / "out"), "--isolate"]) == 1
    assert "SIGSEGV" in capsys.readouterr().err


@pytest.mark.parametrize("run, fmu, key", [
    ({"step_timeout": 1.0}, {}, "run.step_timeout"),  # no FMU in its own process
    ({"step_timeout": 0.0}, {"isolate": True}, "run.step_timeout"),
    ({}, {"isolate": "yes"}, "fmu.p.isolate"),
])
def test_bad_isolation_keys_name_their_key(probe, run, fmu, key):
    with pytest.raises(ConfigError) as caught:
        parse_config({"run": {"step": STEP, **run}, "fmu": {"p": {"path": str(probe), **fmu}},
                      "source": [{"kind": "constant", "values": {"u": 1.0}}]})
    assert caught.value.key == key
