"""A run that stops early keeps what it recorded, and says so: an interrupt before the first
chunk keeps the points made (isolated or not, and also where Python sees the interrupt inside
an FMU's logger), a full disk names the file and what was kept, and a killed run's folder is
marked partial (run.json, results.load, flexff results export)."""

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from flexff import results
from flexff.cli import main
from flexff.cosim import master as master_module
from flexff.cosim.fmu_log import FmuLog
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.recording import PARQUET_NAME, PARTS_NAME, load_recording
from flexff.cosim.run import run_config
from tests.chatty_fmu import build_chatty
from tests.cosim.test_run_signals import _wait_for
from tests.cosim.test_streaming import vdp_config
from tests.helpers import REPOSITORY
from tests.probe_fmu import build_probe

INTERRUPT_AT = 1_500  # the step during which Ctrl-C comes (the first chunk holds far more)
KEPT = 2_000  # the points recorded when the master next looks: a whole progress step


@pytest.fixture(scope="module")
def chatty(tmp_path_factory):
    return build_chatty(tmp_path_factory.mktemp("chatty"))


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return build_probe(tmp_path_factory.mktemp("probe"), startTime=0.0, stopTime=1.0,
                       stepSize=1e-3)


class InterruptingBar:
    """A progress bar that sends Ctrl-C to its own process once INTERRUPT_AT steps are done
    (the master calls it between the engine's calls, where Python runs signal handlers)."""

    def __init__(self, steps: int, shown: bool) -> None:
        self.done = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def update(self, n: int) -> None:
        self.done += n
        if self.done >= INTERRUPT_AT:
            os.kill(os.getpid(), signal.SIGINT)


class ListSink:
    def __init__(self) -> None:
        self.times: list[np.ndarray] = []

    def write(self, k0, time, columns) -> None:
        self.times.append(time)


@pytest.mark.parametrize("isolate", [False, True])
def test_an_interrupt_before_the_first_chunk_hands_over_the_points_made(probe, monkeypatch,
                                                                        isolate):
    monkeypatch.setattr(master_module, "_progress_bar", InterruptingBar)
    sink = ListSink()
    with Master([ResolvedFmu("p", probe, isolate=isolate)], ["u"], 1e-3) as master:
        with pytest.raises(KeyboardInterrupt):
            master.stream({"u": 1.0}, 100_000, sink, ["p.y"], keep_timing=False)
    kept = np.concatenate(sink.times)
    assert kept.size == KEPT and kept[-1] == pytest.approx((KEPT - 1) * 1e-3)


def test_an_interrupt_seen_in_an_fmus_logger_stops_the_run(chatty, tmp_path, monkeypatch):
    """Python runs the handler in the next Python code, here the FMU's logger, called from C:
    its KeyboardInterrupt used to be dropped there (ctypes printed it) and the run went on."""
    write = FmuLog.write

    def interrupting(self, line):
        write(self, line)
        if line.startswith(f"chatty: [OK] step {INTERRUPT_AT} "):
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(FmuLog, "write", interrupting)
    config = tmp_path / "chatty.toml"
    config.write_text(f'[run]\nstep = 0.001\nstop = 100.0\n[fmu.chatty]\npath = "{chatty}"\n')
    with pytest.raises(KeyboardInterrupt) as interrupted:
        run_config(config, tmp_path / "out")
    assert str(interrupted.value) == (f"the record up to t = 1.999 s ({KEPT} points) is in "
                                      f"{tmp_path / 'out'}")
    assert load_recording(tmp_path / "out").time.size == KEPT
    recorded = json.loads((tmp_path / "out" / "run.json").read_text())["recorded"]
    assert (recorded["points"], recorded["complete"]) == (KEPT, False)


def test_a_full_disk_names_the_file_and_what_was_kept(tmp_path, monkeypatch, capsys):
    """The third chunk does not fit (pyarrow's error names no file): the two before are kept as
    written, unjoined (joining takes as much space again), and run.json says so."""
    import pyarrow.parquet as pq

    monkeypatch.setattr("flexff.cosim.recording.CHUNK_BYTES", 16_000)  # 1000 points a chunk
    write_table, calls = pq.write_table, []

    def filling(*args, **kwargs):
        calls.append(args[1])
        if len(calls) == 3:
            raise OSError(28, "Error writing bytes to file. Detail: [errno 28] No space left "
                              "on device")
        write_table(*args, **kwargs)

    monkeypatch.setattr(pq, "write_table", filling)
    (tmp_path / "run.toml").write_text(vdp_config(10.0, '[record]\nsignals = ["vdp.x0"]\n'))
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "run.toml"), "-o", str(out)]) == 1
    parts = out / PARTS_NAME
    assert capsys.readouterr().err == (
        f"flexff: error: {parts / 'part-000002.parquet'}: No space left on device; the record "
        f"up to t = 1.999 s (2000 points) is in {parts}\n")
    assert load_recording(out).time.size == 2000 and not (out / PARQUET_NAME).exists()
    recorded = json.loads((out / "run.json").read_text())["recorded"]
    assert (recorded["points"], recorded["complete"]) == (2000, False)


def test_a_disk_full_at_the_join_keeps_the_whole_record_unjoined(tmp_path, monkeypatch, capsys):
    import pyarrow.parquet as pq

    monkeypatch.setattr("flexff.cosim.recording.CHUNK_BYTES", 16_000)  # 1000 points a chunk

    def full(*args, **kwargs):
        raise OSError(28, "Error writing bytes to file. Detail: [errno 28] No space left on "
                          "device")

    monkeypatch.setattr(pq, "ParquetWriter", full)
    (tmp_path / "run.toml").write_text(vdp_config(3.0, '[record]\nsignals = ["vdp.x0"]\n'))
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "run.toml"), "-o", str(out)]) == 1
    assert capsys.readouterr().err == (
        f"flexff: error: {out / PARQUET_NAME}: No space left on device; the record up to t = 3 s "
        f"(3001 points) is in {out / PARTS_NAME}\n")
    assert load_recording(out).time.size == 3001 and not (out / PARQUET_NAME).exists()
    assert results.load(out).partial is None  # whole, if not joined
    assert json.loads((out / "run.json").read_text())["recorded"]["complete"] is True


def test_a_killed_run_is_marked_partial_when_read_and_exported(tmp_path, capsys):
    (tmp_path / "run.toml").write_text(vdp_config(1e5))
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(REPOSITORY)}
    process = subprocess.Popen([sys.executable, "-m", "flexff", "run",
                                str(tmp_path / "run.toml"), "-o", str(out)], env=env)
    try:
        _wait_for(lambda: any((out / PARTS_NAME).glob("part-*.parquet")), process)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    why = ("the run did not end normally (it was killed, or its disk was full): its record is "
           "the chunks in signals.parts/ up to the last one written")
    assert results.load(out).partial == why
    assert json.loads((out / "run.json").read_text())["recorded"]["complete"] is False
    assert main(["results", "export", str(out)]) == 0
    assert capsys.readouterr().err == f"flexff: warning: {out}: a partial record: {why}\n"


def test_a_finished_run_is_not_partial(tmp_path, capsys):
    (tmp_path / "run.toml").write_text(vdp_config(1.0))
    assert main(["run", str(tmp_path / "run.toml"), "-o", str(tmp_path / "out")]) == 0
    assert results.load(tmp_path / "out").partial is None
    capsys.readouterr()
    assert main(["results", "export", str(tmp_path / "out")]) == 0
    assert capsys.readouterr().err == ""
