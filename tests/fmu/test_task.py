"""A network in its own task (c/wrapper_task.c): the call started at call point k is used from
k + PERIOD, extrapolated one period further, whatever the timing: paced and unpaced runs, fmpy
and libcosim give the same outputs bit for bit; a network slower than its deadline is counted
(and stops a paced run at --max-overruns); a state saved while a call is pending continues
exactly."""

import ctypes
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from fmpy.fmi2 import fmi2Error

from flexff.bench import slow_graph
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.timing import Pacing
from flexff.fmu.onnx_fmu import onnx_system
from flexff.fmu.validation import validate_fmu
from tests.fmu.test_network import INPUTS, PERIOD, STEPS, H, network_system, running_sum_graph
from tests.fmu_toys import LoggedSlave, build_toy, status_of
from tests.runners import run_fmu, run_fmu_libcosim


def task_scheme(calls: np.ndarray, steps: int) -> np.ndarray:
    """The task scheme by hand, from the results of the calls at 0, PERIOD, 2 PERIOD, ...: zero
    until the first result; then the call of point (j - 1) PERIOD is the latest result at
    [j PERIOD, (j + 1) PERIOD), extrapolated from it and the one before by
    (phase + PERIOD) / PERIOD."""
    out = np.zeros((steps, calls.shape[1]))
    for k in range(PERIOD, steps):
        j, phase = divmod(k, PERIOD)
        last, before = calls[max(j - 1, 0)], calls[max(j - 2, 0)]
        out[k] = last + (phase + PERIOD) / PERIOD * (last - before)
    return out


def task_outputs(u: np.ndarray) -> np.ndarray:
    """The running-sum toy (y = r + u, the network fed 2 u) under the task scheme."""
    return task_scheme(np.cumsum(2 * u[::PERIOD], axis=0), len(u)) + u


@pytest.fixture(scope="module")
def task_fmu(tmp_path_factory):
    graph = running_sum_graph(tmp_path_factory.mktemp("graph") / "running_sum.onnx")
    system = network_system(graph, name="toy_task")
    return build_toy(replace(system, network=replace(system.network, task=True)),
                     tmp_path_factory)


@pytest.fixture(scope="module")
def slow_fmu(tmp_path_factory):
    """A network of about 3 ms (longer than the 1 ms step; in onnxruntime, see
    flexff.bench.slow_graph) called every step, in a task."""
    graph = slow_graph(tmp_path_factory.mktemp("slow") / "slow.onnx")
    return build_toy(onnx_system(graph, H, 1, task=True, runtime="onnxruntime"),
                     tmp_path_factory)


def _run(fmu, runner=run_fmu):
    out = runner(fmu, STEPS, H, {"u1": INPUTS[:, 0], "u2": INPUTS[:, 1]})
    return np.column_stack([out["y1"], out["y2"]])


def _master_run(fmu, pacing=None):
    sources = {"u1": np.append(INPUTS[:, 0], INPUTS[-1, 0]),
               "u2": np.append(INPUTS[:, 1], INPUTS[-1, 1])}
    with Master([ResolvedFmu("net", fmu)], list(sources), H) as master:
        return master.run(sources, STEPS, progress=False, pacing=pacing)


def test_the_result_is_used_exactly_one_period_later(task_fmu):
    assert np.array_equal(_run(task_fmu)[:STEPS], task_outputs(INPUTS))


def test_paced_unpaced_and_libcosim_runs_are_equal_bit_for_bit(task_fmu):
    unpaced, paced = _master_run(task_fmu), _master_run(task_fmu, Pacing())
    for name in ("net.y1", "net.y2"):
        assert np.array_equal(paced[name], unpaced[name])
    assert np.array_equal(unpaced["net.y1"][:STEPS], task_outputs(INPUTS)[:, 0])
    ours = []  # libcosim's order: set the inputs, step, read
    s = LoggedSlave(task_fmu)
    s.initialize()
    for k in range(STEPS):
        s.set(u1=INPUTS[k, 0], u2=INPUTS[k, 1])
        s.slave.doStep(k * H, H)
        ours.append(s.get("y1", "y2"))
    s.free()
    assert np.array_equal(_run(task_fmu, run_fmu_libcosim), ours)
    assert validate_fmu(task_fmu) == []


def _worker_threads() -> list[int]:
    """The thread ids of this process's network workers (named by c/wrapper_task.c)."""
    return [int(task.name) for task in Path("/proc/self/task").iterdir()
            if (task / "comm").read_text().strip() == "flexff-network"]


def _settle(s: LoggedSlave) -> None:
    """Wait for the job out (flexff_network_times waits for it, counting no overrun)."""
    times = (ctypes.c_double * 4)()
    assert s.slave.dll.flexff_network_times(ctypes.c_void_p(s.slave.component), times) == 0


def _counts(s: LoggedSlave) -> list[int]:
    """The task's calls handed over, results not ready when due, results the step computed,
    hand-overs that signalled the worker."""
    counts = (ctypes.c_long * 4)()
    assert s.slave.dll.flexff_network_counts(ctypes.c_void_p(s.slave.component), counts) == 0
    return list(counts)


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs to pin to one")
def test_the_worker_runs_on_its_callers_cpus(task_fmu):
    """The worker takes its caller's CPUs as each job starts (no system call in the step)."""
    everywhere = os.sched_getaffinity(0)
    one = {max(everywhere)}
    s = LoggedSlave(task_fmu)
    try:
        s.initialize()
        [worker] = _worker_threads()
        assert os.sched_getaffinity(worker) == everywhere  # created as its caller
        os.sched_setaffinity(0, one)  # this thread only, as --cpu pins a paced run
        s.slave.doStep(0.0, H)  # point 0 posts a call
        _settle(s)
        assert os.sched_getaffinity(worker) == one
        os.sched_setaffinity(0, everywhere)
        for k in range(1, PERIOD + 1):  # up to the next call, which follows the caller again
            s.slave.doStep(k * H, H)
        _settle(s)
        assert os.sched_getaffinity(worker) == everywhere
    finally:
        os.sched_setaffinity(0, everywhere)
        s.free()
    assert _worker_threads() == []


def test_the_worker_never_preempts_its_caller(task_fmu):
    """Rate-monotonic: the worker is below the thread that steps the instance. Under the
    default scheduler it is a batch thread, which never preempts another on waking: an ordinary
    one preempted the step on the caller's CPU at a call point and ran the network in it (the
    feedforward's step p99 one network call, paced on one core without SCHED_FIFO)."""
    s = LoggedSlave(task_fmu)
    try:
        s.initialize()
        [worker] = _worker_threads()
        s.slave.doStep(0.0, H)  # point 0 posts a call
        _settle(s)
        assert os.sched_getscheduler(worker) == os.SCHED_BATCH
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        except PermissionError:
            return  # no real-time scheduling here: the ordinary case is the one to check
        try:
            for k in range(1, PERIOD + 1):
                s.slave.doStep(k * H, H)
            _settle(s)
        finally:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        assert os.sched_getscheduler(worker) == os.SCHED_FIFO
        assert os.sched_getparam(worker).sched_priority == 9
    finally:
        s.free()


def test_the_step_never_computes_a_result_that_was_ready_in_time(task_fmu):
    """A deterministic schedule: before each call point the job out is waited for outside the
    step (as a worker with time to spare would have finished it), so every result is ready
    when due: the steps hand every call over and compute, or wait for, none of them."""
    s = LoggedSlave(task_fmu)
    try:
        s.initialize()
        for k in range(STEPS):
            if k % PERIOD == 0:
                _settle(s)
            s.set(u1=INPUTS[k, 0], u2=INPUTS[k, 1])
            s.get("y1", "y2")
            s.slave.doStep(k * H, H)
        assert _counts(s)[:3] == [len(range(0, STEPS, PERIOD)), 0, 0]
    finally:
        s.free()


def _steady_calls(gaps: np.ndarray) -> int:
    """The call points the clock must have released the worker for, from the intervals
    `gaps` between them as this process saw them: a call whose interval and the two before it
    are alike within half the FMU's tolerances (1/8 between the two seen, 1/16 late), so that
    a busy machine's delayed sleeps are no such call. On a quiet machine every call from the
    fourth on."""
    return sum(1 for j in range(2, len(gaps))
               if abs(gaps[j - 1] - gaps[j - 2]) <= gaps[j - 1] / 16
               and abs(gaps[j] - gaps[j - 1]) <= gaps[j - 1] / 32)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the clock release is Linux's")
def test_calls_at_a_steady_rate_are_handed_over_without_waking_the_task(task_fmu):
    """A paced loop's call points come at a steady rate: from the fourth call on (two
    intervals seen alike), the clock releases the worker at the next call's time, and the
    step's hand-over signals nothing; a call point before its release still gets its result
    (the step waits for the job, signalling it), and so does one far later (the release came
    first: the worker waits for the signal). Outputs as ever, bit for bit."""
    interval = 0.02  # s between call points: Python's sleep is regular enough at this scale
    calls = 10
    s = LoggedSlave(task_fmu)
    outputs, stamps = [], []
    try:
        s.initialize()
        for k in range(calls * PERIOD):
            if k % PERIOD == 0:
                time.sleep(interval)
                stamps.append(time.perf_counter())
            s.set(u1=INPUTS[k, 0], u2=INPUTS[k, 1])
            outputs.append(s.get("y1", "y2"))
            s.slave.doStep(k * H, H)
        handovers, waited, in_step, signalled = _counts(s)
        assert (handovers, waited, in_step) == (calls, 0, 0)
        assert signalled <= calls - _steady_calls(np.diff(stamps))
        for k in range(calls * PERIOD, (calls + 2) * PERIOD):  # at once, then late: still right
            if k == (calls + 1) * PERIOD:
                time.sleep(3 * interval)
            s.set(u1=INPUTS[k, 0], u2=INPUTS[k, 1])
            outputs.append(s.get("y1", "y2"))
            s.slave.doStep(k * H, H)
    finally:
        s.free()
    steps = (calls + 2) * PERIOD
    assert np.array_equal(np.array(outputs), task_outputs(INPUTS[:steps]))


def test_a_network_input_that_is_not_finite_is_named_when_its_result_is_due(task_fmu):
    """The task evaluates its call's inputs (2 u: infinite for u = 1e308), not the step: the
    call of point PERIOD fails in the task, and the step at 2 PERIOD, which needs its result,
    reports the input, the point's time and the FMU's inputs there."""
    s = LoggedSlave(task_fmu)
    try:
        s.initialize()
        for k in range(2 * PERIOD):
            s.set(u1=1e308 if k == PERIOD else 1.0, u2=1.0)
            s.get("y1")
            s.slave.doStep(k * H, H)
        assert status_of(lambda: s.get("y1")) == fmi2Error
        assert f"is inf at t = {PERIOD * H:.17g}: it is not defined for the inputs u1 = 1e+308" \
            in s.log()
    finally:
        s.free()


def test_a_network_that_misses_its_deadline_is_counted(slow_fmu):
    inputs = {"inputs[0]": 1.0, "inputs[1]": 2.0}
    with Master([ResolvedFmu("slow", slow_fmu)], list(inputs), H) as master:
        recording = master.run(inputs, 20, progress=False)
    task = recording.timing.table(recording.wall_s)["tasks"]["slow.network"]
    assert task["overruns"] >= 15  # each call takes ~3 ms, its result is due 1 step later
    assert task["calls"] >= 20 and task["period_us"] == pytest.approx(1e3)
    assert np.array_equal(recording["slow.forces[1]"], [0.0] + [2.0] * 20)  # late, never wrong
    with Master([ResolvedFmu("slow", slow_fmu)], list(inputs), H) as master:
        paced = master.run(inputs, 200, progress=False, pacing=Pacing(max_overruns=10))
    timing = paced.timing  # the steps that wait overrun too: both kinds reach the 10
    assert timing.stopped_at is not None and timing.stopped_at < 100
    assert timing.task_overruns >= 1 and timing.overruns < 10
    assert timing.overruns + timing.task_overruns in (10, 11)  # a step may add one of each
    assert "overruns" in timing.stop_message()


@pytest.mark.parametrize("split", [PERIOD * 4 + 1, PERIOD * 4 + 2, PERIOD * 5])
def test_a_state_saved_with_a_call_pending_continues_exactly(tmp_path_factory, split):
    """The slow network every PERIOD steps: right after a call point's step its call is still
    running when the state is saved."""
    graph = slow_graph(tmp_path_factory.mktemp("slow") / "slow.onnx")
    fmu = build_toy(onnx_system(graph, H, PERIOD, task=True, runtime="onnxruntime"),
                    tmp_path_factory)
    names = ("inputs[0]", "inputs[1]")

    def steps(s, ks):
        out = []
        for k in ks:
            s.set(**dict(zip(names, INPUTS[k])))
            out.append(s.get("forces[0]", "forces[1]"))
            s.slave.doStep(k * H, H)
        return out

    s = LoggedSlave(fmu)
    s.initialize()
    steps(s, range(split))
    saved = s.slave.getFMUstate()
    blob = s.slave.serializeFMUstate(saved)
    straight = steps(s, range(split, STEPS))
    s.slave.setFMUstate(saved)
    assert steps(s, range(split, STEPS)) == straight
    s.slave.setFMUstate(saved)
    steps(s, range(split, split + PERIOD + 1))  # a call pending again when restored
    s.slave.setFMUstate(s.slave.deSerializeFMUstate(blob))
    assert steps(s, range(split, STEPS)) == straight
    s.slave.freeFMUstate(saved)
    s.slave.reset()  # with a call pending: the worker is waited for, then the instance reset
    s.free()
    expected = task_scheme(INPUTS[::PERIOD], STEPS)  # forces = inputs
    assert np.array_equal(np.array(straight), expected[split:STEPS])
