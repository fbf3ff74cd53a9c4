"""Signals end a run cleanly: SIGTERM (as Ctrl-C) stops `flexff run` with exit code 143 and one
line saying what the record kept, the record joined and described in run.json, and no
temporary folder left behind, even while an FMU hangs in its call (cosim.watchdog); an isolated
FMU dies with its master, even a master killed with SIGKILL while the FMU hangs."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from flexff.cosim.recording import PARQUET_NAME, PARTS_NAME, load_recording
from flexff.cosim.watchdog import GRACE_S
from tests.cosim.test_streaming import vdp_config
from tests.helpers import REPOSITORY, assert_descendants_end_with
from tests.probe_fmu import build_probe


def _start(tmp_path, config, *options):
    """`python -m flexff run` on `config`, with a TMPDIR of the test's own."""
    (tmp_path / "tmp").mkdir()
    env = {**os.environ, "PYTHONPATH": str(REPOSITORY), "TMPDIR": str(tmp_path / "tmp")}
    return subprocess.Popen([sys.executable, "-m", "flexff", "run", str(config), "-o",
                             str(tmp_path / "out"), *options],
                            env=env, stderr=subprocess.PIPE, text=True)


def _wait_for(condition, process, seconds=60.0):
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.01)


def test_sigterm_ends_a_run_cleanly(tmp_path):
    (tmp_path / "run.toml").write_text(vdp_config(1e5))
    process = _start(tmp_path, tmp_path / "run.toml")
    parts = tmp_path / "out" / PARTS_NAME
    try:
        _wait_for(lambda: len(list(parts.glob("part-*.parquet"))) >= 2, process)
        assert any((tmp_path / "tmp").iterdir())  # the run's temporary folders exist
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 143, err
    kept = load_recording(tmp_path / "out")
    assert err == (f"flexff: terminated; the record up to t = {kept.time[-1]:.9g} s "
                   f"({kept.time.size} points) is in {tmp_path / 'out'}\n")
    assert (tmp_path / "out" / PARQUET_NAME).is_file() and not parts.exists()
    recorded = json.loads((tmp_path / "out" / "run.json").read_text())["recorded"]
    assert (recorded["points"], recorded["complete"]) == (kept.time.size, False)
    assert list((tmp_path / "tmp").iterdir()) == []


def hanging(tmp_path, isolate):
    """A run whose probe FMU hangs in fmi2DoStep at t = 0.2 s (in its own process or not)."""
    probe = build_probe(tmp_path / "probe", startTime=0.0, stopTime=1.0, stepSize=0.1)
    config = tmp_path / "hang.toml"
    config.write_text(f'[run]\nstep = 0.1\nstop = 1.0\n[fmu.p]\npath = "{probe}"\n'
                      f'isolate = {str(isolate).lower()}\nparameters = {{ hang_at = 0.2 }}\n'
                      f'[[source]]\nkind = "constant"\nvalues = {{ u = 1.0 }}\n')
    return config


@pytest.mark.parametrize("isolate", [False, True])
def test_sigterm_ends_a_run_whose_fmu_hangs(tmp_path, isolate):
    process = _start(tmp_path, hanging(tmp_path, isolate))
    try:
        _wait_for(lambda: (tmp_path / "out" / PARTS_NAME).is_dir(), process)
        time.sleep(1.0)  # into the hang
        process.send_signal(signal.SIGTERM)
        began = time.monotonic()
        _, err = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 143, err
    assert time.monotonic() - began < GRACE_S + 10
    assert err.splitlines()[-1] == (
        f"flexff: terminated; an FMU did not return from its call within {GRACE_S:g} s, so the "
        f"run was ended there: the record up to its last chunk is in "
        f"{tmp_path / 'out' / PARTS_NAME}")
    assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_an_isolated_fmu_dies_with_its_killed_master(tmp_path):
    process = _start(tmp_path, hanging(tmp_path, isolate=True))
    assert_descendants_end_with(process, lambda started: any(
        "flexff.cosim.isolation" in " ".join(child.cmdline()) for child in started),
        settle_s=1.0, within_s=10.0)  # 1 s into the hang

