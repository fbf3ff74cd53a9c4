"""Paced runs on the compiled engine: the schedule holds the wall clock, every overrun is
counted, --max-overruns stops the run and keeps its record, and the timing table says so.

The FMUs are the Modelica Reference-FMUs (VanDerPol, FMI 2.0 and 3.0), which cost about a
microsecond a step, so the pacing (not the FMUs) sets the wall time.
"""

import dataclasses
import json
import mmap
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim.engine import idle_timing
from flexff.cosim.handover import Worker
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.realtime import realtime_process
from flexff.cosim.recording import load_recording
from flexff.cosim.timing import (
    PERCENTILES,
    RESOLUTION,
    US,
    Pacing,
    StepTiming,
    StreamedTiming,
)
from tests.helpers import REFERENCE_FMUS


def van_der_pol(version: int = 2) -> list[ResolvedFmu]:
    path = REFERENCE_FMUS / f"fmi{version}" / "VanDerPol.fmu"
    assert path.is_file(), f"the Reference-FMUs are missing: expected {path}"
    return [ResolvedFmu("vdp", path)]


def run(step: float, steps: int, pacing: Pacing | None, version: int = 2):
    with Master(van_der_pol(version), [], step) as master:
        return master.run({}, steps, pacing=pacing)


@pytest.mark.parametrize("factor, wall", [(1.0, 2.0), (4.0, 0.5)])
def test_pacing_holds_the_wall_clock(factor, wall):
    """2 s of simulated time at 1 ms: 2 s of wall time at F = 1, 0.5 s at F = 4 (within 1 %),
    on an absolute schedule: no step starts before it is due."""
    recording = run(1e-3, 2000, Pacing(rt_factor=factor))
    assert recording.wall_s == pytest.approx(wall, rel=0.01)
    timing = recording.timing
    assert timing.period == pytest.approx(1e-3 / factor)
    assert np.all(timing.lateness >= 0) and timing.tet.size == 2000
    table = timing.table(recording.wall_s)
    assert table["achieved_real_time_factor"] == pytest.approx(factor, rel=0.01)
    assert table["tet_us"]["p50"] <= table["tet_us"]["p99"] <= table["tet_us"]["max"]
    assert set(table["tet_us_per_fmu"]) == {"vdp"}


def test_the_idle_loop_measures_the_machine_alone():
    """The engine's paced loop with no FMU: 0.5 s at 1 kHz, on the same schedule and clock."""
    start = time.perf_counter()
    timing = idle_timing(0.5)
    wall = time.perf_counter() - start
    assert wall == pytest.approx(0.5, rel=0.02, abs=0.005)
    assert timing.tet.size == timing.lateness.size == 500 and timing.names == ()
    assert np.all(timing.lateness >= 0) and np.all(timing.tet < timing.period)
    assert timing.overruns == int(np.sum(timing.tet + timing.lateness > timing.period))
    table = timing.table(wall)
    assert table["tet_us_per_fmu"] == {} and table["lateness_us"]["max"] > 0


@pytest.mark.parametrize("version", [2, 3])
def test_paced_equals_unpaced(version):
    """Pacing changes when the steps run, never what they compute."""
    fast = run(1e-3, 300, None, version)
    paced = run(1e-3, 300, Pacing(rt_factor=10.0), version)
    for name in ("vdp.x0", "vdp.x1"):
        assert np.array_equal(fast[name], paced[name])


def test_every_overrun_is_counted():
    """A 0.1 us period is shorter than any step: every step overruns, and the count is
    exactly the steps whose TET plus lateness passed the period."""
    timing = run(1e-7, 500, Pacing()).timing
    late = timing.tet + timing.lateness > timing.period
    assert timing.overruns == int(late.sum()) == 500
    assert timing.first_overruns == tuple(range(16))


def test_max_overruns_stops_the_run_and_keeps_the_record():
    recording = run(1e-7, 500, Pacing(max_overruns=5))
    timing = recording.timing
    assert timing.stopped_at == 4 and timing.overruns == 5
    assert recording.time.size == 5 and recording["vdp.x0"].size == 5  # points 0 .. 4
    assert "stopped after 5 overruns" in timing.stop_message()
    assert timing.table(recording.wall_s)["stopped_at_s"] == pytest.approx(4e-7)


def test_grace_keeps_early_overruns_from_stopping_the_run():
    """Overruns in the first S seconds are counted, but --max-overruns counts only later ones."""
    recording = run(1e-7, 500, Pacing(max_overruns=5, grace=100e-7))
    assert recording.timing.stopped_at == 104 and recording.timing.overruns == 105


def test_the_process_setup_reports_what_it_did():
    with realtime_process(cpu=0) as report:
        assert report.cpu == 0
        assert report.sched_fifo or any("SCHED_FIFO" in w for w in report.warnings)
        assert report.memory_locked or any("memory" in w for w in report.warnings)
    with pytest.raises(ValueError, match="--cpu 4096"), realtime_process(cpu=4096):
        pass


def _resident_mib() -> float:
    status = Path("/proc/self/status").read_text()
    return int(status.split("VmRSS:")[1].split()[0]) / 1024


def test_memory_is_locked_as_it_is_touched_not_all_that_is_reserved():
    """A library's untouched reserve (as OpenBLAS's per-thread buffers) stays out of memory:
    locking all that was mapped made a paced hardware loop resident at 1.7 GB."""
    reserve = mmap.mmap(-1, 512 * 2**20)  # anonymous, read-write, never touched
    before = _resident_mib()
    with realtime_process() as report:
        if not report.memory_locked:
            pytest.skip("this process may not lock its memory")
        assert _resident_mib() - before < 100
    reserve.close()


def write_config(folder: Path, step: float, stop: float) -> Path:
    path = folder / "vdp.toml"
    path.write_text(f'[run]\nstep = {step}\nstop = {stop}\n[fmu.vdp]\n'
                    f'path = "{REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"}"\n')
    return path


def test_cli_stops_after_max_overruns_with_exit_code_3(tmp_path, capsys):
    config = write_config(tmp_path, 1e-7, 1e-4)
    code = main(["run", str(config), "-o", str(tmp_path / "out"), "--realtime",
                 "--max-overruns", "5"])
    err = capsys.readouterr().err
    assert code == 3 and err.count("\n") == 1 and "stopped after 5 overruns" in err
    assert load_recording(tmp_path / "out").time.size == 5  # the record up to there is kept
    realtime = json.loads((tmp_path / "out" / "metrics.json").read_text())["realtime"]
    assert realtime["overruns"] == 5 and realtime["stopped_at_s"] == pytest.approx(4e-7)
    assert (tmp_path / "out" / "tet.png").is_file()


def test_cli_paced_run_reports_its_timing(tmp_path, capsys):
    config = write_config(tmp_path, 1e-3, 0.2)
    assert main(["run", str(config), "-o", str(tmp_path / "out"), "--realtime",
                 "--rt-factor", "2"]) == 0
    assert "paced at 2x real time" in capsys.readouterr().out
    realtime = json.loads((tmp_path / "out" / "metrics.json").read_text())["realtime"]
    assert realtime["target_real_time_factor"] == 2.0 and realtime["steps"] == 200
    assert set(realtime["tet_us"]) == {"p50", "p99", "p99.9", "max"}
    assert main(["run", str(config), "-o", str(tmp_path / "x"), "--max-overruns", "3"]) == 2
    assert "add --realtime" in capsys.readouterr().err


class _Discard:
    def write(self, k0, time, columns):
        pass


def stream(steps: int, pacing: Pacing):
    """A paced run of VanDerPol at 1 ms whose timing is counted, not kept (as run_config's)."""
    with Master(van_der_pol(), [], 1e-3) as master:
        streamed = master.stream({}, steps, _Discard(), pacing=pacing, keep_timing=False)
        return streamed, master._times.tet.size


def _timing_values(timing: StreamedTiming) -> int:
    """How many values a streamed timing holds: histograms and trace."""
    trace = timing.trace()
    envelopes = (trace.tet, trace.late, *trace.fmu_tet)
    return (sum(h.counts.size for h in (timing.tet, timing.lateness, *timing.fmu_tet))
            + sum(e.low.size + e.high.size for e in envelopes))


def test_a_paced_streamed_runs_timing_takes_memory_flat_in_its_length():
    """3000 and 30000 steps (paced at 100x): the same values held for their timing, the
    engine's timing buffers a chunk (a second of the run) long, and every step counted."""
    held = []
    for steps in (3000, 30_000):
        streamed, buffer_rows = stream(steps, Pacing(rt_factor=100.0))
        timing = streamed.timing
        assert isinstance(timing, StreamedTiming) and buffer_rows == 1000
        assert timing.tet.size == timing.lateness.size == steps
        assert timing.trace().tet.filled <= 1000
        held.append(_timing_values(timing))
    assert held[0] == held[1]


def test_a_paced_runs_chunks_are_delivered_by_a_thread_that_keeps_its_cpus():
    """The record's Worker is made before the loop's thread takes one core: it delivers
    every chunk, in order, on the CPUs the process had, not on the loop's core."""
    allowed = os.sched_getaffinity(0)
    if len(allowed) < 2:
        pytest.skip("needs two CPUs")
    seen = []

    class Sink:
        def write(self, k0, time, columns):
            seen.append((k0, threading.current_thread().name, os.sched_getaffinity(0)))

    worker = Worker()
    try:
        with Master(van_der_pol(), [], 1e-3) as master, realtime_process(cpu=max(allowed)):
            master.stream({}, 2500, Sink(), pacing=Pacing(rt_factor=10.0), keep_timing=False,
                          worker=worker)
    finally:
        worker.join()
    assert [k0 for k0, _, _ in seen] == [0, 1000, 2000]
    assert all(name == "flexff-record" and cpus == allowed for _, name, cpus in seen)


def test_a_streamed_timing_table_agrees_with_the_exact_one(rng):
    """The same steps fed to a StreamedTiming in chunks and held in a StepTiming: the same
    table, percentiles within the histograms' resolution, maxima and counts exact; the same
    trace for tet.png, its one-step spike and overrun kept."""
    steps, pacing, period = 25_001, Pacing(), 1e-3
    tet = rng.lognormal(-11, 0.4, steps)
    tet[12_345] = 3e-3  # one overrun
    fmu_tet = tet[:, None] * rng.uniform(0.2, 0.5, (steps, 2))
    lateness = rng.lognormal(-13, 1.0, steps)
    names = ("a", "b")
    exact = StepTiming(period, names, tet, fmu_tet, lateness, pacing, 1, 0, (12_345,), None)
    streamed = StreamedTiming.counting(period, names, steps, pacing)
    for k0 in range(0, steps, 777):
        streamed.add(k0, tet[k0:k0 + 777], fmu_tet[k0:k0 + 777], lateness[k0:k0 + 777])
    streamed = dataclasses.replace(streamed, overruns=1, first_overruns=(12_345,))
    want, got = exact.table(25.0), streamed.table(25.0)
    assert got.pop("percentile_resolution") == RESOLUTION and "percentile_resolution" not in want

    def close(a, b, path=("",)):
        if isinstance(a, dict):
            assert a.keys() == b.keys(), path
            for key in a:
                close(a[key], b[key], (*path, key))
        elif path[-1] in (*PERCENTILES, "tet_over_period_p99"):
            assert b == pytest.approx(a, rel=RESOLUTION), path
        else:
            assert b == a, path

    close(want, got)
    assert got["tet_us"]["max"] == 3e-3 * US and got["lateness_us"]["max"] == lateness.max() * US
    for a, b in ((exact.trace().tet, streamed.trace().tet), (exact.trace().late,
                                                              streamed.trace().late)):
        assert np.array_equal(a.low, b.low) and np.array_equal(a.high, b.high)
    t, late = streamed.trace().late.peaks(period)
    assert t[late > period] == pytest.approx([12_345 // 26 * 26 * period])


def test_a_paced_streamed_run_stopped_by_its_overruns_reports_the_stopped_step():
    """Every step overruns a 0.1 us period; after 1.5 s of grace the run stops at step 1504,
    in its second chunk: the stop message gives that step's own TET and lateness (its TET
    plus lateness lies within its block of the trace)."""
    streamed, _ = stream(3000, Pacing(rt_factor=1e4, max_overruns=5, grace=1.5))
    timing = streamed.timing
    assert timing.stopped_at == 1504 and streamed.points == 1505
    tet, late = timing.stopped_step
    envelope = timing.trace().late
    block = 1504 // envelope.size
    assert envelope.low[block] <= tet + late <= envelope.high[block]
    assert f"took {tet * US:.1f} us and started {late * US:.1f} us late" in \
        timing.stop_message()
    assert timing.table(streamed.wall_s)["stopped_at_s"] == pytest.approx(1.504)
