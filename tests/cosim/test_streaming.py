"""A run's whole cost: what a plain run imports, the record streamed to disk chunk by chunk (a
killed run keeps it, it equals the in-memory record bit for bit), decimated plots, and the
record's options (`[record] csv`, `plot`, `every`)."""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

from flexff import api, results
from flexff.cli import main
from flexff.cosim.config import parse_config
from flexff.cosim.decimate import Envelope, Strided
from flexff.cosim.handover import ChunkBuffers, Handover, Worker
from flexff.cosim.plots import RunPlots
from flexff.cosim.recording import (
    CSV_NAME,
    PARQUET_NAME,
    PARTS_NAME,
    chunk_rows,
    load_recording,
)
from flexff.cosim.timing import RESOLUTION, Histogram, Pacing
from flexff.fmu.errors import InputError
from tests.helpers import REFERENCE_FMUS, REPOSITORY

VDP = REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"
# what a run of third-party FMUs must not load (the learned feedforward's, the built-in FMUs',
# the references' and the plots' libraries)
UNUSED = ("torch", "onnxruntime", "onnx", "casadi", "scipy", "matplotlib",
          "flexff.learning.dataset", "flexff.controllers", "flexff.fmu.build")


def vdp_config(stop: float, record: str = "") -> str:
    return textwrap.dedent(f"""\
        [fmu.vdp]
        path = "{VDP.as_posix()}"

        [run]
        step = 1e-3
        stop = {stop}
        """) + record


def _python(code: str, *args: str, **kwargs: object) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(REPOSITORY)}
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          env=env, check=True, timeout=120, **kwargs)  # type: ignore[call-overload]


def test_a_plain_run_imports_only_what_it_uses(tmp_path):
    (tmp_path / "run.toml").write_text(vdp_config(1.0))
    code = ("import sys; from flexff.cli import main; code = main(['run', sys.argv[1], '-o', "
            "sys.argv[2]]); print(code, sorted(m for m in sys.modules if m.split('.')[0] in "
            "('torch', 'onnxruntime', 'onnx', 'casadi', 'scipy', 'matplotlib') or m in "
            f"{UNUSED!r}))")
    out = _python(code, str(tmp_path / "run.toml"), str(tmp_path / "out")).stdout
    assert out.split("\n")[-2] == "0 []", out
    assert (tmp_path / "out" / PARQUET_NAME).is_file()
    assert not (tmp_path / "out" / "signals.png").exists()  # a plain run plots when asked


def test_the_command_line_starts_without_numpy():
    code = ("import sys; from flexff.cli import build_parser; build_parser(); "
            "print('numpy' in sys.modules)")
    assert _python(code).stdout.strip() == "False"


def test_a_killed_run_keeps_its_record_up_to_the_last_chunk(tmp_path):
    """SIGKILL in the middle of a long run: the chunks written so far read back, and equal
    the same points of a run held in memory."""
    (tmp_path / "run.toml").write_text(vdp_config(1e5))
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(REPOSITORY)}
    process = subprocess.Popen([sys.executable, "-m", "flexff", "run", str(tmp_path / "run.toml"),
                                "-o", str(out)], env=env, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while len(list((out / PARTS_NAME).glob("part-*.parquet"))) < 3:
            assert time.monotonic() < deadline and process.poll() is None
            time.sleep(0.01)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    kept = load_recording(out)
    points, rows = kept.time.size, chunk_rows(3)  # time, x0, x1
    assert points >= 3 * rows and points % rows == 0
    assert not (out / PARQUET_NAME).exists()
    whole = api.simulate(parse_config(vdp_config((points - 1) * 1e-3)))
    for name, values in whole.signals.items():
        assert kept[name].tobytes() == values.tobytes(), name
    assert kept.time.tobytes() == whole.time.tobytes()


def test_streamed_and_in_memory_records_are_equal_bit_for_bit(tmp_path, monkeypatch):
    monkeypatch.setattr("flexff.cosim.recording.CHUNK_BYTES", 64_000 * 8 * 3)
    config = parse_config(vdp_config(150.0, '[record]\ncsv = true\nplot = true\n'))
    metrics = api.run(config, tmp_path)
    streamed, in_memory = load_recording(tmp_path), api.simulate(config)
    assert streamed.time.size == 150_001 > 2 * chunk_rows(3)
    assert list(streamed.signals) == list(in_memory.signals)
    assert streamed.time.tobytes() == in_memory.time.tobytes()
    for name, values in in_memory.signals.items():
        assert streamed[name].tobytes() == values.tobytes(), name
    table = np.loadtxt(tmp_path / CSV_NAME, delimiter=",", skiprows=1)
    assert np.array_equal(table[:, 1], in_memory.signals["vdp.x0"])
    assert (tmp_path / "signals.png").is_file() and not (tmp_path / PARTS_NAME).exists()
    assert metrics["realtime"]["steps"] == 150_000


def test_record_every_nth_point(tmp_path):
    config = parse_config(vdp_config(2.0, "[record]\nevery = 7\n"))
    api.run(config, tmp_path)
    kept, whole = load_recording(tmp_path), api.simulate(config)
    assert np.array_equal(kept.time, whole.time[::7])
    assert np.array_equal(kept["vdp.x0"], whole["vdp.x0"][::7])
    assert not (tmp_path / CSV_NAME).exists()  # CSV only when asked
    with pytest.raises(InputError, match=r"record\.every"):
        parse_config(vdp_config(2.0, "[record]\nevery = 0\n"))


@pytest.mark.parametrize("chunk", [777, 10**6])
def test_decimated_plots_keep_a_one_sample_spike(chunk):
    points, spike = 1_000_003, 500_123
    values = np.zeros(points)
    values[spike] = 5.0
    values[spike + 1000] = -3.0
    envelope, plots = Envelope(points), RunPlots(["a.v"], points, 1e-3)
    for k0 in range(0, points, chunk):
        envelope.add(k0, values[k0:k0 + chunk])
        plots.add(k0, {"a.v": values[k0:k0 + chunk]})
    t, line = envelope.line(1e-3)
    assert line.size <= 2 * 1000 + 2 and line.max() == 5.0 and line.min() == -3.0
    assert t[np.argmax(line)] == pytest.approx(spike * 1e-3, abs=envelope.size * 1e-3)
    assert np.array_equal(plots._line("a.v")[1], line)


def test_strided_keeps_every_nth_point():
    strided = Strided(100, most=10)
    for k0 in range(0, 100, 13):
        strided.add(k0, np.arange(k0, min(k0 + 13, 100)))
    assert np.array_equal(strided.values(), np.arange(0, 100, 10))


def test_histogram_percentiles_are_within_its_resolution(rng):
    values = rng.lognormal(-13, 1.0, 100_001)
    histogram = Histogram()
    for chunk in np.array_split(values, 7):
        histogram.add(chunk)
    for q in (50.0, 99.0, 99.9):
        assert histogram.percentile(q) == pytest.approx(np.percentile(values, q),
                                                        rel=RESOLUTION)
    assert histogram.max == values.max() and histogram.size == values.size


def test_results_load_and_export(tmp_path):
    """flexff.results.load reads a run folder (api.read is the same function); `flexff results
    export` writes the CSV copy of a record; a folder without one is an input error."""
    api.run(parse_config(vdp_config(1.0)), tmp_path / "out")
    result = results.load(tmp_path / "out")
    assert api.read is results.load and result.metrics["realtime"]["steps"] == 1000
    assert result.configuration["run"]["stop"] == 1.0
    assert main(["results", "export", str(tmp_path / "out")]) == 0
    table = np.loadtxt(tmp_path / "out" / CSV_NAME, delimiter=",", skiprows=1)
    assert np.array_equal(table[:, 1], result.recording["vdp.x0"])
    assert main(["results", "export", str(tmp_path)]) == 2
    with pytest.raises(InputError, match="no such folder"):
        results.load(tmp_path / "missing")


def test_a_handover_delivers_in_order_in_its_workers_thread_and_raises_at_check():
    """Two sets of buffers take turns: each is filled again only once delivered. A delivery
    that raises stops the later ones, and check() raises it in the loop's thread."""
    seen, threads = [], set()
    sets = [ChunkBuffers.allocate(10, 1, 0, None, touch=True) for _ in range(2)]

    def deliver(buffers, base, end):
        threads.add(threading.current_thread().name)
        if base == 20:
            raise OSError("disk full")
        seen.append((base, end, float(buffers.record[0, 0])))

    worker = Worker()
    handover = Handover(sets, deliver, worker)
    for base in range(0, 40, 10):
        handover.current.record[0, 0] = base
        handover.hand(base, base + 10)
    handover.wait()
    with pytest.raises(OSError, match="disk full"):
        handover.check()
    worker.join()
    assert seen == [(0, 10, 0.0), (10, 20, 10.0)] and threads == {"flexff-record"}
    assert not worker.thread.is_alive()
    inline = Handover(sets[:1], deliver, None)
    assert inline.hand(40, 50) is sets[0] and seen[-1][:2] == (40, 50)
    with pytest.raises(ValueError, match="two with a worker"):
        Handover(sets, deliver, None)


def test_a_paced_run_streams_its_record(tmp_path):
    config = parse_config(vdp_config(0.3))
    realtime = api.run(config, tmp_path, pacing=Pacing())["realtime"]
    streamed, in_memory = load_recording(tmp_path), api.simulate(config)
    for name, values in in_memory.signals.items():
        assert streamed[name].tobytes() == values.tobytes(), name
    assert (tmp_path / "tet.png").is_file()
    # its timing counted in histograms, as an unpaced streamed run's, the lateness too
    assert realtime["percentile_resolution"] == RESOLUTION and realtime["steps"] == 300
    assert 0 <= realtime["lateness_us"]["p99"] <= realtime["lateness_us"]["max"]
