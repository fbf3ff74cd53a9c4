"""The sandbox of an isolated FMU (cosim.sandbox, cosim/c/sandbox.c).

- the probe FMU (tests/probe_fmu.c) trying to open a network socket, write outside its
  scratch folder, allocate 10 GB, start processes or run a program is stopped: `flexff run`
  exits 1 with one line naming the attempt, keeps the record up to it, and nothing is written;
- its honest twins (nothing tried; a file written and read back in its working directory) and
  a Reference-FMU system give the in-process records bit for bit, sandboxed;
- the child's replies are JSON with a bounded length: a child that claims a longer message or
  sends one that is not the protocol's is stopped and named;
- the keys (sandbox, sandbox_memory, sandbox_cpu, --no-sandbox) are checked like any other.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim.child_output import OutputRelay
from flexff.cosim.config import parse_config, with_isolation
from flexff.cosim.config_error import ConfigError
from flexff.cosim.isolation import LENGTH, MESSAGE_LIMIT, IsolatedInstance
from flexff.cosim.master import CosimError
from flexff.cosim.recording import load_recording
from flexff.cosim.run import simulate_config
from flexff.cosim.sandbox import LAYERS, Sandbox
from flexff.fmu.importer import FmuError, read_fmu
from tests.helpers import REFERENCE_FMUS
from tests.probe_fmu import ATTEMPTS, ESCAPE, build_probe

STEP = 0.1
STOPPED = {
    "socket": "it tried to open a network socket (address family 2)",
    "escape": f"it tried to write to {ESCAPE}, outside its scratch folder",
    "allocate": "it tried to allocate 10240 MB, over its memory limit of 4096 MB",
    "processes": "it tried to start a process",
    "program": "it tried to start a process",
}


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return build_probe(tmp_path_factory.mktemp("probe"), startTime=0.0, stopTime=1.0,
                       stepSize=STEP)


@pytest.fixture(scope="module")
def held(probe):
    """The sandbox's layers that hold on this machine."""
    with IsolatedInstance(read_fmu(probe), "p") as instance:
        return instance.held


def probe_toml(probe, attempt, isolate=True, extra=""):
    return (f'[run]\nstep = {STEP}\nstop = 1.0\n[fmu.p]\npath = "{probe}"\n'
            f'isolate = {str(isolate).lower()}\n{extra}\n'
            f'parameters = {{ attempt = {ATTEMPTS.get(attempt, 0)}, attempt_at = 0.2 }}\n'
            f'[[source]]\nkind = "constant"\nvalues = {{ u = 1.0 }}\n')


def probe_config(probe, attempt, isolate=True, extra=""):
    return parse_config(probe_toml(probe, attempt, isolate, extra))


def test_the_sandbox_holds_its_layers_here(held):
    """On Linux x86_64 with Landlock and user namespaces (this machine, CI), every layer."""
    needed = {"no new privileges", "memory and CPU limits", "seccomp",
              "Landlock: writes only to the scratch folder"}
    assert needed <= set(held), held
    assert set(held) <= set(LAYERS)


@pytest.mark.parametrize("attempt", sorted(STOPPED))
def test_an_attempt_is_stopped_with_one_line_naming_it(tmp_path, probe, held, attempt,
                                                       capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = tmp_path / "probe.toml"
    config.write_text(probe_toml(probe, attempt))
    assert main(["run", str(config), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert (f"p: the step at t = 0.2 s failed: the sandbox stopped its process: "
            f"{STOPPED[attempt]}") in err
    recording = load_recording(tmp_path / "out")
    assert np.allclose(recording.time, np.arange(3) * STEP)  # up to t = 0.2 s
    assert not Path(ESCAPE).exists()


def test_the_memory_limit_is_the_configured_one(tmp_path, probe, held):
    config = probe_config(probe, "allocate", extra="sandbox_memory = 512")
    with pytest.raises(CosimError, match="it tried to allocate 10240 MB, over its memory limit "
                                       "of 512 MB"):
        simulate_config(config, tmp_path / "out")


@pytest.mark.parametrize("attempt", ["nothing", "scratch"])
def test_honest_twins_equal_the_in_process_run(tmp_path, probe, held, attempt, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the in-process probe writes its note here
    inside = simulate_config(probe_config(probe, attempt, isolate=False))
    alone = simulate_config(probe_config(probe, attempt))
    assert inside.signals.keys() == alone.signals.keys()
    for name in inside.signals:
        assert np.array_equal(inside[name], alone[name]), name
    assert inside.time[-1] == pytest.approx(1.0)


def test_a_reference_fmu_system_is_bit_equal_sandboxed_and_not():
    config = parse_config({
        "run": {"step": 0.01, "stop": 1.0},
        "fmu": {"vdp": {"path": str(REFERENCE_FMUS / "fmi3" / "VanDerPol.fmu")},
                "ft": {"path": str(REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"),
                       "unconnected": "start"}},
        "connection": [{"from": "vdp.x0", "to": "ft.Float64_continuous_input"}]})
    inside = simulate_config(config)
    for sandboxed in (True, False):
        alone = simulate_config(with_isolation(config, True, None, sandboxed))
        for name in inside.signals:
            assert np.array_equal(inside[name], alone[name]), (sandboxed, name)


def _fake_child(tmp_path, reply: bytes) -> IsolatedInstance:
    """An IsolatedInstance whose child (a sleeping process) has sent `reply`."""
    instance = IsolatedInstance.__new__(IsolatedInstance)
    sent = tmp_path / "sent"  # a file: the reply may be longer than a pipe holds
    sent.write_bytes(reply)
    read = os.open(sent, os.O_RDONLY)
    instance.name, instance.timeout, instance._ack, instance._timed_out = "p", 5.0, read, False
    instance._broken = False
    instance._process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    instance._output = OutputRelay(os.open(os.devnull, os.O_RDONLY), "p")
    return instance


@pytest.mark.parametrize("reply, why", [
    (LENGTH.pack(MESSAGE_LIMIT + 1), f"a message of {MESSAGE_LIMIT + 1} bytes"),
    (LENGTH.pack(9) + b"cos\nsystem", "a message that is not the protocol's"),
    (LENGTH.pack(4) + b"[1 ]", "a message that is not the protocol's"),
    (LENGTH.pack(200_000) + b"[" * 200_000, "a message that is not the protocol's"),
], ids=["too long", "pickle", "wrong shape", "nested too deep"])
def test_a_child_that_breaks_the_protocol_is_stopped(tmp_path, reply, why):
    instance = _fake_child(tmp_path, reply)
    with pytest.raises(FmuError, match=f"p: get failed: its process sent {why}"):
        instance._response("get")
    assert instance._process.poll() is not None  # stopped
    os.close(instance._ack)


@pytest.mark.parametrize("fmu, message", [
    ('isolate = true\nsandbox = 1', "fmu.p.sandbox: expected true or false"),
    ('sandbox_memory = 100', "fmu.p.sandbox_memory: applies to an FMU in its own process"),
    ('isolate = true\nsandbox_memory = 0', "fmu.p.sandbox_memory"),
    ('isolate = true\nsandbox_cpu = -1', "fmu.p.sandbox_cpu"),
    ('isolate = true\nsandbox = false\nsandbox_memory = 100',
     "fmu.p.sandbox_memory: is a limit of the sandbox, which sandbox = false turns off"),
    ('isolate = true\nsandbox_scratch = 0', "fmu.p.sandbox_scratch"),
    ('isolate = true\nsandbox_read = "/etc"', "fmu.p.sandbox_read: expected a list of paths"),
    ('isolate = true\nsandbox_read = ["no/such/folder"]',
     "fmu.p.sandbox_read: no such file or folder: no/such/folder"),
])
def test_bad_sandbox_keys_name_their_key(probe, fmu, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        parse_config(f'[run]\nstep = 0.1\nstop = 1.0\n[fmu.p]\npath = "{probe}"\n{fmu}\n'
                     f'[[source]]\nkind = "constant"\nvalues = {{ u = 1.0 }}\n')


def test_the_keys_reach_the_fmu_and_survive_expansion(probe):
    keys = ('sandbox_memory = 512\nsandbox_cpu = 30\nsandbox_scratch = 64\n'
            f'sandbox_read = ["{probe}"]')
    config = probe_config(probe, "nothing", extra=keys)
    limits = Sandbox(512.0, 30.0, 64.0, read=(probe,))
    assert config.fmus[0].sandbox == limits
    assert with_isolation(config, True, None).fmus[0].sandbox == limits
    assert with_isolation(config, True, None, False).fmus[0].sandbox is None
    assert probe_config(probe, "nothing", extra="sandbox = false").fmus[0].sandbox is None
